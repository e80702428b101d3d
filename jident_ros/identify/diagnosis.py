"""One window's diagnosis: gap estimate, the paper's image method, their fused verdict, a status.

Shared by the diagnostic node (:mod:`jident_ros.nodes.diagnostic`, which publishes the result on
``inertia_estimate`` and ``/diagnostics``) and the offline ``jident diagnose`` (:mod:`jident_ros.cli.offline`,
which runs it on the windows of a recording).  Plain numpy/scipy; never imports rclpy.

For one window (48 pre-entry samples, the entry sample, 1999 after it; paper section 2):

1. the gap estimate (:func:`jident_ros.identify.gap.estimate_inertia`): J1 by least squares over the
   samples inside the backlash zone, with its 95 % interval; when there is one, ``on_estimate`` is
   called with it at once, *before* the image method runs (latency), and the backlash width K2 is
   estimated from the relative angle at re-contact (:func:`~jident_ros.identify.gap.estimate_backlash_width`);
2. the paper's image method (:func:`jident_ros.method.patterns.identify_window`, KHM exponent p,
   H vectors of eq. 33) against the pattern library;
3. the fused verdict (:func:`jident_ros.identify.fusion.fuse_verdict`): the best continuous J1 (the gap
   estimate, else the image method's margin-weighted class vote), its class or "between classes", and
   whether the image vote agrees with the gap's nearest class;
4. the level: OK (the class is the nominal J1), WARN (another class, between classes, or the image
   method disagrees with the gap), ERROR (nothing could be identified, or the image method was asked
   for and there is no usable pattern library), with a one-line message and the key/value pairs of
   the DiagnosticStatus (docs/interfaces.md).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np

from jident_ros.identify.fusion import BETWEEN_Z, Verdict, fuse_verdict
from jident_ros.identify.gap import (
    GapEstimate,
    NoGapError,
    WidthEstimate,
    estimate_backlash_width,
    estimate_inertia,
    nearest_class,
)
from jident_ros.identify.levels import ERROR, LEVEL_NAMES, OK, WARN
from jident_ros.method.patterns import Identification, PatternLibrary, identify_window
from jident_ros.method.pipeline import SIGNALS

#: Gap estimators: ``auto`` (acceleration fit when a1 is there, else speed), ``acceleration``, ``speed``, ``off``.
#: ``none`` (preferred) and ``off`` both mean: no gap estimate.
GAP_METHODS = ("auto", "acceleration", "anchored", "angle", "speed", "none", "off")
NO_GAP = ("none", "off")


@dataclass
class WindowDiagnosis:
    """The diagnosis of one window.

    Attributes
    ----------
    level : int                 OK 0, WARN 1, ERROR 2 (diagnostic_msgs/DiagnosticStatus levels)
    message : str               one line, the status message
    values : list of (key, value)   the status key/values in publishing order (docs/interfaces.md)
    inertia_kgm2 : float | None     J1 published on ``inertia_estimate``, kg m^2: the verdict's best
                                    continuous J1 (gap estimate, else the image vote's class); None when
                                    the window could not be diagnosed
    source : str | None         'gap' or 'image'
    class_kgm2 : float | None   identified class: the J1 class (K1 entry) nearest ``inertia_kgm2``
    verdict : Verdict | None    the fused verdict (jident_ros.identify.fusion)
    gap : GapEstimate | None    the gap estimate, when the window has a usable gap
    identification : Identification | None   the image method's answers (five signals, fused class)
    width : WidthEstimate | None    K2 estimated at re-contact, m (needs alpha1 and alpha2)
    problems : list of str      what partly or wholly failed, one reason each
    """

    level: int
    message: str
    values: list
    inertia_kgm2: Optional[float] = None
    source: Optional[str] = None
    class_kgm2: Optional[float] = None
    verdict: Optional[Verdict] = None
    gap: Optional[GapEstimate] = None
    identification: Optional[Identification] = None
    width: Optional[WidthEstimate] = None
    problems: list = field(default_factory=list)

    @property
    def level_name(self) -> str:
        return LEVEL_NAMES[self.level]

    @property
    def diagnosed(self) -> bool:
        """True when a J1 was identified (published)."""
        return self.inertia_kgm2 is not None

    def value_dict(self) -> dict:
        """The status key/values as a dict."""
        return dict(self.values)


def diagnose_window(window_data: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                    sample_period_s: float, *, library: Optional[PatternLibrary], system, method, p: float,
                    gap_method: str = "auto", image_method: bool = True, nominal_kgm2: Optional[float] = None,
                    library_error: str = "", window_id: Optional[int] = None,
                    entry_time_s: Optional[float] = None,
                    on_estimate: Optional[Callable[[float], Any]] = None,
                    started_at: Optional[float] = None) -> WindowDiagnosis:
    """Diagnose one window (see the module docstring).

    Parameters
    ----------
    window_data : dict of 1-D arrays, one per channel (``t``, ``alpha1``, ``alpha2`` rad, ``a1`` m/s^2,
        ``m_el`` N m, ``omega1`` rad/s, ``a2`` m/s^2, ``v2`` m/s, ...), all of the window's length
    entry_index : row of the backlash-zone entry sample (48)
    backlash_width_m : K2 the detector used, m (picks the library width, bounds the gap)
    wheel_radius_m : r of inequality (1), m
    sample_period_s : T_s, s
    library : the pattern library, or None (no image method; ``library_error`` says why)
    system, method : SystemConfig and MethodConfig (``system.motor.bearing_friction_nms_per_rad`` = b1
        of the gap fit; classes K1 from the library, else ``system.grid.inertia_classes_kgm2``)
    p : KHM exponent of the image method, one of the library's p values
    gap_method : one of :data:`GAP_METHODS`
    image_method : run the paper's image method
    nominal_kgm2 : nominal J1, kg m^2 (default ``system.motor.nominal_inertia_kgm2``)
    library_error : why ``library`` is None, for the status (default "no pattern library")
    window_id, entry_time_s : reported in the status (entry_time_s defaults to t at the entry sample)
    on_estimate : called with the published J1 (kg m^2) as soon as it is known: right after the gap
        fit when there is a gap, else after the image method
    started_at : ``time.perf_counter()`` when the window arrived (default: now); ``estimate_latency_ms``
        and ``processing_ms`` are measured from it
    """
    t0 = time.perf_counter() if started_at is None else float(started_at)
    if gap_method not in GAP_METHODS:
        raise ValueError(f"gap_method: expected one of {', '.join(GAP_METHODS)}, got {gap_method!r}")
    if not image_method and gap_method in NO_GAP:
        raise ValueError("image_method: must be true when gap_method is off (nothing would be identified)")
    nominal = float(system.motor.nominal_inertia_kgm2 if nominal_kgm2 is None else nominal_kgm2)
    classes = tuple(float(c) for c in (library.classes_kgm2 if library is not None
                                       else system.grid.inertia_classes_kgm2))
    if entry_time_s is None and "t" in window_data:
        entry_time_s = float(np.asarray(window_data["t"])[entry_index])
    vals: list = []
    if window_id is not None:
        vals.append(("window_id", int(window_id)))
    if entry_time_s is not None:
        vals.append(("entry_time_s", float(entry_time_s)))
    vals += [("backlash_width_m", float(backlash_width_m)), ("p", float(p))]
    problems: list = []
    latency_ms = None

    def publish(j1):
        nonlocal latency_ms
        if on_estimate is not None:
            on_estimate(j1)
        latency_ms = (time.perf_counter() - t0) * 1e3

    # 1. the gap: fast, published first
    gap, gap_reason, width = None, "", None
    if gap_method not in NO_GAP:
        try:
            gap = estimate_inertia(window_data, entry_index, backlash_width_m, wheel_radius_m, sample_period_s,
                                   method=None if gap_method == "auto" else gap_method,
                                   bearing_friction_nms_per_rad=system.motor.bearing_friction_nms_per_rad)
        except NoGapError as exc:
            gap_reason = str(exc)
            problems.append(f"gap: {exc}")
        if gap is not None:
            publish(gap.inertia_kgm2)
            vals += [("gap_j1_kgm2", gap.inertia_kgm2), ("gap_ci95_kgm2", list(gap.ci95_kgm2)),
                     ("gap_std_error_kgm2", gap.std_error_kgm2), ("gap_samples", gap.n_samples),
                     ("gap_fit", gap.method), ("gap_interval", gap.interval),
                     ("gap_residual_rms", gap.residual_rms), ("gap_model_error_kgm2", gap.model_error_kgm2)]
            if "alpha1" in window_data and "alpha2" in window_data:
                try:
                    width = estimate_backlash_width(window_data, gap.gap_end, wheel_radius_m, sample_period_s,
                                                    gap.inertia_kgm2)
                except NoGapError as exc:
                    problems.append(f"backlash width estimate: {exc}")
            if width is not None:
                vals += [("backlash_width_estimate_m", width.width_m),
                         ("backlash_width_estimate_std_m", width.std_m),
                         ("backlash_width_estimate_method", width.method)]
    else:
        gap_reason = "gap method off"
    # 2. the image method
    idn = None
    if image_method:
        if library is None:
            problems.append(library_error or "no pattern library")
        else:
            signals = [s for s in SIGNALS if s in window_data]
            if not signals:
                problems.append(f"image method: the window has none of {', '.join(SIGNALS)}")
            else:
                try:
                    idn = identify_window(window_data, entry_index, backlash_width_m, library, method, p,
                                          signals=signals)
                except Exception as exc:
                    problems.append(f"image method: {type(exc).__name__}: {exc}")
    if idn is not None:
        vals += [("fused_class_kgm2", idn.fused_inertia_kgm2), ("fused_margin", idn.fused_margin),
                 ("library_width_m", library.widths_m[idn.width_index])]
        for s, a in idn.answers.items():
            vals += [(f"j1.{s}", a.inertia_kgm2), (f"h.{s}", a.h), (f"margin.{s}", a.margin)]
    # 3. the verdict
    if gap is None and idn is None:
        text = "window could not be diagnosed: " + "; ".join(problems)
        if problems:
            vals.append(("problems", "; ".join(problems)))
        return WindowDiagnosis(ERROR, text, vals, problems=problems)
    verdict = fuse_verdict(classes, idn.answers if idn is not None else None,
                           idn.fused_class_index if idn is not None else None, gap, gap_reason)
    j1, source = float(verdict.inertia_kgm2), verdict.source
    if source == "image":
        publish(j1)
    cls = classes[nearest_class(j1, classes)]
    deviation = (cls - nominal) / nominal * 100.0
    if image_method and library is None:
        level = ERROR
        text = f"J1 = {j1:.5g} kg m^2 (from the gap only): {library_error or 'no pattern library'}"
    elif verdict.between_classes:
        level = WARN
        text = (f"J1 = {j1:.5g} ± {gap.std_error_kgm2:.2g} kg m^2: between classes (none within "
                f"{BETWEEN_Z:g} standard errors), "
                f"{(j1 - nominal) / nominal * 100.0:+.1f} % from the nominal {nominal:g}")
    elif cls == nominal:
        level, text = OK, f"J1 = {j1:.5g} kg m^2: nominal class {cls:g}"
    else:
        level = WARN
        text = f"J1 = {j1:.5g} kg m^2: class {cls:g} deviates from the nominal {nominal:g} by {deviation:+.1f} %"
    if verdict.agree is False:
        level = max(level, WARN)
        text += (f"; the image method disagrees: its vote is class {classes[verdict.image_class_index]:g}, "
                 f"the gap's nearest class {cls:g}")
    head = [("identified_class_kgm2", cls), ("inertia_estimate_kgm2", j1), ("estimate_source", source),
            ("nominal_kgm2", nominal), ("deviation_percent", deviation),
            ("verdict_class_kgm2", math.nan if verdict.class_inertia_kgm2 is None else verdict.class_inertia_kgm2),
            ("verdict_between_classes", verdict.between_classes),
            ("verdict_agree", "unknown" if verdict.agree is None else verdict.agree)]
    if verdict.image_class_index is not None:
        head.append(("image_vote_class_kgm2", classes[verdict.image_class_index]))
    vals = head + vals
    vals += [("estimate_latency_ms", latency_ms), ("processing_ms", (time.perf_counter() - t0) * 1e3)]
    if problems:
        vals.append(("problems", "; ".join(problems)))
    return WindowDiagnosis(level, text, vals, j1, source, cls, verdict, gap, idn, width, problems)


__all__ = ["GAP_METHODS", "WindowDiagnosis", "diagnose_window"]
