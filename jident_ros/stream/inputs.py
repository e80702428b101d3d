"""Standard inputs of a drive (pure Python/numpy, never imports rclpy): sensor_msgs/JointState as ros2_control's
joint_state_broadcaster publishes it (one message per controller update = one sample), sensor_msgs/Imu for a1,
and CSV exports of a drive's trace buffer.  Both become the (n, c) sample batches the detectors take.

JointState (:class:`JointStateAdapter`)
---------------------------------------
* the motor joint (``motor_joint``, default ``motor``) gives alpha1 (position, rad), omega1 (velocity, rad/s)
  and m_el (effort, N m); the load joint (``load_joint``, default ``load``) gives alpha2 and omega2;
* ``t`` is the header stamp (s);
* NaN means "this joint has no such interface": a channel NaN in the **first** message is absent throughout
  (not provided); a NaN later in a present channel is carried into the batch, where the detector drops it
  with reason ``nonfinite`` (counted, reported);
* optional a1 from sensor_msgs/Imu ``linear_acceleration.<imu_axis>`` (default x), matched to a sample by
  stamp (nearest within T_s/2); a sample waits for its IMU message (at most ``imu_wait_samples`` samples),
  else its a1 is NaN (a ``nonfinite`` drop);
* a message without one of the two joints is counted (``missing_joint``) and skipped, which the detector then
  sees as a ``gap`` in t;
* the period between stamps is checked against ``sample_period_s``: :meth:`JointStateAdapter.jitter` reports
  its median, standard deviation and largest deviation, and whether the median matches (within 1 %);
* samples are batched inside (``batch_size``); :meth:`JointStateAdapter.flush` hands out the rest.

CSV (:func:`read_csv`)
----------------------
A header row of the documented channel names in SI units (``t,alpha1,alpha2,m_el,...``, docs/interfaces.md);
``maps`` ({channel: (column, scale)}, e.g. from ``--map alpha1=enc_motor:0.0000958738,t=time_ms:0.001``,
:func:`parse_map`) takes other column names and scale factors.  Other columns are ignored (and listed).
"""
from __future__ import annotations

import csv
import math
from collections import deque
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from jident_ros.stream.layout import KNOWN_CHANNELS

#: Where each channel comes from in a JointState message: (joint role, field).
JOINT_CHANNELS = (("alpha1", "motor", "position"), ("omega1", "motor", "velocity"), ("m_el", "motor", "effort"),
                  ("alpha2", "load", "position"), ("omega2", "load", "velocity"))
IMU_AXES = ("x", "y", "z")


class InputError(ValueError):
    """Input that cannot be read at all (one line naming the field and value)."""


class JointStateAdapter:
    """sensor_msgs/JointState (+ sensor_msgs/Imu) -> sample batches (module docstring).

    Parameters
    ----------
    sample_period_s : configured T_s (> 0)
    motor_joint, load_joint : joint names
    batch_size : samples per batch handed out (>= 1)
    use_imu : expect sensor_msgs/Imu for a1
    imu_axis : "x" | "y" | "z"
    imu_wait_samples : how many samples a sample waits for its IMU message
    """

    def __init__(self, sample_period_s: float, motor_joint: str = "motor", load_joint: str = "load",
                 batch_size: int = 50, use_imu: bool = False, imu_axis: str = "x", imu_wait_samples: int = 20):
        if not (isinstance(sample_period_s, (int, float)) and math.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s: must be a finite number > 0, got {sample_period_s!r}")
        if not motor_joint or not load_joint or motor_joint == load_joint:
            raise ValueError(f"motor_joint/load_joint: two different non-empty names, got {motor_joint!r}, {load_joint!r}")
        if isinstance(batch_size, bool) or int(batch_size) != batch_size or batch_size < 1:
            raise ValueError(f"batch_size: must be an integer >= 1, got {batch_size!r}")
        if imu_axis not in IMU_AXES:
            raise ValueError(f"imu_axis: expected one of {', '.join(IMU_AXES)}, got {imu_axis!r}")
        self.sample_period_s = float(sample_period_s)
        self.joints = {"motor": str(motor_joint), "load": str(load_joint)}
        self.batch_size = int(batch_size)
        self.use_imu = bool(use_imu)
        self.imu_axis = imu_axis
        self.imu_wait_samples = int(imu_wait_samples)
        self.channels: Optional[tuple] = None      # decided by the first usable message
        self._sources: list = []
        self._rows: list = []                      # ready rows
        self._pending: deque = deque()             # rows waiting for their IMU sample
        self._imu: deque = deque()                 # (stamp, a) not yet matched
        self._imu_last = -math.inf
        self._last_stamp: Optional[float] = None
        self._periods: list = []
        self.counts = {"messages": 0, "missing_joint": 0, "imu_messages": 0, "imu_unmatched": 0}

    # ------------------------------------------------------------- input
    def push(self, stamp_s: float, names: Sequence[str], position: Sequence[float] = (),
             velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> list:
        """One JointState message; returns the batches [(array (n, c), channels)] now complete."""
        self.counts["messages"] += 1
        names = list(names)
        idx = {}
        for role, joint in self.joints.items():
            if joint not in names:
                self.counts["missing_joint"] += 1
                self.last_problem = f"joint {joint!r} ({role}) not in the message's names {names}"
                return self._ready()
            idx[role] = names.index(joint)
        fields = {"position": position, "velocity": velocity, "effort": effort}

        def value(role, fld):
            arr = fields[fld]
            i = idx[role]
            return float(arr[i]) if i < len(arr) else math.nan   # an empty array: the interface is absent

        if self.channels is None:
            present = [(c, role, fld) for c, role, fld in JOINT_CHANNELS if math.isfinite(value(role, fld))]
            self._sources = present
            self.channels = ("t",) + tuple(c for c, _, _ in present) + (("a1",) if self.use_imu else ())
        row = [float(stamp_s)] + [value(role, fld) for _, role, fld in self._sources]
        if self._last_stamp is not None:
            self._periods.append(float(stamp_s) - self._last_stamp)
        self._last_stamp = float(stamp_s)
        if self.use_imu:
            row.append(math.nan)
            self._pending.append(row)
            self._match()
        else:
            self._rows.append(row)
        return self._ready()

    def push_imu(self, stamp_s: float, linear_acceleration) -> list:
        """One Imu message (linear_acceleration as an object with x, y, z or a 3-sequence)."""
        self.counts["imu_messages"] += 1
        la = linear_acceleration
        a = float(getattr(la, self.imu_axis)) if hasattr(la, self.imu_axis) else float(la[IMU_AXES.index(self.imu_axis)])
        self._imu.append((float(stamp_s), a))
        self._imu_last = max(self._imu_last, float(stamp_s))
        self._match()
        return self._ready()

    def _match(self):
        tol = 0.5 * self.sample_period_s
        while self._pending:
            row = self._pending[0]
            t = row[0]
            while self._imu and self._imu[0][0] < t - tol:       # IMU samples too old for any pending row
                self._imu.popleft()
            if self._imu and abs(self._imu[0][0] - t) <= tol:
                row[-1] = self._imu.popleft()[1]
            elif self._imu_last > t + tol or len(self._pending) > self.imu_wait_samples:
                self.counts["imu_unmatched"] += 1                 # stays NaN: a nonfinite drop downstream
            else:
                return
            self._rows.append(self._pending.popleft())

    def _ready(self) -> list:
        out = []
        while len(self._rows) >= self.batch_size:
            out.append((np.array(self._rows[:self.batch_size]), self.channels))
            del self._rows[:self.batch_size]
        return out

    def flush(self) -> list:
        """The samples left (pending IMU matches given up): at most one short batch."""
        while self._pending:
            self.counts["imu_unmatched"] += 1
            self._rows.append(self._pending.popleft())
        out = self._ready()
        if self._rows:
            out.append((np.array(self._rows), self.channels))
            self._rows = []
        return out

    # ------------------------------------------------------------- checks
    def jitter(self) -> dict:
        """Stamp period statistics against the configured T_s."""
        p = np.asarray(self._periods[-100000:])
        if p.size == 0:
            return {"periods": 0}
        med = float(np.median(p))
        return {"periods": int(p.size), "median_period_s": med, "std_s": float(p.std()),
                "max_abs_deviation_s": float(np.max(np.abs(p - self.sample_period_s))),
                "period_matches": bool(abs(med - self.sample_period_s) <= 0.01 * self.sample_period_s)}


# --------------------------------------------------------------------------- CSV

def parse_map(text: str) -> dict:
    """``alpha1=enc_motor:0.0000958738,t=time_ms:0.001`` -> {channel: (column, scale)} (scale 1 when left out)."""
    out = {}
    for item in [s.strip() for s in str(text).split(",") if s.strip()]:
        if "=" not in item:
            raise InputError(f"--map {item!r}: expected channel=column[:scale]")
        ch, rhs = (s.strip() for s in item.split("=", 1))
        if ch not in KNOWN_CHANNELS:
            raise InputError(f"--map {item!r}: unknown channel {ch!r} (known: {', '.join(KNOWN_CHANNELS)})")
        col, _, scale = rhs.partition(":")
        try:
            k = float(scale) if scale else 1.0
        except ValueError:
            raise InputError(f"--map {item!r}: scale {scale!r} is not a number") from None
        if not col or not math.isfinite(k) or k == 0:
            raise InputError(f"--map {item!r}: need a column name and a finite non-zero scale")
        out[ch] = (col, k)
    return out


def read_csv(path, maps: Optional[dict] = None) -> tuple:
    """(array (n, c), channels, ignored columns) of a CSV file (module docstring)."""
    path = Path(path)
    maps = dict(maps or {})
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise InputError(f"CSV {path}: {exc.strerror or exc}") from None
    if not rows:
        raise InputError(f"CSV {path}: empty file")
    header = [h.strip() for h in rows[0]]
    source = {}                       # channel -> (column index, scale)
    for ch, (col, k) in maps.items():
        if col not in header:
            raise InputError(f"--map {ch}={col}: column {col!r} not in the CSV header {header}")
        source[ch] = (header.index(col), k)
    mapped_cols = {col for col, _ in maps.values()}
    for i, h in enumerate(header):
        if h in KNOWN_CHANNELS and h not in source and h not in mapped_cols:
            source[h] = (i, 1.0)
    if "t" not in source:
        raise InputError(f"CSV {path}: no time column 't' (header {header}; use --map t=<column>:<scale to s>)")
    ignored = [h for h in header if h not in KNOWN_CHANNELS and h not in mapped_cols]
    channels = ("t",) + tuple(c for c in KNOWN_CHANNELS if c in source and c != "t")
    data = np.empty((len(rows) - 1, len(channels)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise InputError(f"CSV {path} line {r}: {len(row)} fields, the header has {len(header)}")
        for j, ch in enumerate(channels):
            i, k = source[ch]
            text = row[i].strip()
            try:
                data[r - 2, j] = k * float(text) if text else math.nan
            except ValueError:
                raise InputError(f"CSV {path} line {r}: column {header[i]!r} value {text!r} is not a number") from None
    absent = [j for j, ch in enumerate(channels) if ch != "t" and data.size and np.isnan(data[:, j]).all()]
    if absent:                        # a channel absent throughout is simply not provided
        keep = [j for j in range(len(channels)) if j not in absent]
        data, channels = data[:, keep], tuple(channels[j] for j in keep)
    return data, channels, ignored


__all__ = ["InputError", "JOINT_CHANNELS", "JointStateAdapter", "parse_map", "read_csv"]
