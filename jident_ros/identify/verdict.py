"""The publishing policy of a window's diagnosis: when a J1 goes out, and which status level it gets.

Principle: a J1 is published on ``inertia_estimate`` only when the data support it:

* not from a window whose header or content cannot support an estimate (:func:`input_refusal`: a
  sample period, wheel radius or backlash width <= 0 or non-finite, too few samples, a non-finite
  or absurd value; one line naming the field);
* not outside the plausible band of J1 (:attr:`VerdictPolicy.plausible_min_ratio` ..
  :attr:`~VerdictPolicy.plausible_max_ratio` x the nominal J1);
* not when the backlash width K2 the window was cut with disagrees with the re-contact the dynamics
  show (:func:`recontact_check`: where a1 -- else the second difference of alpha1 -- drops at the
  flank impact, |alpha1 - alpha2| must be K2/r);
* not with a 95 % interval wider than ± :data:`MAX_CI95_HALF_WIDTH_REL` of J1 ("undetermined");
* with a 95 % interval that holds two or more classes ("ambiguous"), the continuous J1 goes out but no class is
  named (:attr:`VerdictPolicy.publish_ambiguous`; false: nothing goes out, the first reading of issue 12);
* not from a guess: the image method's class alone only when its margin clears
  :attr:`VerdictPolicy.image_min_margin` (chosen from an evaluation set by
  :mod:`jident_ros.research.evaluation.verdicts` so that it is wrong in <= 1 % of the windows it answers) and
  the window lies in its validity domain (a library width within
  :attr:`VerdictPolicy.library_width_tolerance` of the window's K2, the library's sample period).

Levels (docs/interfaces.md, "/diagnostics"): a WARN means "look at this drive". OK: the nominal
class (or an ambiguous interval that holds the nominal class); WARN: a deviating class, a J1
between classes, an ambiguous interval that excludes the nominal, or the image method disagreeing
inside its validity domain; ERROR: nothing could be diagnosed (refused input, a refused estimate,
no gap and no trusted image answer).  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Mapping, Optional

import numpy as np

from jident_ros.identify import gap_terms
from jident_ros.identify.gap import GapEstimate, NoGapError, gap_interval
from jident_ros.identify.gap_free import GapModel
from jident_ros.identify.gap_terms import MAX_CI95_HALF_WIDTH_REL, STD_ERROR_TERM_SOURCES, largest_term  # noqa: F401  (re-exported)

#: Window channels whose magnitude is bounded (see :func:`input_bounds`).
BOUNDED = ("m_el", "omega1", "omega2", "a1", "a2", "v2")

#: Re-contact check: (before, after) -- the flanks must meet between ``before`` samples before and
#: ``after`` samples after the end of the gap by the dynamics (gap.gap_interval's 'signature', where
#: a1 -- or the second difference of alpha1 -- drops).  Measured on the 168 grid cases with the true
#: K2 (noise-free, 30 dB, 2^16 and 2^18 encoders): the gap by the angles ends 0..1 samples after the
#: a1 signature's end, -1..2 after the alpha1 one.  A gap that ends later holds loaded samples (a
#: biased J1), so no margin after: a1 (2, 1), alpha1 (3, 2); one sample of margin before.  With K2
#: x1.1 the angle gap ends 1..4 samples after the a1 signature's end, with x0.9 -2..0
#: (`python -m jident_ros.research.evaluation.verdicts stress` shows what this lets through).
RECONTACT_SLACK_SAMPLES = {"a1": (2, 1), "alpha1": (3, 2)}

#: Statuses of a window (``WindowDiagnosis.status``).
STATUSES = ("nominal", "deviating", "between_classes", "ambiguous", "refused", "undiagnosed")


#: What a drive that declares nothing (:meth:`VerdictPolicy.declares_nothing`) is taken for on windows of raw encoder
#: angles when ``assume_typical_drive`` is on: "a few %" of torque accuracy (issue 20), an offset band of 2 % of M_b
#: (an induction motor's friction and windage near rated speed: the DOL drive's 1.8 %), a 1 ms torque response.
#: Chosen on the DOL drive undeclared (the interval covered 1/87 with the exact torque, 75/78 with these; docs/results.md
#: stop 23); tested on the zoo undeclared (ours, the second drive, the vector drive).
TYPICAL_DRIVE = {"torque_accuracy": 0.03, "torque_offset_rel_base": 0.02, "torque_lag_max_s": 1e-3}
#: ... and its motor's bearing friction and windage: a torque against the motion in [0, this x M_b] (the Coulomb band,
#: GapModel.coulomb_friction_max_nm, fitted in the gap where the torque varies enough, else a bounded term around the
#: band's middle).  Friction and windage losses of 4-pole induction motors are 0.5-3 % of their rated output (the
#: larger share on the smaller motors), a torque of that share of M_b at the rated speed; a drive that declares
#: nothing has them all the same (DOL draws, set 2, undeclared: 1 J1 > 10 % off, 49/66 covered, the undeclared b1
#: up to 3.7 % of M_b; docs/results.md "Stop 31").  The published J1 and interval hold the band; the trend reads each
#: window's J1 with the friction at 0 (GapEstimate.trend_fit: a drive-constant bias), else the free-constant fits'
#: scatter and the a1 fit's larger band term (it loses the cross-check to the angle fit) hid the wear scenario's
#: +2.5 % step (docs/trend.md, "What the trend reads of a window").
TYPICAL_FRICTION_REL_BASE = 0.03


@dataclass(frozen=True)
class VerdictPolicy:
    """When a window's J1 is published, and the bounds of a plausible window.

    The diagnostic node's parameters of the same names (jident_ros/parameters.py, config/nodes.yaml;
    docs/interfaces.md) -- a test keeps these defaults equal to them.

    plausible_min_ratio, plausible_max_ratio : the plausible band of J1, x the nominal J1
    image_min_margin : the image method's class is published alone, and its disagreement with the
        gap is a WARN, only at a fused margin (second-smallest over smallest fused H, eq. 33) >= this;
        0 = never (no margin met the 1 % error target on the evaluation set).  Chosen by
        ``python -m jident_ros.research.evaluation.verdicts threshold``
    library_width_tolerance : the image method is in its validity domain only when the library width
        it used is within this fraction of the window's K2
    max_torque_factor : |m_el| above this many base torques M_b is absurd (refused)
    max_speed_factor : |omega1|, |omega2| above this many synchronous speeds Omega_b is absurd; |v2|
        above r times that; |a1|, |a2| above r x (max torque) / (plausible_min_ratio x nominal J1)
    torque_accuracy : the drive's torque estimate (m_el) scale-error bound, fraction (0.02 = 2 %): J1 a/sqrt(3)
        in every gap fit's standard error, so in the 95 % interval and the 'between classes' test
    coulomb_friction_max_nm : the motor's Coulomb (bearing) friction lies in [0, this], N m: fitted in the gap
        inside that band when the torque varies enough, else a bounded term of the standard error
    viscous_friction_band_nms_per_rad : the viscous friction is motor.bearing_friction_nms_per_rad ± this,
        N m s/rad (a bounded term)
    torque_offset_rel_base : an unknown constant torque in the gap (the torque estimate's offset, friction
        that b1 and the Coulomb band leave out) lies within ± this × the base torque M_b: a bounded term of
        every gap fit's standard error (GapModel.torque_offset_nm)
    torque_lag_max_s : the torque estimate lags (or leads) the shaft's torque by at most this, s: a bounded term
        of the angle and a1 fits' standard error (GapModel.torque_lag_s; the speed fit fits its own lag)
    torque_delay_s : the torque estimate's known delay behind the shaft's torque, s (reported N drive cycles late:
        N·T_s): m_el is advanced by it before the gap fits, and torque_lag_max_s bounds what remains
        (GapModel.torque_delay_s)
    torque_filter_s : the time constant of a first-order low-pass the drive applies to its torque estimate (a smoothed
        'actual torque'), s: undone before the gap fits (GapModel.torque_filter_s)
    encoder_accuracy_rad : the motor encoder's angle error is at most this, rad, once and twice per revolution (its
        data sheet's accuracy: an optical encoder tens of arc seconds, a resolver ± 10 arc minutes = 2.9e-3): a
        bounded term of the angle fits' standard error (GapModel.encoder_error_rad; 0: an exact disc)
    coupling_release_max_s : the coupling lets go of the motor within this time after its torque starts to fall, s
        (about a quarter period of the load on the coupling, (π/2)·√(J_load/k); 0: a rigid contact, lost at once):
        the steady-entry fit searches the unloading times up to it (GapModel.coupling_release_s; docs/method.md)
    publish_ambiguous : a gap J1 whose 95 % interval (within ± MAX_CI95_HALF_WIDTH_REL) holds two or more
        classes is published as a continuous J1 with its interval, no class named (status 'ambiguous'); False:
        nothing is published for it (issue 12's first reading: a plotted J1 looks like a result).  The J1 is what
        the data support (issue 20: JointState windows hold J1 to ± 2..10 %, classes are 2.5 % apart); the class is
        what they do not
    """

    plausible_min_ratio: float = 0.5
    plausible_max_ratio: float = 1.5
    image_min_margin: float = 1.401117   # python -m jident_ros.research.evaluation.verdicts threshold
    library_width_tolerance: float = 0.05
    max_torque_factor: float = 100.0
    max_speed_factor: float = 10.0
    # the gap fits' drive model (jident_ros.identify.gap_free.GapModel; issue 20)
    torque_accuracy: float = 0.0
    coulomb_friction_max_nm: float = 0.0
    viscous_friction_band_nms_per_rad: float = 0.0
    torque_offset_rel_base: float = 0.01   # chosen on the vector drive (docs/method.md "Torque offset")
    torque_lag_max_s: float = 0.0
    torque_delay_s: float = 0.0
    torque_filter_s: float = 0.0
    encoder_accuracy_rad: float = 0.0
    coupling_release_max_s: float = 4e-3   # gap_kink.KINK_UNLOAD_ROWS' longest (docs/method.md)
    assume_typical_drive: bool = True
    publish_ambiguous: bool = True

    def gap_model(self, base_torque_nm: float = 0.0) -> GapModel:
        """The gap fits' drive model from this policy's torque accuracy, friction band and torque offset
        (``base_torque_nm``: the motor's M_b, which scales torque_offset_rel_base)."""
        return GapModel(torque_accuracy=float(self.torque_accuracy),
                        coulomb_friction_max_nm=float(self.coulomb_friction_max_nm),
                        viscous_friction_band_nms_per_rad=float(self.viscous_friction_band_nms_per_rad),
                        torque_offset_nm=float(self.torque_offset_rel_base) * abs(float(base_torque_nm)),
                        torque_lag_s=float(self.torque_lag_max_s),
                        torque_delay_s=float(self.torque_delay_s),
                        torque_filter_s=float(self.torque_filter_s),
                        encoder_error_rad=float(self.encoder_accuracy_rad),
                        coupling_release_s=float(self.coupling_release_max_s))

    def drive_model(self, raw_angles: bool, motor) -> GapModel:
        """The gap fits' model of a window (``raw_angles``: a flank- or dynamics-detector window, a real drive's
        recording: :meth:`for_raw_angles`) on ``motor`` (its b1 and M_b)."""
        policy = self.for_raw_angles(motor.bearing_friction_nms_per_rad, motor.base.torque_nm) if raw_angles else self
        return policy.gap_model(motor.base.torque_nm)

    def declares_nothing(self, bearing_friction_nms_per_rad: float = 0.0) -> bool:
        """No torque accuracy, friction band, torque lag or b1 declared (the defaults: our simulator's exact torque)."""
        return not (self.torque_accuracy or self.coulomb_friction_max_nm or self.viscous_friction_band_nms_per_rad
                    or self.torque_lag_max_s or bearing_friction_nms_per_rad)

    def for_raw_angles(self, bearing_friction_nms_per_rad: float = 0.0, base_torque_nm: float = 0.0) -> "VerdictPolicy":
        """The policy for a window of raw encoder angles (a real drive's recording): :data:`TYPICAL_DRIVE` and a
        friction band of :data:`TYPICAL_FRICTION_REL_BASE` x ``base_torque_nm`` (the motor's M_b) when the drive
        declares nothing and ``assume_typical_drive`` is on (the offset band at least as declared), else this one."""
        if not (self.assume_typical_drive and self.declares_nothing(bearing_friction_nms_per_rad)):
            return self
        typical = dict(TYPICAL_DRIVE, torque_offset_rel_base=max(TYPICAL_DRIVE["torque_offset_rel_base"],
                                                                 self.torque_offset_rel_base),
                       coulomb_friction_max_nm=TYPICAL_FRICTION_REL_BASE * abs(float(base_torque_nm)))
        return replace(self, **typical)

    def undeclared_note(self, bearing_friction_nms_per_rad: float = 0.0) -> str:
        """One line when the drive declares no torque accuracy, friction or torque lag, '' otherwise (docs/results.md,
        stop 23: the DOL drive undeclared and taken as exact, the intervals covered 1/87)."""
        if not self.declares_nothing(bearing_friction_nms_per_rad):
            return ""
        keys = ("(torque_accuracy, coulomb_friction_max_nm, viscous_friction_band_nms_per_rad, torque_lag_max_s, "
                "motor.bearing_friction_nms_per_rad are 0)")
        if self.assume_typical_drive:
            return (f"the drive declares no torque accuracy, friction or torque lag {keys}: windows of raw encoder "
                    f"angles are diagnosed as a typical drive's (torque accuracy {TYPICAL_DRIVE['torque_accuracy']:.0%}, "
                    f"offset {TYPICAL_DRIVE['torque_offset_rel_base']:.0%} of M_b, lag "
                    f"{1e3 * TYPICAL_DRIVE['torque_lag_max_s']:g} ms, bearing friction up to "
                    f"{TYPICAL_FRICTION_REL_BASE:.0%} of M_b); declare your drive's (docs/your_drive.md)")
        return (f"the drive declares no torque accuracy, friction or torque lag {keys} and assume_typical_drive is "
                "false: the intervals assume an exact torque estimate and a frictionless motor")

    @classmethod
    def from_params(cls, params: Mapping) -> "VerdictPolicy":
        """The policy from a parameter dict (the diagnostic node's); missing keys take the defaults."""
        return cls(**{f.name: (params[f.name] if isinstance(f.default, bool) else float(params[f.name]))
                      for f in fields(cls) if f.name in params})

    def problems(self) -> list:
        """(field, what it must be) for every invalid field; empty when valid."""
        out = []
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(f.default, bool):
                if not isinstance(v, bool):
                    out.append((f.name, "true or false"))
                continue
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v)):
                out.append((f.name, "a finite number"))
        if out:
            return out
        if not 0 < self.plausible_min_ratio < 1:
            out.append(("plausible_min_ratio", "a number in (0, 1)"))
        if not self.plausible_max_ratio > 1:
            out.append(("plausible_max_ratio", "a number > 1"))
        if not (self.image_min_margin == 0 or self.image_min_margin >= 1):
            out.append(("image_min_margin", "0 (never) or a margin >= 1"))
        for name in ("library_width_tolerance", "max_torque_factor", "max_speed_factor"):
            if not getattr(self, name) > 0:
                out.append((name, "a number > 0"))
        if not 0 <= self.torque_accuracy < 0.5:
            out.append(("torque_accuracy", "a fraction in [0, 0.5)"))
        for name in ("coulomb_friction_max_nm", "viscous_friction_band_nms_per_rad"):
            if not getattr(self, name) >= 0:
                out.append((name, "a number >= 0"))
        if not 0 <= self.torque_offset_rel_base < 1:
            out.append(("torque_offset_rel_base", "a fraction in [0, 1)"))
        if not 0 <= self.torque_lag_max_s <= 1:
            out.append(("torque_lag_max_s", "a time in [0, 1] s"))
        if not 0 <= self.encoder_accuracy_rad <= 0.1:
            out.append(("encoder_accuracy_rad", "an angle in [0, 0.1] rad"))
        if not 0 <= self.coupling_release_max_s <= 1:
            out.append(("coupling_release_max_s", "a time in [0, 1] s"))
        return out

    def check(self) -> None:
        """ValueError 'field: must be ..., got ...' for the first invalid field."""
        for name, what in self.problems():
            raise ValueError(f"{name}: must be {what}, got {getattr(self, name)!r}")

    def band_kgm2(self, nominal_kgm2: float) -> tuple:
        return self.plausible_min_ratio * nominal_kgm2, self.plausible_max_ratio * nominal_kgm2


# --------------------------------------------------------------------------- input


def input_bounds(system, policy: VerdictPolicy, wheel_radius_m: float, nominal_kgm2: float) -> dict:
    """Bounds of a plausible window: channel -> (bound of |value|, unit, why), from the configuration."""
    base = system.motor.base
    t_max = policy.max_torque_factor * base.torque_nm
    w_max = policy.max_speed_factor * base.mechanical_speed_rad_s
    a_max = wheel_radius_m * t_max / (policy.plausible_min_ratio * nominal_kgm2)
    return {
        "m_el": (t_max, "N m", f"{policy.max_torque_factor:g} x the base torque M_b {base.torque_nm:.4g} N m"),
        "omega1": (w_max, "rad/s", f"{policy.max_speed_factor:g} x the synchronous speed "
                                   f"{base.mechanical_speed_rad_s:.4g} rad/s"),
        "omega2": (w_max, "rad/s", f"{policy.max_speed_factor:g} x the synchronous speed "
                                   f"{base.mechanical_speed_rad_s:.4g} rad/s"),
        "v2": (wheel_radius_m * w_max, "m/s", "r x the speed bound"),
        "a1": (a_max, "m/s^2", "r x the torque bound / the smallest plausible J1"),
        "a2": (a_max, "m/s^2", "r x the torque bound / the smallest plausible J1"),
    }


def _positive(name: str, v) -> Optional[str]:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return f"{name}: must be a finite number > 0, got {v!r}"
    if not (math.isfinite(x) and x > 0):
        return f"{name}: must be a finite number > 0, got {x!r}"
    return None


def input_refusal(window: Mapping, entry_index, backlash_width_m, wheel_radius_m, sample_period_s, *,
                  system, policy: VerdictPolicy, nominal_kgm2: float, width_unknown: bool = False) -> Optional[str]:
    """Why the window's header or content cannot support an estimate (one line naming the field and
    the value), or None.  Checks, in order: the header values (sample period, wheel radius, backlash
    width > 0 and finite), the channels (1-D, all of one length), the length (at least the configured
    ``sampling.samples_before_entry`` before the entry and ``samples_from_entry`` from it), every value
    finite, and the magnitudes of :func:`input_bounds`.  ``width_unknown``: K2 is not known (NaN, a
    dynamics-detector window without a load encoder) and not checked."""
    header = (("sample_period_s", sample_period_s), ("wheel_radius_m", wheel_radius_m))
    for name, v in header + (() if width_unknown else (("backlash_width_m", backlash_width_m),)):
        why = _positive(name, v)
        if why:
            return why
    if not window:
        return "channels: the window holds no channel"
    arrays = {}
    for name, v in window.items():
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            return f"channel {name}: not numeric"
        if a.ndim != 1:
            return f"channel {name}: expected one value per sample, got shape {a.shape}"
        arrays[name] = a
    lengths = {a.size for a in arrays.values()}
    n = max(lengths)
    if len(lengths) > 1:
        bad = next(k for k, a in arrays.items() if a.size != n)
        return f"channel {bad}: {arrays[bad].size} samples, the window's other channels have {n}"
    s = system.sampling
    if isinstance(entry_index, bool) or not isinstance(entry_index, (int, np.integer)):
        return f"entry_index: must be an integer, got {entry_index!r}"
    need = s.samples_before_entry + s.samples_from_entry
    if n < need:
        return (f"samples: {n} in the window, need >= {need} (sampling.samples_before_entry "
                f"{s.samples_before_entry} + samples_from_entry {s.samples_from_entry})")
    if not s.samples_before_entry <= entry_index <= n - s.samples_from_entry:
        return (f"entry_index: {entry_index} leaves {entry_index} samples before the entry and {n - entry_index} "
                f"from it; need >= {s.samples_before_entry} and >= {s.samples_from_entry}")
    for name, a in arrays.items():
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            return f"channel {name}: non-finite value {float(a[bad[0]])!r} at sample {int(bad[0])}"
    for name, (bound, unit, why) in input_bounds(system, policy, float(wheel_radius_m), nominal_kgm2).items():
        if name in arrays:
            k = int(np.argmax(np.abs(arrays[name])))
            if abs(arrays[name][k]) > bound:
                return (f"channel {name}: |value| {abs(arrays[name][k]):.4g} {unit} at sample {k} exceeds the "
                        f"plausible {bound:.4g} {unit} ({why})")
    return None


# --------------------------------------------------------------------------- width consistency


@dataclass(frozen=True)
class RecontactCheck:
    """Where the dynamics show the load coming back, and whether the window's K2 agrees with it.

    signature_end : first sample after the gap by the dynamics (gap.gap_interval's 'signature')
    signal : 'a1' or 'alpha1' (its second difference)
    width_m : r |alpha1 - alpha2| at re-contact (midpoint of the samples around signature_end), m
    range_m : (lo, hi) the width range consistent with the dynamics (RECONTACT_SLACK_SAMPLES), m:
        r |alpha1 - alpha2| from ``before`` samples before to ``after`` samples after signature_end
    consistent : the window's K2 lies in range_m
    """

    signature_end: int
    signal: str
    width_m: float
    range_m: tuple
    consistent: bool


def recontact_check(window: Mapping, entry_index: int, backlash_width_m: float,
                    wheel_radius_m: float) -> RecontactCheck:
    """Compare K2 with the re-contact the dynamics show.  Needs alpha1, alpha2 and a1 (else the
    second difference of alpha1); raises :class:`NoGapError` with the reason when it cannot tell."""
    if "alpha1" not in window or "alpha2" not in window:
        raise NoGapError("needs alpha1 and alpha2")
    signal = "a1" if "a1" in window else "alpha1"
    _, end, _ = gap_interval({signal: window[signal]}, entry_index, backlash_width_m, wheel_radius_m)
    rel = np.abs(np.asarray(window["alpha1"], float) - np.asarray(window["alpha2"], float))
    n = rel.size
    before, after = RECONTACT_SLACK_SAMPLES[signal]
    lo_i = max(entry_index, end - before)
    hi_i = min(n - 1, end + after)
    r = wheel_radius_m
    lo, hi = r * float(rel[lo_i:end + 1].min()), r * float(rel[end:hi_i + 1].max())
    width = 0.5 * r * (float(rel[max(end - 1, entry_index)]) + float(rel[min(end + 1, n - 1)]))
    return RecontactCheck(int(end), signal, width, (lo, hi), bool(lo <= backlash_width_m <= hi))


# --------------------------------------------------------------------------- classes


def classes_in_interval(interval, classes) -> list:
    """The classes (kg m^2) inside a closed interval, in increasing order."""
    lo, hi = interval
    return sorted(float(c) for c in classes if lo <= c <= hi)


def fmt_classes(cls) -> str:
    return ", ".join(f"{c:g}" for c in cls)


@dataclass(frozen=True)
class GapDecision:
    """Whether the gap estimate may be published.

    status : 'accepted', 'ambiguous' or 'refused'
    reason : one line (why no class, or why nothing is published), '' when accepted
    classes_in_ci : the classes inside the 95 % interval
    publish : the continuous J1 goes out on ``inertia_estimate`` (accepted; ambiguous over classes with
        :attr:`VerdictPolicy.publish_ambiguous`)
    """

    status: str
    reason: str
    classes_in_ci: tuple
    publish: bool = False


#: A gap J1 outside the plausible band is refused as a configuration problem ("a wrong K2, radius or torque
#: scale?", ERROR) only when its interval says so: where the interval is wider than MAX_CI95_HALF_WIDTH_REL and reaches
#: into the band, the window cannot tell a wrong configuration from its own resolution, and it is undetermined like
#: any other wide interval (level by the nominal, nothing published).  The vector draws' speed steps with an Imu at
#: 30 dB: 2.06 +- 0.56 kg m^2 against a band up to 1.74, ERROR on healthy drives (5 windows over 42 sets; the DOL
#: draws: 0.51 +- 0.18 against 0.58).  A J1 pinned outside the band stays refused.  False: the point estimate alone
#: (stop 42).
BAND_BY_INTERVAL = True


def decide_gap(gap: GapEstimate, classes, nominal_kgm2: float, policy: VerdictPolicy,
               recontact: Optional[RecontactCheck], backlash_width_m: float) -> GapDecision:
    """Publish the gap estimate or not (module docstring): plausible band, width consistency,
    ambiguity (two or more classes in the 95 % interval)."""
    j1 = gap.inertia_kgm2
    held = tuple(classes_in_interval(gap.ci95_kgm2, classes))
    lo, hi = policy.band_kgm2(nominal_kgm2)
    half = 0.5 * (gap.ci95_kgm2[1] - gap.ci95_kgm2[0])
    if not lo <= j1 <= hi:
        a, b = gap.ci95_kgm2
        if BAND_BY_INTERVAL and not half <= gap_terms.MAX_CI95_HALF_WIDTH_REL * j1 and a <= hi and b >= lo:
            return GapDecision("ambiguous", f"undetermined: J1 = {j1:.4g} kg m^2 lies outside the plausible band "
                                            f"{lo:.4g}..{hi:.4g} kg m^2 but its 95 % interval {a:.4g}..{b:.4g} (± "
                                            f"{100 * half / j1:.3g} %) reaches into it: it cannot tell a wrong "
                                            f"configuration{widest_term(gap)}", held)
        return GapDecision("refused", f"J1 = {j1:.4g} kg m^2 is outside the plausible band {lo:.4g}..{hi:.4g} "
                                      f"kg m^2 ({policy.plausible_min_ratio:g}..{policy.plausible_max_ratio:g} x "
                                      f"the nominal {nominal_kgm2:g}); a wrong K2, radius or torque scale?", held)
    if recontact is not None and not recontact.consistent:
        return GapDecision("refused", width_disagreement(recontact, backlash_width_m), held)
    if not half <= gap_terms.MAX_CI95_HALF_WIDTH_REL * j1:
        a, b = gap.ci95_kgm2
        return GapDecision("ambiguous", f"undetermined: 95 % interval {a:.4g}..{b:.4g} kg m^2 is ± "
                                      f"{100 * half / j1:.3g} % of J1 (> ± {100 * gap_terms.MAX_CI95_HALF_WIDTH_REL:g} %): it cannot tell "
                                      f"a {100 * gap_terms.MAX_CI95_HALF_WIDTH_REL:g} % change{widest_term(gap)}", held)
    if len(held) >= 2:
        a, b = gap.ci95_kgm2
        return GapDecision("ambiguous", f"ambiguous: 95 % interval {a:.4g}..{b:.4g} kg m^2 holds classes "
                                        f"{fmt_classes(held)}", held, publish=bool(policy.publish_ambiguous))
    return GapDecision("accepted", "", held, publish=True)


def widest_term(gap: GapEstimate) -> str:
    """'; the largest part: ...' for an undetermined gap J1: which part of its standard error
    (:data:`~jident_ros.identify.gap_terms.STD_ERROR_TERM_SOURCES`) widens its interval most, as ± % of J1 (the
    interval's half-width times that part's share of the standard error), and the parameter that bounds it: a
    drive declared too loosely can be declared tighter there; a part only the data narrow says so.  '' when the
    estimate carries no parts."""
    top = largest_term(getattr(gap, "std_error_terms", ()))
    if top is None or not gap.inertia_kgm2:
        return ""
    name, part = top
    se = float(gap.std_error_kgm2)
    if not (math.isfinite(se) and se > 0.0):
        return ""
    half = 0.5 * (gap.ci95_kgm2[1] - gap.ci95_kgm2[0])   # the interval's own quantile times se
    what, param = STD_ERROR_TERM_SOURCES.get(name, (name, None))
    where = f"bounded by {param}" if param else "only more data narrow it"
    return f"; the largest part: {what}, ± {100 * half * part / se / abs(gap.inertia_kgm2):.3g} % ({where})"


def width_disagreement(rc: RecontactCheck, backlash_width_m: float) -> str:
    return (f"backlash_width_m: the window's K2 = {backlash_width_m:.4g} m disagrees with the re-contact in the "
            f"dynamics ({rc.signal} drops at sample {rc.signature_end}, where r|alpha1 - alpha2| = "
            f"{rc.range_m[0]:.4g}..{rc.range_m[1]:.4g} m, about {rc.width_m:.4g} m)")


# --------------------------------------------------------------------------- image method


#: The method variants whose margins ``image_min_margin`` was chosen on (``python -m
#: jident_ros.research.evaluation.verdicts threshold`` runs the paper-faithful distances, eq. 33).  Another variant's
#: margins are on another scale (sensor_matched: distances in units of the seed-to-seed scatter), so its class
#: is information only until a threshold is chosen for it.
MARGIN_CALIBRATED_VARIANTS = ("paper",)


def image_domain(fused_margin: float, library_width_m: float, backlash_width_m: float, sample_period_s: float,
                 library_sample_period_s: float, policy: VerdictPolicy, variant: str = "paper") -> tuple:
    """(inside, reason): is the image method's answer trusted (publishable alone; its disagreement a
    WARN)?  Inside when image_min_margin > 0 and was chosen for this method ``variant``, the fused margin >=
    it, the library width within library_width_tolerance of the window's K2, and the window's sample period
    the library's."""
    if policy.image_min_margin <= 0:
        return False, "image_min_margin 0: the image method never answers alone"
    if variant not in MARGIN_CALIBRATED_VARIANTS:
        return False, (f"image_min_margin was chosen for variant(s) {', '.join(MARGIN_CALIBRATED_VARIANTS)}, not "
                       f"'{variant}' (its margins are on another scale)")
    if not fused_margin >= policy.image_min_margin:
        return False, f"its margin {fused_margin:.4g} is below image_min_margin {policy.image_min_margin:g}"
    if abs(library_width_m - backlash_width_m) > policy.library_width_tolerance * backlash_width_m:
        return False, (f"its library width {library_width_m:g} m is not within "
                       f"{policy.library_width_tolerance:.0%} of the window's K2 {backlash_width_m:.4g} m")
    if abs(sample_period_s - library_sample_period_s) > 1e-6 * library_sample_period_s:
        return False, (f"the library is built for T_s = {library_sample_period_s:g} s, the window has "
                       f"{sample_period_s:g} s")
    return True, ""


__all__ = ["BOUNDED", "MARGIN_CALIBRATED_VARIANTS", "RECONTACT_SLACK_SAMPLES", "STATUSES", "GapDecision", "RecontactCheck", "VerdictPolicy",
           "classes_in_interval", "decide_gap", "fmt_classes", "image_domain", "input_bounds", "input_refusal",
           "recontact_check", "widest_term", "width_disagreement"]
