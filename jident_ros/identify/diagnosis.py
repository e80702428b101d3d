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
    SHALLOW_GAP_REASON,
    SHORT_BOUNCE_REASON,
    GapEstimate,
    NoGapError,
    WidthEstimate,
    estimate_backlash_width,
    estimate_inertia,
    nearest_class,
    resolution_limited,
)
from jident_ros.identify.gap_load import LOAD_ANGLE_KEY
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
from jident_ros.identify.window_args import (  # noqa: F401 -- re-exported (tests, raw_inputs)
    ENTRY_UNCERTAINTY_WITHOUT_A1,
    FLANK_WINDOWS_WITHOUT_K2,
    detector_arguments,
)
from jident_ros.method.patterns import Identification, PatternLibrary, identify_window
from jident_ros.method.pipeline import SIGNALS
from jident_ros.parameters import GAP_METHODS, NO_GAP, gap_method_problem


@dataclass
class WindowDiagnosis:
    """The diagnosis of one window.

    Attributes
    ----------
    level : int                 OK 0, WARN 1, ERROR 2 (diagnostic_msgs/DiagnosticStatus levels)
    message : str               one line, the status message
    values : list of (key, value)   the status key/values in publishing order (docs/interfaces.md)
    inertia_kgm2 : float | None     J1 published on ``inertia_estimate``, kg m^2: the accepted gap
                                    estimate (with a class, or 'ambiguous' without one), else the image
                                    method's class when it is trusted; None
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


@dataclass(frozen=True)
class DiagnosisConfig:
    """How every window is diagnosed (the diagnostic node's ``p``, ``gap_method``, ``image_method``).

    p : KHM exponent of the image method, one of the library's p values
    gap_method : one of :data:`GAP_METHODS` (``none``/``off``: no gap estimate)
    image_method : run the paper's image method
    nominal_kgm2 : nominal J1, kg m^2 (None: ``system.motor.nominal_inertia_kgm2``)
    """

    p: float = 2.0
    gap_method: str = "auto"
    image_method: bool = True
    nominal_kgm2: Optional[float] = None

    #: The node parameter (jident_ros/parameters.py, DIAGNOSTIC_PARAMS) that describes each field -- its
    #: description, unit, range, choices and whether it changes at run time; None: not a node parameter.
    PARAMETERS = {"p": "p", "gap_method": "gap_method", "image_method": "image_method",
                  "nominal_kgm2": None}     # nominal_kgm2: system.motor.nominal_inertia_kgm2 (config/system.yaml)

    @classmethod
    def from_parameters(cls, params, nominal_kgm2: Optional[float] = None) -> "DiagnosisConfig":
        """From the diagnostic node's parameters (``gap_method`` ``off`` and ``none`` both mean no gap)."""
        gap_method = "off" if params["gap_method"] in NO_GAP else params["gap_method"]
        return cls(float(params["p"]), gap_method, bool(params["image_method"]), nominal_kgm2)

    def check(self) -> None:
        """ValueError naming the field (the rules of :func:`jident_ros.parameters.gap_method_problem`)."""
        problem = gap_method_problem(self.gap_method, self.image_method)
        if problem is not None:
            raise ValueError(f"{problem[0]}: {problem[1]}")


@dataclass(frozen=True)
class WindowInput:
    """One window as the diagnosis reads it.

    data : dict of 1-D arrays, one per channel (``t``, ``alpha1``, ``alpha2`` rad, ``a1`` m/s^2, ``m_el`` N m,
        ``omega1`` rad/s, ``a2`` m/s^2, ``v2`` m/s, ...), all of the window's length
    entry_index : row of the backlash-zone entry sample (48)
    backlash_width_m : K2 the detector used, m (picks the library width, bounds the gap)
    wheel_radius_m : r of inequality (1), m
    sample_period_s : T_s, s
    window_id, entry_time_s : reported in the status (entry_time_s defaults to t at the entry sample)
    recontact_index, width_estimate, raw_angles : from a flank- or dynamics-detector window (raw encoder angles, a real
        drive's: VerdictPolicy.drive_model): its re-contact row ends the gap, its K2 estimate is reported
    entry_uncertainty_samples : the entry row is known to +- this many samples (a dynamics-detector window
        without a1): the gap fit's uncertainty takes it in
    backlash_width_unknown : K2 is not known (a dynamics-detector window without a load encoder: no flanks to
        measure): a NaN ``backlash_width_m`` is then accepted; the gap fit runs without it, the image method
        (which picks its library width by K2) is not run and the status says so
    """

    data: dict
    entry_index: int
    backlash_width_m: float
    wheel_radius_m: float
    sample_period_s: float
    entry_uncertainty_samples: int = 0
    window_id: Optional[int] = None
    backlash_width_unknown: bool = False
    entry_time_s: Optional[float] = None
    recontact_index: Optional[int] = None
    width_estimate: Optional[WidthEstimate] = None
    raw_angles: bool = False
    shallow_gap: bool = False       # the flank detector's shallow gap (layout.FLAG_SHALLOW_GAP): no gap fit
    bounce: bool = False            # ... its excursion came back to the flank it left (layout.FLAG_BOUNCE)
    second_entry: bool = False      # ... another entry lies inside the window (layout.FLAG_SECOND_ENTRY)

    @classmethod
    def from_window(cls, window) -> "WindowInput":
        """A captured :class:`~jident_ros.stream.layout.Window` (any detector: :func:`detector_arguments`)."""
        return cls(window.as_dict(), window.entry_index, window.backlash_width_m, window.wheel_radius_m,
                   window.sample_period_s, window_id=window.window_id, entry_time_s=window.entry_time_s,
                   **detector_arguments(window))


def _short_bounce(w: WindowInput, search_rows: int) -> Optional[str]:
    """gap.SHORT_BOUNCE_REASON for a bounce's window (layout.FLAG_BOUNCE) that holds another entry (FLAG_SECOND_ENTRY)
    and whose gap, entry to re-contact row, is shorter than the gap fit's change-point search; None otherwise."""
    if not (w.bounce and w.second_entry) or w.recontact_index is None:
        return None
    rows = int(w.recontact_index) - int(w.entry_index)
    return SHORT_BOUNCE_REASON.format(rows=rows, search=search_rows) if 0 < rows < search_rows else None


class Diagnoser:
    """The per-window diagnosis, configured once (module docstring): ``diagnose(window) -> WindowDiagnosis``.

    Parameters
    ----------
    system, method : SystemConfig and MethodConfig (``system.motor.bearing_friction_nms_per_rad`` = b1 of the
        gap fit; classes K1 from the library, else ``system.grid.inertia_classes_kgm2``)
    config : :class:`DiagnosisConfig` (p, gap method, image method, nominal J1)
    policy : the publishing policy (default :class:`~jident_ros.identify.verdict.VerdictPolicy()`, the
        diagnostic node's default parameters)
    library : the pattern library, or None (no image method; ``library_error`` says why)
    library_error : why ``library`` is None, for the status (default "no pattern library")
    """

    def __init__(self, system, method, config: DiagnosisConfig = DiagnosisConfig(),
                 policy: Optional[VerdictPolicy] = None, library: Optional[PatternLibrary] = None,
                 library_error: str = ""):
        config.check()
        self.policy = VerdictPolicy() if policy is None else policy
        self.policy.check()
        self.system, self.method, self.config = system, method, config
        self.library, self.library_error = library, library_error
        self.nominal = float(system.motor.nominal_inertia_kgm2 if config.nominal_kgm2 is None
                             else config.nominal_kgm2)
        self.classes = tuple(float(c) for c in (library.classes_kgm2 if library is not None
                                                else system.grid.inertia_classes_kgm2))

    def diagnose(self, window, *, on_estimate: Optional[Callable[[float], Any]] = None,
                 started_at: Optional[float] = None) -> WindowDiagnosis:
        """Diagnose one window: a :class:`WindowInput` or a captured :class:`~jident_ros.stream.layout.Window`.

        on_estimate : called with the published J1 (kg m^2) as soon as it is known: right after the gap fit when
            its estimate is accepted, else after the image method when its class is trusted; never when nothing
            is published
        started_at : ``time.perf_counter()`` when the window arrived (default: now); ``estimate_latency_ms``
            and ``processing_ms`` are measured from it
        """
        win = window if isinstance(window, WindowInput) else WindowInput.from_window(window)
        return _WindowRun(self, win, on_estimate, started_at).run()


class _WindowRun:
    """One window through the steps 0-3 of the module docstring (the state they share)."""

    def __init__(self, diagnoser: Diagnoser, win: WindowInput, on_estimate, started_at):
        self.t0 = time.perf_counter() if started_at is None else float(started_at)
        self.dg, self.win, self.on_estimate = diagnoser, win, on_estimate
        self.vals: list = [] if win.window_id is None else [("window_id", int(win.window_id))]
        self.problems: list = []
        self.latency_ms = None
        self.gap, self.gap_reason, self.width, self.recontact, self.decision = None, "", None, None, None
        self.idn, self.image_cls, self.in_domain, self.domain_reason = None, None, False, ""
        k2 = win.backlash_width_m
        self.k2_unknown = bool(win.backlash_width_unknown) and isinstance(k2, float) and math.isnan(k2)

    # ------------------------------------------------------------------ helpers
    def finish(self, level, status, text, j1=None, source=None, cls=None, **kw):
        """The WindowDiagnosis with the head key/values in front."""
        nominal = self.dg.nominal
        refused = kw.pop("refused_reason", None)
        head = [("status", status)]
        if refused:
            head.append(("refused_reason", refused))
        head += [("identified_class_kgm2", math.nan if cls is None else cls),
                 ("inertia_estimate_kgm2", math.nan if j1 is None else j1),
                 ("estimate_source", source or "none"), ("nominal_kgm2", nominal),
                 ("deviation_percent", math.nan if cls is None else (cls - nominal) / nominal * 100.0)]
        tail = list(kw.pop("tail", []))
        if self.problems:
            tail.append(("problems", "; ".join(self.problems)))
        return WindowDiagnosis(level, text, head + self.vals + tail, j1, source, cls, problems=self.problems,
                               status=status, refused_reason=refused, **kw)

    def publish(self, j1):
        if self.on_estimate is not None:
            self.on_estimate(j1)
        self.latency_ms = (time.perf_counter() - self.t0) * 1e3

    def timing(self):
        return [("estimate_latency_ms", math.nan if self.latency_ms is None else self.latency_ms),
                ("processing_ms", (time.perf_counter() - self.t0) * 1e3)]

    # ------------------------------------------------------------------ the steps
    def run(self) -> WindowDiagnosis:
        refusal = self.check_input()
        if refusal is not None:
            self.problems.append(refusal)
            return self.finish(ERROR, "refused", f"window refused: {refusal}", refused_reason=refusal)
        self.vals.append(("plausible_band_kgm2", list(self.dg.policy.band_kgm2(self.dg.nominal))))
        if self.dg.config.gap_method not in NO_GAP:
            self.gap_step()
        else:
            self.gap_reason = "gap method off"
        self.image_step()
        return self.verdict_step()

    def check_input(self):
        """0. the input: the refusal (one line) or None; the entry time, K2 and p go to the values."""
        w, dg = self.win, self.dg
        refusal = input_refusal(w.data, w.entry_index, w.backlash_width_m, w.wheel_radius_m, w.sample_period_s,
                                system=dg.system, policy=dg.policy, nominal_kgm2=dg.nominal,
                                width_unknown=self.k2_unknown)
        entry_time_s = w.entry_time_s
        if entry_time_s is None and refusal is None and "t" in w.data:
            entry_time_s = float(np.asarray(w.data["t"], float)[w.entry_index])
        if entry_time_s is not None:
            self.vals.append(("entry_time_s", _finite_or_nan(entry_time_s)))
        self.vals += [("backlash_width_m", _finite_or_nan(w.backlash_width_m)), ("p", float(dg.config.p))]
        return refusal

    def gap_step(self):
        """1. the gap: fast; published first when the policy accepts it."""
        w, dg, method = self.win, self.dg, self.dg.config.gap_method
        # raw angles, own K2 or none: the gap from the detector's re-contact row, never |alpha1 - alpha2| < K2/r
        raw_angles = w.width_estimate is not None or self.k2_unknown
        model = dg.policy.drive_model(w.raw_angles, dg.system.motor)
        # layout.FLAG_SHALLOW_GAP, or a bounce before another entry, shorter than the change-point search: no gap fit
        no_fit = SHALLOW_GAP_REASON if w.shallow_gap else _short_bounce(w, model.search_rows(w.sample_period_s))
        if no_fit is not None:
            self.gap_reason = no_fit
            self.problems.append(f"gap: {no_fit}")
            return self.recontact_step()
        data = {(LOAD_ANGLE_KEY if k == "alpha2" else k): v for k, v in w.data.items()} if raw_angles else w.data
        try:
            self.gap = estimate_inertia(data, w.entry_index, w.backlash_width_m, w.wheel_radius_m,
                                        w.sample_period_s, method=None if method == "auto" else method,
                                        bearing_friction_nms_per_rad=dg.system.motor.bearing_friction_nms_per_rad,
                                        recontact_index=w.recontact_index,
                                        entry_uncertainty_samples=w.entry_uncertainty_samples,
                                        # torque accuracy, friction band, offset (x M_b); a real drive's: TYPICAL_DRIVE
                                        model=model)
        except NoGapError as exc:
            self.gap_reason = str(exc)
            self.problems.append(f"gap: {exc}")
        self.recontact_step()
        if self.gap is not None:
            self.decide_gap()

    def recontact_step(self):
        w, gap = self.win, self.gap
        # K2 bounded the gap (or was blamed): checked against zone-centred angles only for a window whose K2 was
        # given (paper detector); a flank window's K2 was measured by its detector on the offset-free relative
        # angle alpha1 - N alpha2 at its re-contact row (issue 20: raw angles read here gave 'r|alpha1 - alpha2|
        # = 25 m')
        if not self.k2_unknown and w.width_estimate is None and (gap is None or gap.interval == "angles"):
            try:
                self.recontact = recontact_check(w.data, w.entry_index, w.backlash_width_m, w.wheel_radius_m)
            except NoGapError as exc:
                self.vals.append(("width_consistent", f"unknown: {exc}"))
        rc = self.recontact
        if rc is not None:
            self.vals += [("width_consistent", rc.consistent), ("recontact_width_m", rc.width_m),
                          ("recontact_width_range_m", list(rc.range_m)), ("recontact_signal", rc.signal)]
            if gap is None and not rc.consistent:
                self.problems.append(width_disagreement(rc, w.backlash_width_m))

    def decide_gap(self):
        w, dg, gap = self.win, self.dg, self.gap
        self.decision = decision = decide_gap(gap, dg.classes, dg.nominal, dg.policy, self.recontact,
                                              w.backlash_width_m)
        if decision.publish:
            self.publish(gap.inertia_kgm2)
        self.vals += [("gap_j1_kgm2", gap.inertia_kgm2), ("gap_ci95_kgm2", list(gap.ci95_kgm2)),
                      ("gap_std_error_kgm2", gap.std_error_kgm2), ("gap_samples", gap.n_samples),
                      ("gap_fit", gap.method), ("gap_model_choice", gap.model_choice or "given"),
                      ("gap_interval", gap.interval),
                      ("gap_residual_rms", gap.residual_rms), ("gap_model_error_kgm2", gap.model_error_kgm2),
                      ("gap_classes_in_ci95_kgm2", list(decision.classes_in_ci)), ("gap_decision", decision.status)]
        if w.width_estimate is not None:
            self.width = w.width_estimate
        elif "alpha1" in w.data and "alpha2" in w.data and not self.k2_unknown:
            try:
                self.width = estimate_backlash_width(w.data, gap.gap_end, w.wheel_radius_m, w.sample_period_s,
                                                     gap.inertia_kgm2)
            except NoGapError as exc:
                self.problems.append(f"backlash width estimate: {exc}")
        if self.width is not None:
            self.vals += [("backlash_width_estimate_m", self.width.width_m),
                          ("backlash_width_estimate_std_m", self.width.std_m),
                          ("backlash_width_estimate_method", self.width.method)]

    def image_step(self):
        """2. the image method, and whether its answer is trusted."""
        if not self.dg.config.image_method:
            return
        if self.k2_unknown:
            self.vals.append(("image_method", "not run: K2 unknown (no load encoder, or no traversal in this window), "
                                             "no library width to compare with"))
            return
        self.identify()
        if self.idn is not None:
            self.image_domain()

    def identify(self):
        w, dg = self.win, self.dg
        if dg.library is None and (dg.library_error or "").startswith(IMAGE_METHOD_OFF):
            self.vals.append(("image_method", "off: no pattern library for this drive"))   # said once per run
            return
        if dg.library is None:
            self.problems.append(dg.library_error or "no pattern library")
            return
        signals = [s for s in SIGNALS if s in w.data]
        if not signals:
            self.problems.append(f"image method: the window has none of {', '.join(SIGNALS)}")
            return
        try:
            sign = rotation_sign(w.data, w.entry_index)
            if sign < 0:    # the library is built forward: a reverse window is mirrored first
                self.vals.append(("image_rotation", "reverse (mirrored)"))
            self.idn = identify_window(mirrored(w.data) if sign < 0 else w.data, w.entry_index,
                                       w.backlash_width_m, dg.library, dg.method, dg.config.p, signals=signals)
        except Exception as exc:
            self.problems.append(f"image method: {type(exc).__name__}: {exc}")

    def image_domain(self):
        w, dg, idn = self.win, self.dg, self.idn
        policy = dg.policy
        self.image_cls = dg.classes[idn.fused_class_index]
        lib_width = float(dg.library.widths_m[idn.width_index])
        self.in_domain, self.domain_reason = image_domain(
            idn.fused_margin, lib_width, float(w.backlash_width_m), float(w.sample_period_s),
            float(dg.system.sampling.sample_period_s), policy, variant=dg.method.variant)
        if self.in_domain and self.recontact is not None and not self.recontact.consistent:
            self.in_domain, self.domain_reason = False, "the window's K2 disagrees with the re-contact"
        self.vals += [("image_class_kgm2", self.image_cls), ("image_margin", idn.fused_margin),
                      ("image_in_domain", self.in_domain), ("image_min_margin", policy.image_min_margin)]
        if not self.in_domain:
            self.vals.append(("image_domain_reason", self.domain_reason))
        self.vals += [("fused_class_kgm2", idn.fused_inertia_kgm2), ("fused_margin", idn.fused_margin),
                      ("library_width_m", lib_width)]
        for s, a in idn.answers.items():
            self.vals += [(f"j1.{s}", a.inertia_kgm2), (f"h.{s}", a.h), (f"margin.{s}", a.margin)]

    @property
    def library_missing(self) -> bool:
        return (self.dg.config.image_method and not self.k2_unknown and self.dg.library is None
                and not (self.dg.library_error or "").startswith(IMAGE_METHOD_OFF))

    @property
    def lib_text(self) -> str:
        return self.dg.library_error or "no pattern library"

    def image_phrase(self, disagree_with: str) -> tuple:
        """(level bump, text) for the image answer next to a gap class."""
        if self.idn is None:
            return OK, ""
        if self.in_domain:
            return WARN, (f"; the image method disagrees: its class {self.image_cls:g} (margin "
                          f"{self.idn.fused_margin:.3g}), {disagree_with}")
        return OK, (f"; information: the image method answers class {self.image_cls:g}, outside its validity "
                    f"domain ({self.domain_reason}): not a warning")

    def verdict_step(self) -> WindowDiagnosis:
        """3. the verdict and the level."""
        gap, decision = self.gap, self.decision
        if gap is not None and decision.status == "accepted":
            return self.accepted()
        if gap is not None and decision.status == "ambiguous":
            return self.ambiguous()
        if gap is not None:  # refused by the policy
            text = f"estimate refused: {decision.reason}; nothing published"
            if self.idn is not None:
                text += (f"; the image method answers class {self.image_cls:g} (margin {self.idn.fused_margin:.3g}), "
                         "not published")
            if self.library_missing:
                text += f"; {self.lib_text}"
            return self.finish(ERROR, "refused", text, gap=gap, identification=self.idn, width=self.width,
                               refused_reason=decision.reason, tail=self.timing())
        if self.idn is not None and self.in_domain:  # no gap: the image method's class, trusted
            return self.image_only()
        if self.idn is not None:
            self.problems.append(f"image method: class {self.image_cls:g} not published: {self.domain_reason}")
        reason = "; ".join(self.problems) or "nothing identified"
        # the gap is there but this window cannot resolve J1 (too short, a standard error above 25 %: a low-torque
        # return traversal, a short gap at a coarse encoder): no J1, nothing against the drive or the monitor's
        # configuration, so not an ERROR (a monitoring user who sees ERROR on every second window learns to ignore
        # it); anything else that went wrong keeps the ERROR
        others = [p for p in self.problems if not p.startswith(("gap: ", "image method: class "))]
        if self.gap_reason and resolution_limited(self.gap_reason) and not others and not self.library_missing:
            return self.finish(OK, "undiagnosed", f"no J1 from this window: {reason}; nothing published",
                               identification=self.idn, width=self.width, refused_reason=reason, tail=self.timing())
        return self.finish(ERROR, "undiagnosed", f"window could not be diagnosed: {reason}", identification=self.idn,
                           width=self.width, refused_reason=reason, tail=self.timing())

    def accepted(self) -> WindowDiagnosis:
        gap, idn, classes, nominal = self.gap, self.idn, self.dg.classes, self.dg.nominal
        verdict = fuse_verdict(classes, None, idn.fused_class_index if idn is not None else None, gap, self.gap_reason)
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
            bump, phrase = self.image_phrase(f"the gap's nearest class {nearest:g}")
            level, text = max(level, bump), text + phrase
        if self.library_missing:
            level, text = ERROR, text.replace(" kg m^2:", " kg m^2 (from the gap only):", 1) + f"; {self.lib_text}"
        tail = _verdict_values(verdict, classes) + self.timing()
        return self.finish(level, status, text, j1, "gap", cls, verdict=verdict, gap=gap, identification=idn,
                           width=self.width, tail=tail)

    def ambiguous(self) -> WindowDiagnosis:
        gap, nominal = self.gap, self.dg.nominal
        j1, se = float(gap.inertia_kgm2), float(gap.std_error_kgm2)
        held = self.decision.classes_in_ci
        reason = self.decision.reason
        if nominal in held or abs(j1 - nominal) <= BETWEEN_Z * se:
            level, note = OK, f"consistent with the nominal {nominal:g}"
        else:
            level, note = WARN, (f"the nominal {nominal:g} is excluded (more than {BETWEEN_Z:g} standard errors "
                                 f"from J1 = {j1:.4g} ± {se:.2g})")
        pub = self.decision.publish   # the continuous J1 with its interval, no class (VerdictPolicy.publish_ambiguous)
        text = (f"J1 = {j1:.5g} ± {se:.2g} kg m^2 published without a class: {reason}; {note}" if pub else
                f"{reason}: no class named, nothing published; {note}")
        if self.idn is not None and self.image_cls not in held:
            bump, phrase = self.image_phrase(f"outside the interval's classes {fmt_classes(held)}")
            level, text = max(level, bump), text + phrase
        if self.library_missing:
            level, text = ERROR, text + f"; {self.lib_text}"
        # a J1 that went out: why no class is named is a value, not a refusal
        return self.finish(level, "ambiguous", text, *((j1, "gap") if pub else ()), gap=gap, identification=self.idn,
                           width=self.width, refused_reason=None if pub else reason,
                           tail=([("no_class_reason", reason)] if pub else []) + self.timing())

    def image_only(self) -> WindowDiagnosis:
        idn, classes, nominal, policy = self.idn, self.dg.classes, self.dg.nominal, self.dg.policy
        j1 = float(self.image_cls)
        self.publish(j1)
        verdict = fuse_verdict(classes, None, idn.fused_class_index, None, self.gap_reason)
        status, level = ("nominal", OK) if j1 == nominal else ("deviating", WARN)
        what = "nominal class" if j1 == nominal else (
            f"class {j1:g} deviates from the nominal {nominal:g} by {(j1 - nominal) / nominal * 100.0:+.1f} %; class")
        text = (f"J1 = {j1:g} kg m^2 (image method, margin {idn.fused_margin:.3g} >= image_min_margin "
                f"{policy.image_min_margin:g}; no gap estimate: {self.gap_reason}): {what} {j1:g}")
        tail = _verdict_values(verdict, classes) + self.timing()
        return self.finish(level, status, text, j1, "image", j1, verdict=verdict, identification=idn,
                           width=self.width, tail=tail)


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
    """Every channel but t with its sign changed: a reverse window as a forward one (docs/method.md, "Reverse rotation")."""
    return {k: (v if k == "t" else -np.asarray(v, float)) for k, v in window_data.items()}


__all__ = ["GAP_METHODS", "Diagnoser", "DiagnosisConfig", "WindowDiagnosis", "WindowInput", "detector_arguments"]
