"""One window's diagnosis: gap estimate, the paper's image method, their fused verdict, a status.

Shared by the diagnostic node (:mod:`jident_ros.nodes.diagnostic`, which publishes the result on
``inertia_estimate`` and ``/diagnostics``) and the offline ``jident diagnose`` (:mod:`jident_ros.cli.offline`,
which runs it on the windows of a recording).  Plain numpy/scipy; never imports rclpy.

For one window (48 pre-entry samples, the entry sample, 1999 after it; paper section 2):

0. the input (:func:`jident_ros.identify.verdict.input_refusal`): a header or content that cannot
   support an estimate is refused with one line naming the field (ERROR, nothing published);
1. the gap estimate (:func:`jident_ros.identify.gap.estimate_inertia`): J1 by least squares over the
   samples inside the backlash zone, with its 95 % interval; the re-contact check
   (:func:`~jident_ros.identify.verdict.recontact_check`: does the window's K2 agree with where the
   load comes back?) and the publishing policy (:func:`~jident_ros.identify.verdict.decide_gap`:
   plausible band, width consistency, ambiguity).  An accepted estimate is passed to ``on_estimate``
   at once, *before* the image method runs (latency); the backlash width K2 is estimated from the
   relative angle at re-contact (:func:`~jident_ros.identify.gap.estimate_backlash_width`);
2. the paper's image method (:func:`jident_ros.method.patterns.identify_window`, KHM exponent p,
   H vectors of eq. 33, the five signals fused) against the pattern library, and whether its answer
   is in its validity domain (:func:`~jident_ros.identify.verdict.image_domain`);
3. the verdict (:func:`jident_ros.identify.fusion.fuse_verdict`) and the level: the table of
   docs/interfaces.md ("/diagnostics"), with a one-line message, a ``status`` (one of
   :data:`~jident_ros.identify.verdict.STATUSES`), ``refused_reason`` when nothing was published, and
   the key/value pairs of the DiagnosticStatus.
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
from jident_ros.identify.library import IMAGE_METHOD_OFF
from jident_ros.identify.verdict import (
    VerdictPolicy,
    decide_gap,
    fmt_classes,
    image_domain,
    input_refusal,
    recontact_check,
    width_disagreement,
)
from jident_ros.method.patterns import Identification, PatternLibrary, identify_window
from jident_ros.method.pipeline import SIGNALS

#: Gap estimators: ``auto`` (acceleration fit when a1 is there, else speed), ``acceleration``, ``speed``, ``off``.
#: ``none`` (preferred) and ``off`` both mean: no gap estimate.
GAP_METHODS = ("auto", "acceleration", "gap_only", "anchored", "angle", "speed", "none", "off")
NO_GAP = ("none", "off")


@dataclass
class WindowDiagnosis:
    """The diagnosis of one window.

    Attributes
    ----------
    level : int                 OK 0, WARN 1, ERROR 2 (diagnostic_msgs/DiagnosticStatus levels)
    message : str               one line, the status message
    values : list of (key, value)   the status key/values in publishing order (docs/interfaces.md)
    inertia_kgm2 : float | None     J1 published on ``inertia_estimate``, kg m^2: the accepted gap
                                    estimate, else the image method's class when it is trusted; None
                                    when nothing was published (``refused_reason`` says why)
    source : str | None         'gap' or 'image'
    class_kgm2 : float | None   the class named: the J1 class (K1 entry) nearest ``inertia_kgm2``
    verdict : Verdict | None    the fused verdict (jident_ros.identify.fusion)
    gap : GapEstimate | None    the gap estimate, when the window has a usable gap (published or not)
    identification : Identification | None   the image method's answers (five signals, fused class)
    width : WidthEstimate | None    K2 estimated at re-contact, m (needs alpha1 and alpha2)
    problems : list of str      what partly or wholly failed, one reason each
    status : str                'nominal', 'deviating', 'between_classes', 'ambiguous', 'refused' or
                                'undiagnosed' (jident_ros.identify.verdict.STATUSES)
    refused_reason : str | None     why nothing was published (one line), None when a J1 was
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
    status: str = "undiagnosed"
    refused_reason: Optional[str] = None

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


def _finite_or_nan(v) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x


def diagnose_window(window_data: dict, entry_index: int, backlash_width_m: float, wheel_radius_m: float,
                    sample_period_s: float, *, library: Optional[PatternLibrary], system, method, p: float,
                    gap_method: str = "auto", image_method: bool = True, nominal_kgm2: Optional[float] = None,
                    library_error: str = "", window_id: Optional[int] = None,
                    entry_time_s: Optional[float] = None,
                    on_estimate: Optional[Callable[[float], Any]] = None,
                    started_at: Optional[float] = None,
                    policy: Optional[VerdictPolicy] = None, recontact_index: Optional[int] = None,
                    width_estimate: Optional[WidthEstimate] = None,
                    entry_uncertainty_samples: int = 0, backlash_width_unknown: bool = False) -> WindowDiagnosis:
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
        fit when its estimate is accepted, else after the image method when its class is trusted;
        never when nothing is published
    started_at : ``time.perf_counter()`` when the window arrived (default: now); ``estimate_latency_ms``
        and ``processing_ms`` are measured from it
    policy : the publishing policy (default :class:`~jident_ros.identify.verdict.VerdictPolicy()`, the
        diagnostic node's default parameters)
    recontact_index, width_estimate : from a flank-detector window (raw encoder angles, no K2): the gap
        ends at its re-contact row and its K2 estimate is reported instead of one from zone-centred angles
        (:func:`detector_arguments`)
    entry_uncertainty_samples : the entry row is known to +- this many samples (a dynamics-detector window
        without a1, :func:`detector_arguments`): the gap fit's uncertainty takes it in
    backlash_width_unknown : K2 is not known (a dynamics-detector window without a load encoder: no flanks to
        measure, :func:`detector_arguments`): a NaN ``backlash_width_m`` is then accepted; the gap fit runs
        without it, the image method (which picks its library width by K2) is not run and the status says so
    """
    t0 = time.perf_counter() if started_at is None else float(started_at)
    if gap_method not in GAP_METHODS:
        raise ValueError(f"gap_method: expected one of {', '.join(GAP_METHODS)}, got {gap_method!r}")
    if not image_method and gap_method in NO_GAP:
        raise ValueError("image_method: must be true when gap_method is off (nothing would be identified)")
    policy = VerdictPolicy() if policy is None else policy
    policy.check()
    nominal = float(system.motor.nominal_inertia_kgm2 if nominal_kgm2 is None else nominal_kgm2)
    classes = tuple(float(c) for c in (library.classes_kgm2 if library is not None
                                       else system.grid.inertia_classes_kgm2))
    vals: list = []
    if window_id is not None:
        vals.append(("window_id", int(window_id)))
    problems: list = []

    def finish(level, status, text, j1=None, source=None, cls=None, **kw):
        """The WindowDiagnosis with the head key/values in front."""
        refused = kw.pop("refused_reason", None)
        head = [("status", status)]
        if refused:
            head.append(("refused_reason", refused))
        head += [("identified_class_kgm2", math.nan if cls is None else cls),
                 ("inertia_estimate_kgm2", math.nan if j1 is None else j1),
                 ("estimate_source", source or "none"), ("nominal_kgm2", nominal),
                 ("deviation_percent", math.nan if cls is None else (cls - nominal) / nominal * 100.0)]
        tail = list(kw.pop("tail", []))
        if problems:
            tail.append(("problems", "; ".join(problems)))
        return WindowDiagnosis(level, text, head + vals + tail, j1, source, cls, problems=problems,
                               status=status, refused_reason=refused, **kw)

    # 0. the input
    k2_unknown = bool(backlash_width_unknown) and isinstance(backlash_width_m, float) and math.isnan(backlash_width_m)
    refusal = input_refusal(window_data, entry_index, backlash_width_m, wheel_radius_m, sample_period_s,
                            system=system, policy=policy, nominal_kgm2=nominal, width_unknown=k2_unknown)
    if entry_time_s is None and refusal is None and "t" in window_data:
        entry_time_s = float(np.asarray(window_data["t"], float)[entry_index])
    if entry_time_s is not None:
        vals.append(("entry_time_s", _finite_or_nan(entry_time_s)))
    vals += [("backlash_width_m", _finite_or_nan(backlash_width_m)), ("p", float(p))]
    if refusal is not None:
        problems.append(refusal)
        return finish(ERROR, "refused", f"window refused: {refusal}", refused_reason=refusal)
    band = policy.band_kgm2(nominal)
    vals.append(("plausible_band_kgm2", list(band)))
    latency_ms = None

    def publish(j1):
        nonlocal latency_ms
        if on_estimate is not None:
            on_estimate(j1)
        latency_ms = (time.perf_counter() - t0) * 1e3

    # 1. the gap: fast; published first when the policy accepts it
    gap, gap_reason, width, recontact, decision = None, "", None, None, None
    if gap_method not in NO_GAP:
        try:
            # a detector window (its own K2, or none) holds raw encoder angles: the gap interval comes from the
            # detector's re-contact row or the dynamics, never from |alpha1 - alpha2| < K2/r
            raw_angles = width_estimate is not None or k2_unknown
            gap_window = {k: v for k, v in window_data.items() if k != "alpha2"} if raw_angles else window_data
            gap = estimate_inertia(gap_window, entry_index, backlash_width_m, wheel_radius_m, sample_period_s,
                                   method=None if gap_method == "auto" else gap_method,
                                   bearing_friction_nms_per_rad=system.motor.bearing_friction_nms_per_rad,
                                   recontact_index=recontact_index,
                                   entry_uncertainty_samples=entry_uncertainty_samples)
        except NoGapError as exc:
            gap_reason = str(exc)
            problems.append(f"gap: {exc}")
        # K2 bounded the gap (or was blamed): checked against zone-centred angles only for a window whose K2 was
        # given (paper detector); a flank window's K2 was measured by its detector on the offset-free relative
        # angle alpha1 - N alpha2 at its re-contact row (issue 20: raw angles read here gave 'r|alpha1 - alpha2|
        # = 25 m')
        if not k2_unknown and width_estimate is None and (gap is None or gap.interval == "angles"):
            try:
                recontact = recontact_check(window_data, entry_index, backlash_width_m, wheel_radius_m)
            except NoGapError as exc:
                vals.append(("width_consistent", f"unknown: {exc}"))
        if recontact is not None:
            vals += [("width_consistent", recontact.consistent), ("recontact_width_m", recontact.width_m),
                     ("recontact_width_range_m", list(recontact.range_m)), ("recontact_signal", recontact.signal)]
            if gap is None and not recontact.consistent:
                problems.append(width_disagreement(recontact, backlash_width_m))
        if gap is not None:
            decision = decide_gap(gap, classes, nominal, policy, recontact, backlash_width_m)
            if decision.status == "accepted":
                publish(gap.inertia_kgm2)
            vals += [("gap_j1_kgm2", gap.inertia_kgm2), ("gap_ci95_kgm2", list(gap.ci95_kgm2)),
                     ("gap_std_error_kgm2", gap.std_error_kgm2), ("gap_samples", gap.n_samples),
                     ("gap_fit", gap.method), ("gap_model_choice", gap.model_choice or "given"),
                     ("gap_interval", gap.interval),
                     ("gap_residual_rms", gap.residual_rms), ("gap_model_error_kgm2", gap.model_error_kgm2),
                     ("gap_classes_in_ci95_kgm2", list(decision.classes_in_ci)), ("gap_decision", decision.status)]
            if width_estimate is not None:
                width = width_estimate
            elif "alpha1" in window_data and "alpha2" in window_data and not k2_unknown:
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
    # 2. the image method, and whether its answer is trusted
    idn, image_cls, in_domain, domain_reason = None, None, False, ""
    if image_method and k2_unknown:
        vals.append(("image_method", "not run: K2 unknown (no load encoder, or no traversal in this window), no "
                                     "library width to compare with"))
    elif image_method:
        if library is None and (library_error or "").startswith(IMAGE_METHOD_OFF):
            vals.append(("image_method", "off: no pattern library for this drive"))   # said once per run, not here
        elif library is None:
            problems.append(library_error or "no pattern library")
        else:
            signals = [s for s in SIGNALS if s in window_data]
            if not signals:
                problems.append(f"image method: the window has none of {', '.join(SIGNALS)}")
            else:
                try:
                    sign = rotation_sign(window_data, entry_index)
                    if sign < 0:    # the library is built forward: a reverse window is mirrored first
                        vals.append(("image_rotation", "reverse (mirrored)"))
                    idn = identify_window(mirrored(window_data) if sign < 0 else window_data, entry_index,
                                          backlash_width_m, library, method, p, signals=signals)
                except Exception as exc:
                    problems.append(f"image method: {type(exc).__name__}: {exc}")
    if idn is not None:
        image_cls = classes[idn.fused_class_index]
        lib_width = float(library.widths_m[idn.width_index])
        in_domain, domain_reason = image_domain(idn.fused_margin, lib_width, float(backlash_width_m),
                                                float(sample_period_s), float(system.sampling.sample_period_s),
                                                policy, variant=method.variant)
        if in_domain and recontact is not None and not recontact.consistent:
            in_domain, domain_reason = False, "the window's K2 disagrees with the re-contact"
        vals += [("image_class_kgm2", image_cls), ("image_margin", idn.fused_margin),
                 ("image_in_domain", in_domain), ("image_min_margin", policy.image_min_margin)]
        if not in_domain:
            vals.append(("image_domain_reason", domain_reason))
        vals += [("fused_class_kgm2", idn.fused_inertia_kgm2), ("fused_margin", idn.fused_margin),
                 ("library_width_m", lib_width)]
        for s, a in idn.answers.items():
            vals += [(f"j1.{s}", a.inertia_kgm2), (f"h.{s}", a.h), (f"margin.{s}", a.margin)]
    library_missing = (image_method and not k2_unknown and library is None
                       and not (library_error or "").startswith(IMAGE_METHOD_OFF))
    lib_text = library_error or "no pattern library"

    def image_phrase(disagree_with: str) -> tuple:
        """(level bump, text) for the image answer next to a gap class."""
        if idn is None:
            return OK, ""
        if in_domain:
            return WARN, (f"; the image method disagrees: its class {image_cls:g} (margin {idn.fused_margin:.3g}), "
                          f"{disagree_with}")
        return OK, (f"; information: the image method answers class {image_cls:g}, outside its validity domain "
                    f"({domain_reason}): not a warning")

    def timing():
        return [("estimate_latency_ms", math.nan if latency_ms is None else latency_ms),
                ("processing_ms", (time.perf_counter() - t0) * 1e3)]

    # 3. the verdict and the level
    if gap is not None and decision.status == "accepted":
        verdict = fuse_verdict(classes, None, idn.fused_class_index if idn is not None else None, gap, gap_reason)
        j1 = float(gap.inertia_kgm2)
        nearest = classes[nearest_class(j1, classes)]
        deviation = (j1 - nominal) / nominal * 100.0
        if verdict.between_classes:
            status, level, cls = "between_classes", WARN, None
            text = (f"J1 = {j1:.5g} ± {gap.std_error_kgm2:.2g} kg m^2: between classes (none within "
                    f"{BETWEEN_Z:g} standard errors), {deviation:+.1f} % from the nominal {nominal:g}")
        elif nearest == nominal:
            status, level, cls = "nominal", OK, nearest
            text = f"J1 = {j1:.5g} kg m^2: nominal class {nearest:g}"
        else:
            status, level, cls = "deviating", WARN, nearest
            text = (f"J1 = {j1:.5g} kg m^2: class {nearest:g} deviates from the nominal {nominal:g} by "
                    f"{(nearest - nominal) / nominal * 100.0:+.1f} %")
        if verdict.agree is False:
            bump, phrase = image_phrase(f"the gap's nearest class {nearest:g}")
            level, text = max(level, bump), text + phrase
        if library_missing:
            level, text = ERROR, text.replace(" kg m^2:", " kg m^2 (from the gap only):", 1) + f"; {lib_text}"
        tail = _verdict_values(verdict, classes) + timing()
        return finish(level, status, text, j1, "gap", cls, verdict=verdict, gap=gap, identification=idn,
                      width=width, tail=tail)
    if gap is not None and decision.status == "ambiguous":
        j1, se = float(gap.inertia_kgm2), float(gap.std_error_kgm2)
        held = decision.classes_in_ci
        reason = decision.reason
        if nominal in held or abs(j1 - nominal) <= BETWEEN_Z * se:
            level, note = OK, f"consistent with the nominal {nominal:g}"
        else:
            level, note = WARN, (f"the nominal {nominal:g} is excluded (more than {BETWEEN_Z:g} standard errors "
                                 f"from J1 = {j1:.4g} ± {se:.2g})")
        text = f"{reason}: no class named, nothing published; {note}"
        if idn is not None and image_cls not in held:
            bump, phrase = image_phrase(f"outside the interval's classes {fmt_classes(held)}")
            level, text = max(level, bump), text + phrase
        if library_missing:
            level, text = ERROR, text + f"; {lib_text}"
        return finish(level, "ambiguous", text, gap=gap, identification=idn, width=width, refused_reason=reason,
                      tail=timing())
    if gap is not None:  # refused by the policy
        reason = decision.reason
        text = f"estimate refused: {reason}; nothing published"
        if idn is not None:
            text += f"; the image method answers class {image_cls:g} (margin {idn.fused_margin:.3g}), not published"
        if library_missing:
            text += f"; {lib_text}"
        return finish(ERROR, "refused", text, gap=gap, identification=idn, width=width, refused_reason=reason,
                      tail=timing())
    if idn is not None and in_domain:  # no gap: the image method's class, trusted
        j1 = float(image_cls)
        publish(j1)
        verdict = fuse_verdict(classes, None, idn.fused_class_index, None, gap_reason)
        status, level = ("nominal", OK) if j1 == nominal else ("deviating", WARN)
        what = "nominal class" if j1 == nominal else (
            f"class {j1:g} deviates from the nominal {nominal:g} by {(j1 - nominal) / nominal * 100.0:+.1f} %; class")
        text = (f"J1 = {j1:g} kg m^2 (image method, margin {idn.fused_margin:.3g} >= image_min_margin "
                f"{policy.image_min_margin:g}; no gap estimate: {gap_reason}): {what} {j1:g}")
        tail = _verdict_values(verdict, classes) + timing()
        return finish(level, status, text, j1, "image", j1, verdict=verdict, identification=idn, width=width,
                      tail=tail)
    if idn is not None:
        problems.append(f"image method: class {image_cls:g} not published: {domain_reason}")
    reason = "; ".join(problems) or "nothing identified"
    return finish(ERROR, "undiagnosed", f"window could not be diagnosed: {reason}", identification=idn,
                  width=width, refused_reason=reason, tail=timing())


def _verdict_values(verdict: Verdict, classes) -> list:
    return [("verdict_class_kgm2", math.nan if verdict.class_inertia_kgm2 is None else verdict.class_inertia_kgm2),
            ("verdict_between_classes", verdict.between_classes),
            ("verdict_agree", "unknown" if verdict.agree is None else verdict.agree)]


def rotation_sign(window_data: dict, entry_index: int) -> float:
    """+1 forward, -1 reverse rotation: the sign of the motor speed before the entry (the median of omega1,
    else the slope of alpha1, else the sign of m_el: the motor drives its load); +1 when none tells."""
    pre = slice(0, max(int(entry_index), 2))
    for name, stat in (("omega1", np.median), ("alpha1", lambda x: x[-1] - x[0]), ("m_el", np.median)):
        if name in window_data:
            v = float(stat(np.asarray(window_data[name], float)[pre]))
            if v != 0 and math.isfinite(v):
                return 1.0 if v > 0 else -1.0
    return 1.0


def mirrored(window_data: dict) -> dict:
    """Every channel but t with its sign changed: a reverse window as the forward one the model is odd to
    (docs/method.md, "Reverse rotation")."""
    return {k: (v if k == "t" else -np.asarray(v, float)) for k, v in window_data.items()}


#: The dynamics detector's entry row without a1 (from the motor angle) is known to +- this many samples
#: (docs/results.md, "Entries from the dynamics": -5 ... +1 on our simulator, -9 ... -3 on the second drive).
ENTRY_UNCERTAINTY_WITHOUT_A1 = 10


def detector_arguments(window) -> dict:
    """diagnose_window's ``recontact_index`` and ``width_estimate`` for a captured
    :class:`~jident_ros.stream.layout.Window`: a flank- or dynamics-detector window's own (and, for a dynamics
    window without a1, ``entry_uncertainty_samples``); none for the paper detector's."""
    kind = getattr(window, "detector", "paper")
    if kind not in ("flank", "dynamics"):
        return {}
    est = None
    if math.isfinite(window.backlash_width_estimate_m):
        est = WidthEstimate(float(window.backlash_width_estimate_m), float(window.backlash_width_se_m),
                            int(window.recontact_index), "flank")
    out = {"recontact_index": window.recontact_index if window.recontact_index >= 0 else None,
           "width_estimate": est}
    if kind == "dynamics" and "a1" not in window.channels:
        out["entry_uncertainty_samples"] = ENTRY_UNCERTAINTY_WITHOUT_A1
    if not math.isfinite(window.backlash_width_m):
        # no load encoder (dynamics), or no traversal in this window (a one-sided excursion): no K2, and a
        # missing K2 never blocks the gap's J1 (issue 20)
        out["backlash_width_unknown"] = True
    return out


__all__ = ["GAP_METHODS", "WindowDiagnosis", "detector_arguments", "diagnose_window"]
