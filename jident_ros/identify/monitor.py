"""The product's chain in one place: samples -> detector -> window -> diagnosis -> trend.

Where does a window become J1, and which parameters steer it?  Here:

* :func:`make_detector` builds the entry detector from the drive's :class:`~jident_ros.sim.params.SystemConfig`
  and a frozen :class:`DetectorConfig` (the windowing node's ``detector``, ``backlash_width_m``, ``channels``,
  ``gap_tolerance``, ``gear_ratio``): the paper's inequality (1) (:class:`~jident_ros.stream.detector.BacklashDetector`),
  the flank detector (raw encoder angles, no K2: :class:`~jident_ros.stream.flank.FlankDetector`) or the dynamics
  detector (no load encoder: :class:`~jident_ros.stream.dynamics.DynamicsDetector`);
* :class:`~jident_ros.identify.diagnosis.Diagnoser` (built once from
  :class:`~jident_ros.identify.diagnosis.DiagnosisConfig` and the publishing policy
  :class:`~jident_ros.identify.verdict.VerdictPolicy`) diagnoses one window;
* :class:`DriveMonitor` holds the three: ``feed(batch, channels)`` gives the diagnosed windows of a batch (and
  with a tracker, the trend's update), ``finish()`` the end of the data.

The windowing and diagnostic nodes, ``jident diagnose``/``jident trend``, the evaluation and calibration build
these and keep only their own I/O (ROS messages, files, tables).  Plain numpy; never imports rclpy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence

from jident_ros.identify.diagnosis import Diagnoser, WindowDiagnosis
from jident_ros.identify.trend_status import SAME_TRAVERSAL, trend_inputs
from jident_ros.stream.detector import BacklashDetector
from jident_ros.stream.dynamics import DynamicsDetector
from jident_ros.stream.flank import DETECTORS, FlankDetector
from jident_ros.stream.layout import DEFAULT_CHANNELS, REQUIRED_CHANNELS


@dataclass(frozen=True)
class DetectorConfig:
    """How backlash entries are found (the windowing node's parameters of the same names).

    kind : 'paper' (inequality 1 with K2), 'flank' (no K2, raw encoder angles) or 'dynamics' (no load encoder)
    backlash_width_m : K2 of inequality (1), m (the paper detector only)
    channels : the captured channels, ``t`` first
    gap_tolerance : a step of t above this many sample periods is a gap (samples lost)
    gear_ratio : N in delta = alpha1 - N alpha2 (flank and dynamics detectors)
    encoder_counts_per_rev : the encoders' counts per revolution (0: unknown; flank and dynamics detectors)
    """

    kind: str = "paper"
    backlash_width_m: float = 0.005
    channels: tuple = DEFAULT_CHANNELS
    gap_tolerance: float = 1.5
    gear_ratio: float = 1.0
    encoder_counts_per_rev: int = 0

    #: The windowing node parameter (jident_ros/parameters.py, WINDOWING_PARAMS) that describes each field -- its
    #: description, unit, range, choices and whether it changes at run time; None: not a node parameter.
    PARAMETERS = {"kind": "detector", "backlash_width_m": "backlash_width_m", "channels": "channels",
                  "gap_tolerance": "gap_tolerance", "gear_ratio": "gear_ratio",
                  "encoder_counts_per_rev": None}   # known from the recording's truth file only (evaluation)

    @classmethod
    def from_parameters(cls, params, kind: str, channels: Sequence[str]) -> "DetectorConfig":
        """From the windowing node's parameters, with its resolved detector ``kind`` (``auto`` decided) and the
        captured ``channels`` (``t`` first)."""
        return cls(kind, params["backlash_width_m"], tuple(channels), params["gap_tolerance"], params["gear_ratio"])


def make_detector(system, config: DetectorConfig, wheel_radius_m: Optional[float] = None,
                  sample_period_s: Optional[float] = None):
    """The entry detector of ``config.kind`` for the drive ``system`` (its wheel radius, sample period,
    window lengths and nominal J1; ``wheel_radius_m``/``sample_period_s`` override the first two for a drive
    described otherwise, e.g. the second drive's truth file).  ValueError naming the field on a bad value."""
    s = system.sampling
    r = system.load.wheel_radius_m if wheel_radius_m is None else wheel_radius_m
    ts = s.sample_period_s if sample_period_s is None else sample_period_s
    common = dict(channels=tuple(config.channels), samples_before_entry=s.samples_before_entry,
                  samples_from_entry=s.samples_from_entry, gap_tolerance=config.gap_tolerance)
    if config.kind in ("flank", "dynamics"):
        if config.kind == "dynamics":
            return DynamicsDetector(r, ts, gear_ratio=config.gear_ratio,
                                    nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2,
                                    encoder_counts_per_rev=config.encoder_counts_per_rev, **common)
        # the motor's M_b bounds the constant torque the entry's motor-equation fit may take (BACK_CONSTANT_MAX_REL_BASE)
        return FlankDetector(r, ts, gear_ratio=config.gear_ratio, nominal_inertia_kgm2=system.motor.nominal_inertia_kgm2,
                             encoder_counts_per_rev=config.encoder_counts_per_rev,
                             base_torque_nm=system.motor.base.torque_nm, **common)
    if config.kind != "paper":
        raise ValueError(f"detector: expected one of {', '.join(DETECTORS)}, got {config.kind!r}")
    return BacklashDetector(config.backlash_width_m, r, ts, **common)


def required_channels(kind: str) -> tuple:
    """The channels the detector ``kind`` needs in every batch."""
    return ("t", "m_el") if kind == "dynamics" else REQUIRED_CHANNELS


@dataclass
class MonitorResult:
    """One captured window, its diagnosis and (with a tracker) the trend's update (None: nothing to follow)."""

    window: Any
    diagnosis: WindowDiagnosis
    trend: Any = None
    trend_source: Optional[str] = None    # where the trend's width came from: flank, gap or None
    same_traversal_as: Optional[int] = None   # the window id whose gap fit read the same traversal (trend: once)


@dataclass
class DriveMonitor:
    """The chain of one drive: ``feed`` batches, get diagnosed windows.

    detector : an entry detector (:func:`make_detector`), or None when the caller cuts the windows itself
        (then :meth:`window` only)
    diagnoser : the :class:`~jident_ros.identify.diagnosis.Diagnoser`
    tracker : a :class:`~jident_ros.identify.trend.TrendTracker`, or None (no trend); fed through its public
        ``update`` with the diagnostic node's rule (:func:`~jident_ros.identify.trend_status.trend_inputs`)
    on_error : a window whose diagnosis raised gets ``on_error(window, exc)``'s diagnosis instead (the nodes
        and ``jident diagnose`` report it and go on); None: the exception propagates
    """

    detector: Any
    diagnoser: Diagnoser
    tracker: Any = None
    on_error: Optional[Callable[[Any, Exception], WindowDiagnosis]] = None
    events: list = field(default_factory=list)      # the detector's other events (drops), in order
    # the drive-clock span (first, last) of the last gap fit's rows and its window id (:meth:`_same_traversal`)
    _last_gap: Optional[tuple] = field(default=None, repr=False)

    def feed(self, batch, channels: Sequence[str]) -> list:
        """One batch (n x c samples, ``channels`` its column names) -> a :class:`MonitorResult` per window
        captured in it; the detector's other events go to :attr:`events`."""
        out = []
        for ev in self.detector.push(batch, channels):
            if ev.kind == "window":
                out.append(self.window(ev.window))
            else:
                self.events.append(ev)
        return out

    def window(self, win, *, on_estimate: Optional[Callable[[float], Any]] = None,
               started_at: Optional[float] = None) -> MonitorResult:
        """Diagnose one captured window (and update the trend)."""
        try:
            d = self.diagnoser.diagnose(win, on_estimate=on_estimate, started_at=started_at)
        except Exception as exc:
            if self.on_error is None:
                raise
            d = self.on_error(win, exc)
        result = MonitorResult(win, d)
        result.same_traversal_as = self._same_traversal(win, d)
        if self.tracker is not None and result.same_traversal_as is not None:
            # a second window of one traversal (an early entry whose gap fit found the same rows): its J1 and K2 are
            # that traversal's again, and the trend takes each traversal once (counted by reason on /diagnostics)
            self.tracker.count_refused(SAME_TRAVERSAL)
        elif self.tracker is not None:
            j, jse, w, wse, source, refused = trend_inputs(d, self.tracker.config.width_se_floor_m, win)
            result.trend_source = source
            if j is not None or w is not None:
                result.trend = self.tracker.update(win.entry_time_s, j, jse, w, wse, inertia_refused=refused)
            elif refused is not None:   # no estimate at all: counted by reason (the trend status says it)
                self.tracker.count_refused(refused)
        return result

    def _same_traversal(self, win, d) -> Optional[int]:
        """The id of the window before when this window's gap fit covers instants of the drive's clock that the gap
        fit of the window before covered too (both windows read one traversal), else None; remembers this window's
        span for the next one (a window without a gap fit leaves the last one).  The clock is the trend's: the
        window's entry_time_s, its rows sample_period_s apart."""
        g = getattr(d, "gap", None)
        lo, hi = getattr(g, "fit_start", None), getattr(g, "fit_end", None)
        entry, ts = getattr(win, "entry_time_s", None), getattr(win, "sample_period_s", None)
        row0 = getattr(win, "entry_index", None)
        if None in (lo, hi, entry, row0) or not ts or not 0 <= int(lo) < int(hi):
            return None
        at = lambda row: float(entry) + (int(row) - int(row0)) * float(ts)  # noqa: E731
        span = (at(lo), at(int(hi) - 1))
        prev, self._last_gap = self._last_gap, (span, getattr(win, "window_id", 0))
        if prev is not None and span[0] <= prev[0][1] and prev[0][0] <= span[1]:
            self._last_gap = ((min(span[0], prev[0][0]), max(span[1], prev[0][1])), prev[1])
            return prev[1]
        return None

    def finish(self) -> list:
        """The end of the data: the detector's closing events (a window cut off by the end of the data)."""
        return list(self.detector.finish()) if self.detector is not None else []


__all__ = ["DetectorConfig", "DriveMonitor", "MonitorResult", "make_detector", "required_channels"]
