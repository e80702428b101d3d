"""The drive's topic names and channel layouts: the std_msgs/Float64MultiArray contract of
``drive/signals`` and ``drive/window`` (docs/interfaces.md), as plain numpy (never imports rclpy).

Layout of a batch / window as ``std_msgs/Float64MultiArray``::

    layout.dim[0]: label "sample",                      size n, stride n * c
    layout.dim[1]: label "t,alpha1,alpha2,...",         size c, stride c
    layout.data_offset: number of header values in front of the samples (0 for drive/signals)
    data: header values, then the n x c samples, row-major (sample-major)

:func:`pack` and :func:`unpack` convert between numpy and this layout using plain tuples
``(label, size, stride)`` for the dims (:mod:`jident_ros.nodes.ros_io` moves them into and out of the
ROS message).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from jident_ros.sim.simulate import CHANNELS

#: Relative names of the drive's topics (docs/interfaces.md), as recordings hold them under any namespace.
SIGNALS_TOPIC = "drive/signals"
WIDTH_TOPIC = "drive/backlash_width"
TRUE_INERTIA_TOPIC = "drive/true_inertia"
CASE_TOPIC = "drive/case"
DRIVE_TOPICS = (SIGNALS_TOPIC, WIDTH_TOPIC, TRUE_INERTIA_TOPIC, CASE_TOPIC)
#: Channels of a drive/case message (one row per case, published by the simulator).
CASE_LABEL = "case_index,inertia_kgm2,backlash_width_m,consistency_pa_sn,entry_time_s"


def topic_matches(topic: str, relative: str) -> bool:
    """True when a recorded (absolute) topic name is ``relative`` in some namespace
    (``/press3/drive/signals`` matches ``drive/signals``)."""
    return topic == relative or topic == "/" + relative or topic.endswith("/" + relative)

#: Label of dim[0] (rows = samples).
SAMPLE_LABEL = "sample"
#: Channel names a batch may carry ("t" = drive clock, s).
KNOWN_CHANNELS = ("t",) + tuple(CHANNELS) + ("clutch_torque",)
#: Channels without which inequality (1) cannot be evaluated.
REQUIRED_CHANNELS = ("t", "alpha1", "alpha2")
#: Default channel set of a window: the drive clock then every simulator channel.
DEFAULT_CHANNELS = ("t",) + tuple(CHANNELS)

#: Window header of format 1 (data_offset values in front of the samples of drive/window), in this order.
WINDOW_HEADER_1 = ("format", "entry_index", "entry_time_s", "backlash_width_m", "wheel_radius_m",
                   "sample_period_s", "window_id")
#: Window header of format 2 (written by this version): format 1's fields, then what the detector learnt.
WINDOW_HEADER = WINDOW_HEADER_1 + ("backlash_width_estimate_m", "backlash_width_se_m", "detector", "flags",
                                   "recontact_index")
WINDOW_FORMAT = 2.0
#: Formats this version reads, with their header lengths.
WINDOW_FORMATS = {1.0: len(WINDOW_HEADER_1), 2.0: len(WINDOW_HEADER)}
#: Header field ``detector``: which detector captured the window.
DETECTOR_CODES = {"paper": 0, "flank": 1, "dynamics": 2}
#: The detectors whose windows hold raw encoder angles (a real drive's recording; the paper's: zone-centred angles).
RAW_ANGLE_DETECTORS = ("flank", "dynamics")
#: Header field ``flags`` (bits): another zone entry lies inside the window (information) ...
FLAG_SECOND_ENTRY = 1
#: ... the data ended before the window was complete (a partial window, reported, never published).
FLAG_CUT_OFF = 2
#: ... the flank detector's shallow gap (flank_window.SHALLOW_*: a slip drop's few samples past the coupling's zero twist):
#: its entry and K2 count, its J1 is not fitted (identify.diagnosis.SHALLOW_GAP_REASON)
FLAG_SHALLOW_GAP = 4
#: ... the flank detector's excursion came back to the flank it left (a bounce, no traversal: K2 not observable);
#: nothing but the motor's own fit shows that the coupling let go (identify.diagnosis: a short one that goes on to
#: another entry in the window, FLAG_SECOND_ENTRY, gets no J1: gap.SHORT_BOUNCE_REASON)
FLAG_BOUNCE = 8
FLAG_NAMES = {FLAG_SECOND_ENTRY: "second_entry", FLAG_CUT_OFF: "cut_off", FLAG_SHALLOW_GAP: "shallow_gap",
              FLAG_BOUNCE: "bounce"}


def flag_names(flags: int) -> list:
    """Names of the bits set in a window's ``flags``."""
    return [name for bit, name in FLAG_NAMES.items() if int(flags) & bit]


class LayoutError(ValueError):
    """A message does not follow the documented layout (reason ``layout``)."""


# --------------------------------------------------------------------------- layout


def channel_label(channels: Sequence[str]) -> str:
    """dim[1] label: channel names joined by commas."""
    return ",".join(channels)


def parse_channel_label(label: str) -> tuple:
    """Channel names of a dim[1] label; raises LayoutError on empty or repeated names.  Cached: every batch of a
    stream carries the same label (a per-message parse was 1/4 of unpack's cost, issue 25)."""
    return _parse_channel_label(str(label))


@functools.lru_cache(maxsize=64)
def _parse_channel_label(label: str) -> tuple:
    names = tuple(s.strip() for s in label.split(","))
    if not label or any(not s for s in names):
        raise LayoutError(f"dim[1].label {label!r}: expected comma-separated channel names")
    if len(set(names)) != len(names):
        dup = sorted({s for s in names if names.count(s) > 1})
        raise LayoutError(f"dim[1].label {label!r}: repeated channel {dup[0]!r}")
    return names


def pack(array: np.ndarray, channels: Sequence[str], header: Sequence[float] = ()):
    """Numpy (n, c) + channel names -> (flat float64 data, dims, data_offset).

    dims is a list of (label, size, stride) for dim[0] (samples) and dim[1] (channels).
    """
    a = np.asarray(array, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != len(channels):
        raise ValueError(f"array: expected shape (n, {len(channels)}), got {a.shape}")
    n, c = a.shape
    head = np.asarray(header, dtype=np.float64).ravel()
    data = np.concatenate([head, a.ravel()]) if head.size else np.ascontiguousarray(a).ravel()
    dims = [(SAMPLE_LABEL, n, n * c), (channel_label(channels), c, c)]
    return data, dims, int(head.size)


def unpack(data, dims: Sequence, data_offset: int = 0):
    """(flat data, dims, data_offset) -> (array (n, c) view, channel names, header array).

    ``dims`` holds (label, size, stride) tuples or objects with those attributes (a ROS
    MultiArrayDimension).  Raises :class:`LayoutError` with what is wrong.
    """
    dims = [_dim_tuple(d) for d in dims]
    if len(dims) != 2:
        raise LayoutError(f"layout.dim: expected 2 dimensions (sample, channel), got {len(dims)}")
    (l0, n, s0), (l1, c, s1) = dims
    if l0 != SAMPLE_LABEL:
        raise LayoutError(f"dim[0].label: expected {SAMPLE_LABEL!r}, got {l0!r}")
    channels = parse_channel_label(l1)
    if c != len(channels):
        raise LayoutError(f"dim[1].size {c} does not match the {len(channels)} channels named in its label")
    if c < 1:
        raise LayoutError("dim[1].size: need at least one channel")
    if s1 != c or s0 != n * c:
        raise LayoutError(f"strides ({s0}, {s1}): expected ({n * c}, {c}) for a row-major {n} x {c} array")
    off = int(data_offset)
    flat = np.asarray(data, dtype=np.float64)
    if flat.ndim != 1:
        flat = flat.ravel()
    if off < 0 or flat.size != off + n * c:
        raise LayoutError(f"data: {flat.size} values, expected data_offset {off} + {n} x {c} = {off + n * c}")
    return flat[off:].reshape(n, c), channels, flat[:off]


def _dim_tuple(d):
    if isinstance(d, (tuple, list)):
        label, size, stride = d
    else:
        label, size, stride = d.label, d.size, d.stride
    try:
        return str(label), int(size), int(stride)
    except (TypeError, ValueError):
        raise LayoutError(f"layout.dim: size/stride must be integers, got {size!r}/{stride!r}") from None


# --------------------------------------------------------------------------- window


@dataclass
class Window:
    """A captured window: samples_before + samples_from rows, the entry at ``entry_index``.

    Attributes
    ----------
    data : ndarray (n, c)          samples, columns ``channels`` (SI units)
    channels : tuple of str        column names, "t" first
    entry_index : int              row of the entry sample (48)
    entry_time_s : float           t of the entry sample (drive clock)
    backlash_width_m : float       K2 used by the detector for this window (paper detector); the flank
                                   detector, which needs none, writes its estimate here (NaN: none)
    wheel_radius_m : float         r used in inequality (1)
    sample_period_s : float
    window_id : int                running number of captured windows (from 1)
    backlash_width_estimate_m : float   K2 estimated from this traversal (flank detector), m; NaN: none
    backlash_width_se_m : float    its standard uncertainty, m; NaN: none
    detector : str                 "paper" (inequality 1 with a given K2), "flank" (no K2 needed) or
                                   "dynamics" (no angles needed: the load-torque step)
    flags : int                    FLAG_SECOND_ENTRY | FLAG_CUT_OFF | FLAG_SHALLOW_GAP bits
    recontact_index : int          row where the flanks meet again (the first contact sample), -1: unknown
    """

    data: np.ndarray
    channels: tuple
    entry_index: int
    entry_time_s: float
    backlash_width_m: float
    wheel_radius_m: float
    sample_period_s: float
    window_id: int = 0
    backlash_width_estimate_m: float = float("nan")
    backlash_width_se_m: float = float("nan")
    detector: str = "paper"
    flags: int = 0
    recontact_index: int = -1

    def __len__(self):
        return self.data.shape[0]

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.channels.index(name)]

    def as_dict(self) -> dict:
        """Channels as a dict of 1-D arrays (the form identify_window/estimate_inertia take)."""
        return {name: np.ascontiguousarray(self.data[:, i]) for i, name in enumerate(self.channels)}

    @property
    def flag_names(self) -> list:
        return flag_names(self.flags)

    def header(self) -> np.ndarray:
        return np.array([WINDOW_FORMAT, self.entry_index, self.entry_time_s, self.backlash_width_m,
                         self.wheel_radius_m, self.sample_period_s, self.window_id,
                         self.backlash_width_estimate_m, self.backlash_width_se_m, DETECTOR_CODES[self.detector],
                         self.flags, self.recontact_index], dtype=np.float64)

    def pack(self):
        """(flat data, dims, data_offset) of the drive/window layout."""
        return pack(self.data, self.channels, self.header())

    @classmethod
    def unpack(cls, data, dims, data_offset) -> "Window":
        """Format 2 and format 1 windows (format 1: no estimate, detector "paper", no flags)."""
        arr, channels, head = unpack(data, dims, data_offset)
        if head.size == 0:
            raise LayoutError(f"data_offset: a window carries a header {WINDOW_HEADER}, got none")
        fmt = float(head[0])
        if fmt not in WINDOW_FORMATS and head.size not in WINDOW_FORMATS.values():
            raise LayoutError(f"data_offset: a window carries {len(WINDOW_HEADER)} header values {WINDOW_HEADER} "
                              f"(format 2) or {len(WINDOW_HEADER_1)} (format 1), got {head.size}")
        if fmt not in WINDOW_FORMATS:
            raise LayoutError(f"window header format {head[0]!r}: this version reads {sorted(WINDOW_FORMATS)}")
        names = WINDOW_HEADER[:WINDOW_FORMATS[fmt]]
        if head.size != len(names):
            raise LayoutError(f"data_offset: a format-{fmt:g} window carries {len(names)} header values "
                              f"{names}, got {head.size}")
        # NaN is allowed where it means "none": the flank detector's width fields
        may_be_nan = {"backlash_width_m", "backlash_width_estimate_m", "backlash_width_se_m"}
        for name, v in zip(names, head):
            if not np.isfinite(v) and not (name in may_be_nan and np.isnan(v)):
                raise LayoutError(f"window header: {name} = {v!r} is not finite")
        entry = int(head[1])
        if entry != head[1] or not 0 <= entry < arr.shape[0]:
            raise LayoutError(f"window header entry_index {head[1]!r}: not a row of the {arr.shape[0]}-sample window")
        extra = {}
        if fmt == 2.0:
            codes = {v: k for k, v in DETECTOR_CODES.items()}
            if head[9] not in codes:
                raise LayoutError(f"window header detector {head[9]!r}: expected one of {sorted(codes)}")
            flags = int(head[10])
            if flags != head[10] or flags < 0:
                raise LayoutError(f"window header flags {head[10]!r}: expected a non-negative integer")
            rc = int(head[11])
            if rc != head[11] or not -1 <= rc < arr.shape[0]:
                raise LayoutError(f"window header recontact_index {head[11]!r}: not -1 or a row of the window")
            extra = dict(backlash_width_estimate_m=float(head[7]), backlash_width_se_m=float(head[8]),
                         detector=codes[head[9]], flags=flags, recontact_index=rc)
        return cls(arr.copy(), channels, entry, float(head[2]), float(head[3]), float(head[4]), float(head[5]),
                   int(head[6]), **extra)
