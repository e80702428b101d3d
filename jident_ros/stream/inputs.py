"""Standard inputs of a drive (pure Python/numpy, never imports rclpy): sensor_msgs/JointState as ros2_control's
joint_state_broadcaster publishes it (one message per controller update = one sample), sensor_msgs/Imu for a1,
and CSV exports of a drive's trace buffer.  Both become the (n, c) sample batches the detectors take.

JointState (:class:`JointStateAdapter`)
---------------------------------------
* the motor joint (``motor_joint``, default ``motor``) gives alpha1 (position, rad), omega1 (velocity, rad/s)
  and m_el (effort, N m); the load joint (``load_joint``, default ``load``) gives alpha2 and omega2;
* ``t`` is the header stamp (s);
* the channel set comes from the configuration (``channels``: which of the five, default all; ``use_imu`` adds
  a1), never from the first message: a bad first message cannot disable the input;
* a message whose configured value is NaN/Inf, or whose field array is empty or shorter than its names, is
  dropped and counted (``nonfinite``, ``empty_field``), naming the joint and the field; the next good message is
  used (the detector sees one missing sample as a ``gap``);
* a message without one of the two joints is counted (``missing_joint``) and skipped, naming the joint and the
  names the message has (a renamed joint); :meth:`JointStateAdapter.problems` lists every kind of problem with
  its count, most frequent first;
* optional a1 from sensor_msgs/Imu ``linear_acceleration.<imu_axis>`` (default x), matched to a sample by
  stamp (the nearest within T_s/2); a sample waits for its IMU message while the Imu stream has not passed its stamp (two topics
  delivered in chunks: a node that starts behind a running drive, or stalls, gets one topic's backlog before the
  other's), at most ``imu_wait_samples`` samples (default :data:`IMU_WAIT_S` of drive time); a sample the Imu stream
  passed without a match, or beyond that bound, is dropped (``imu_unmatched``); Imu messages wait for their samples
  as long, and those no sample took are counted (``imu_unused``: an Imu faster than the joint states, or one running
  ahead of a stalled JointState stream); an Imu message with a NaN/Inf value is dropped (``imu_nonfinite``);
* the stamps of the two clocks can agree while the data do not (an IMU whose stamp is taken late):
  :mod:`jident_ros.stream.imu_skew` estimates a window's skew of a1 against the motor encoder; beyond half a
  sample the window is not diagnosed and the input goes on without a1 (:meth:`JointStateAdapter.drop_a1`), so
  that no J1 comes from a skewed a1;
* the period between stamps is checked against ``sample_period_s``: :meth:`JointStateAdapter.jitter` reports
  its median, standard deviation and largest deviation, and whether the median matches (within 1 %);
* samples are batched inside (``batch_size``); :meth:`JointStateAdapter.flush` hands out the rest.

CSV (:class:`CsvStream`, :func:`read_csv`)
------------------------------------------
Read block by block (bounded memory, any file size, any field length); UTF-8 with or without a byte-order
mark, UTF-16 with one, else Latin-1; every error names the file and the line (one line, never a traceback).
A header row of the documented channel names in SI units (``t,alpha1,alpha2,m_el,...``, docs/interfaces.md);
``maps`` ({channel: (column, scale)}, e.g. from ``--map alpha1=enc_motor:0.0000958738,t=time_ms:0.001``,
:func:`parse_map`) takes other column names and scale factors.  Other columns are ignored (and listed).
"""
from __future__ import annotations

import csv
import math
import sys
from collections import deque
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from jident_ros.stream.detector import stream_batches
from jident_ros.stream.layout import KNOWN_CHANNELS
from jident_ros.stream.stamps import StampGrid

#: Where each channel comes from in a JointState message: (joint role, field).
JOINT_CHANNELS = (("alpha1", "motor", "position"), ("omega1", "motor", "velocity"), ("m_el", "motor", "effort"),
                  ("alpha2", "load", "position"), ("omega2", "load", "velocity"))
IMU_AXES = ("x", "y", "z")


class InputError(ValueError):
    """Input that cannot be read at all (one line naming the field and value)."""


#: The channels a JointState message can carry.
JOINTSTATE_CHANNELS = tuple(c for c, _, _ in JOINT_CHANNELS)
#: How many messages decide the channel set with ``channels="auto"``.
PROBE_MESSAGES = 200
#: How many problem kinds :meth:`JointStateAdapter.problems` keeps (the first ones; the rest are counted).
MAX_PROBLEM_KINDS = 32
#: Drive time (s) a JointState sample waits for its Imu message, and an Imu message for its sample, by default
#: (``imu_wait_samples``: this over T_s).  One topic's backlog can come before the other's (a node started behind a
#: running drive, or stalled: rclpy's executor takes a subscription's waiting messages in one run); with 20 samples
#: (stop 43's bound) a loaded machine lost every window of test_reliability's live skewed-Imu test, 2,100-7,900
#: JointStates each time.  2 s covers the nodes' default queue depth (1000) at 2 kHz twice; the memory is a few
#: floats per sample.
IMU_WAIT_S = 2.0


class JointStateAdapter:
    """sensor_msgs/JointState (+ sensor_msgs/Imu) -> sample batches (module docstring).

    Parameters
    ----------
    sample_period_s : configured T_s (> 0)
    motor_joint, load_joint : joint names
    batch_size : samples per batch handed out (>= 1)
    use_imu : expect sensor_msgs/Imu for a1
    imu_axis : "x" | "y" | "z"
    imu_wait_samples : how many samples a sample waits for its IMU message (and an Imu message for its sample);
        None: :data:`IMU_WAIT_S` over ``sample_period_s``
    channels : the JointState channels to take (of alpha1, omega1, m_el, alpha2, omega2; default all five);
        ``t`` first and ``a1`` last (with ``use_imu``) are added.  ``"auto"`` (offline, a recording of an
        unknown drive): the channels finite in most of the first :data:`PROBE_MESSAGES` messages
    """

    def __init__(self, sample_period_s: float, motor_joint: str = "motor", load_joint: str = "load",
                 batch_size: int = 50, use_imu: bool = False, imu_axis: str = "x", imu_wait_samples: Optional[int] = None,
                 channels: Optional[Sequence[str]] = None):
        if not (isinstance(sample_period_s, (int, float)) and math.isfinite(sample_period_s) and sample_period_s > 0):
            raise ValueError(f"sample_period_s: must be a finite number > 0, got {sample_period_s!r}")
        if not motor_joint or not load_joint or motor_joint == load_joint:
            raise ValueError(f"motor_joint/load_joint: two different non-empty names, got {motor_joint!r}, {load_joint!r}")
        if isinstance(batch_size, bool) or int(batch_size) != batch_size or batch_size < 1:
            raise ValueError(f"batch_size: must be an integer >= 1, got {batch_size!r}")
        if imu_axis not in IMU_AXES:
            raise ValueError(f"imu_axis: expected one of {', '.join(IMU_AXES)}, got {imu_axis!r}")
        self._probe: Optional[list] = None
        if channels == "auto":                     # offline: decided by the majority of the first messages
            self._probe, wanted = [], JOINTSTATE_CHANNELS
        else:
            wanted = JOINTSTATE_CHANNELS if channels is None else tuple(c for c in channels if c not in ("t", "a1"))
        unknown = [c for c in wanted if c not in JOINTSTATE_CHANNELS]
        if unknown or not wanted:
            raise ValueError(f"channels: JointState carries {', '.join(JOINTSTATE_CHANNELS)}, got {list(wanted)!r}")
        self.sample_period_s = float(sample_period_s)
        self.joints = {"motor": str(motor_joint), "load": str(load_joint)}
        self.batch_size = int(batch_size)
        self.use_imu = bool(use_imu)
        self.imu_axis = imu_axis
        if imu_wait_samples is None:
            imu_wait_samples = max(int(math.ceil(IMU_WAIT_S / float(sample_period_s))), 1)
        if isinstance(imu_wait_samples, bool) or int(imu_wait_samples) != imu_wait_samples or imu_wait_samples < 1:
            raise ValueError(f"imu_wait_samples: must be an integer >= 1, got {imu_wait_samples!r}")
        self.imu_wait_samples = int(imu_wait_samples)
        self._sources = [(c, role, fld) for c, role, fld in JOINT_CHANNELS if c in wanted]
        self.channels: tuple = ("t",) + tuple(c for c, _, _ in self._sources) + (("a1",) if self.use_imu else ())
        self._rows: list = []                      # ready rows
        self._pending: deque = deque()             # rows waiting for their IMU sample
        self._imu: deque = deque()                 # (stamp, a) not yet matched
        self._imu_last = -math.inf
        self._last_stamp: Optional[float] = None
        self._periods: list = []
        self.counts = {"messages": 0, "samples": 0, "missing_joint": 0, "empty_field": 0, "nonfinite": 0,
                       "imu_messages": 0, "imu_nonfinite": 0, "imu_unmatched": 0, "imu_ignored": 0, "imu_unused": 0}
        self.a1_dropped = False
        self.grid: Optional[StampGrid] = None      # the time base (stream/stamps.py), made with the first batch
        self._problems: dict = {}                  # one line -> count
        self.last_problem = ""

    def _problem(self, reason: str, text: str) -> None:
        self.counts[reason] += 1
        self.last_problem = text
        if text in self._problems or len(self._problems) < MAX_PROBLEM_KINDS:
            self._problems[text] = self._problems.get(text, 0) + 1

    def problems(self) -> list:
        """[(one line, count)] of the input's problems so far, most frequent first."""
        return sorted(self._problems.items(), key=lambda kv: -kv[1])

    # ------------------------------------------------------------- input
    def _decide(self) -> list:
        """``channels="auto"``: the channels finite in more than half of the probed messages that hold both
        joints; then the probed messages go through as any other."""
        probe, self._probe = self._probe, None
        seen = dict.fromkeys(JOINTSTATE_CHANNELS, 0)
        usable = 0
        for _, names, pos, vel, eff in probe:
            names = list(names)
            if not all(j in names for j in self.joints.values()):
                continue
            usable += 1
            fields = {"position": pos, "velocity": vel, "effort": eff}
            for c, role, fld in JOINT_CHANNELS:
                i = names.index(self.joints[role])
                arr = fields[fld]
                if i < len(arr) and math.isfinite(float(arr[i])):
                    seen[c] += 1
        if usable:
            keep = [c for c in JOINTSTATE_CHANNELS if seen[c] > usable / 2] or list(JOINTSTATE_CHANNELS)
            self._sources = [(c, role, fld) for c, role, fld in JOINT_CHANNELS if c in keep]
            self.channels = ("t",) + tuple(keep) + (("a1",) if self.use_imu else ())
        out = []
        for msg in probe:
            self.counts["messages"] -= 1
            out += self.push(*msg)
        return out

    def push(self, stamp_s: float, names: Sequence[str], position: Sequence[float] = (),
             velocity: Sequence[float] = (), effort: Sequence[float] = ()) -> list:
        """One JointState message; returns the batches [(array (n, c), channels)] now complete."""
        if self._probe is not None:
            self._probe.append((stamp_s, list(names), list(position), list(velocity), list(effort)))
            if len(self._probe) < PROBE_MESSAGES:
                return []
            return self._decide()
        self.counts["messages"] += 1
        names = list(names)
        idx = {}
        for role, joint in self.joints.items():
            if joint not in names:
                shown = names if len(names) <= 8 else names[:8] + ["..."]
                self._problem("missing_joint", f"joint {joint!r} ({role}_joint) not in the JointState names {shown}")
                return self._ready()
            idx[role] = names.index(joint)
        fields = {"position": position, "velocity": velocity, "effort": effort}
        row = [float(stamp_s)]
        for _, role, fld in self._sources:
            arr, i = fields[fld], idx[role]
            if i >= len(arr):
                what = "an empty array" if len(arr) == 0 else f"{len(arr)} value(s) for {len(names)} names"
                self._problem("empty_field", f"joint {self.joints[role]!r} {fld}: {what}")
                return self._ready()
            v = float(arr[i])
            if not math.isfinite(v):
                self._problem("nonfinite", f"joint {self.joints[role]!r} {fld}: {v}")
                return self._ready()
            row.append(v)
        if not math.isfinite(row[0]):
            self._problem("nonfinite", f"header stamp: {row[0]}")
            return self._ready()
        self.counts["samples"] += 1
        if self._last_stamp is not None:
            self._periods.append(row[0] - self._last_stamp)
            if len(self._periods) > 200_000:
                del self._periods[:100_000]
        self._last_stamp = row[0]
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
        if self.a1_dropped:
            self.counts["imu_ignored"] += 1
            return self._ready()
        la = linear_acceleration
        try:
            a = float(getattr(la, self.imu_axis)) if hasattr(la, self.imu_axis) \
                else float(la[IMU_AXES.index(self.imu_axis)])
        except (TypeError, ValueError, IndexError):
            a = math.nan
        if not (math.isfinite(a) and math.isfinite(float(stamp_s))):
            self._problem("imu_nonfinite", f"Imu linear_acceleration.{self.imu_axis}: {a} (stamp {float(stamp_s)})")
            return self._ready()
        self._imu.append((float(stamp_s), a))
        self._imu_last = max(self._imu_last, float(stamp_s))
        self._match()
        while len(self._imu) > self.imu_wait_samples:            # no sample came for them (the JointStates stopped)
            self._imu.popleft()
            self.counts["imu_unused"] += 1
        return self._ready()

    @property
    def waiting_for_imu(self) -> int:
        """Samples waiting for their Imu message now."""
        return len(self._pending)

    def _match(self):
        tol = 0.5 * self.sample_period_s
        while self._pending:
            row = self._pending[0]
            t = row[0]
            while self._imu and self._imu[0][0] < t - tol:       # IMU samples too old for any pending row
                self._imu.popleft()
                self.counts["imu_unused"] += 1
            near = self._nearest_imu(t, tol)
            if near is not None:
                for _ in range(near):                             # nearer ones follow: those before are unused
                    self._imu.popleft()
                    self.counts["imu_unused"] += 1
                row[-1] = self._imu.popleft()[1]
                self._rows.append(self._pending.popleft())
            elif self._imu_last > t + tol:
                self._pending.popleft()                           # the Imu stream passed it: no a1, dropped, counted
                self._problem("imu_unmatched", f"no Imu message within {tol:g} s of the JointState stamp")
            elif len(self._pending) > self.imu_wait_samples:
                self._pending.popleft()                           # waited its bound: dropped, counted
                self._problem("imu_unmatched", f"no Imu message for {self.imu_wait_samples} samples "
                                               f"({self.imu_wait_samples * self.sample_period_s:g} s of drive time) "
                                               f"after the JointState stamp")
            else:
                return

    def _nearest_imu(self, t: float, tol: float) -> Optional[int]:
        """Index of the waiting Imu message nearest to stamp ``t`` within ``tol`` (the first of equally near ones),
        None when none is (an Imu faster than the joint states has several within T_s/2: the first one is not the
        nearest)."""
        best, best_dt = None, math.inf
        for i, (stamp, _) in enumerate(self._imu):
            if stamp > t + tol:
                break
            dt = abs(stamp - t)
            if dt <= tol and dt < best_dt:
                best, best_dt = i, dt
        return best

    def _ready(self) -> list:
        out = []
        while len(self._rows) >= self.batch_size:
            out += self._on_grid(np.array(self._rows[:self.batch_size]))
            del self._rows[:self.batch_size]
        return out

    def _on_grid(self, batch: np.ndarray) -> list:
        """A batch through the time base (stream/stamps.py): [(rows, channels)], none while a block is held."""
        if self.grid is None:
            self.grid = StampGrid(self.sample_period_s, self.channels.index("alpha1") if "alpha1" in self.channels
                                   else None)
        rows = self.grid.feed(batch)
        return [(b, self.channels) for b in stream_batches(rows, self.batch_size)]

    def flush(self) -> list:
        """The samples left (pending IMU matches given up): at most one short batch."""
        early = self._decide() if self._probe is not None else []
        while self._pending:
            self._pending.popleft()
            self._problem("imu_unmatched", "no Imu message for the last sample(s) of the input")
        out = early + self._ready()
        if self._rows:
            out += self._on_grid(np.array(self._rows))
            self._rows = []
        return out

    def drop_a1(self) -> None:
        """Go on without a1 (an Imu out of step with the encoder, :func:`check_imu_skew`): the channel set loses
        a1, rows waiting for their Imu sample go out without it, later Imu messages are counted and ignored."""
        if not self.use_imu:
            return
        self.use_imu = False
        self.a1_dropped = True
        self.channels = tuple(c for c in self.channels if c != "a1")
        if self.grid is not None:
            self.grid.drop_last_column()
        self._rows = [r[:-1] for r in self._rows] + [r[:-1] for r in self._pending]
        self._pending.clear()
        self._imu.clear()

    # ------------------------------------------------------------- checks
    def jitter(self) -> dict:
        """Stamp period statistics against the configured T_s."""
        p = np.asarray(self._periods[-100000:])
        if p.size == 0:
            return {"periods": 0}
        grid = {} if self.grid is None else self.grid.summary()
        k = grid.get("decimated_by", 1)            # a faster recording, decimated to T_s: its stamps step by T_s/k
        med = float(np.median(p))
        return {"periods": int(p.size), "median_period_s": med, "std_s": float(p.std()),
                "max_abs_deviation_s": float(np.max(np.abs(p - self.sample_period_s))),
                "period_matches": bool(abs(k * med - self.sample_period_s) <= 0.01 * self.sample_period_s), **grid}


# --------------------------------------------------------------------------- CSV

def parse_map(text: str) -> dict:
    """``alpha1=enc_motor:0.0000958738,t=time_ms:0.001`` -> {channel: (column, scale)} (scale 1 when left out).
    A channel mapped twice is refused (one line naming both mappings)."""
    out, given = {}, {}
    for item in [s.strip() for s in str(text).split(",") if s.strip()]:
        if "=" not in item:
            raise InputError(f"--map {item!r}: expected channel=column[:scale]")
        ch, rhs = (s.strip() for s in item.split("=", 1))
        if ch not in KNOWN_CHANNELS:
            raise InputError(f"--map {item!r}: unknown channel {ch!r} (known: {', '.join(KNOWN_CHANNELS)})")
        if ch in out:
            raise InputError(f"--map: channel {ch!r} mapped twice ({given[ch]!r} and {item!r}); give one mapping")
        col, _, scale = rhs.partition(":")
        try:
            k = float(scale) if scale else 1.0
        except ValueError:
            raise InputError(f"--map {item!r}: scale {scale!r} is not a number") from None
        if not col or not math.isfinite(k) or k == 0:
            raise InputError(f"--map {item!r}: need a column name and a finite non-zero scale")
        out[ch], given[ch] = (col, k), item
    return out


#: Rows per array the CSV stream hands out (a multiple of the detectors' 50-sample batches).
CSV_BLOCK_ROWS = 5000
#: Rows that decide which channels a CSV provides (a channel empty in all of them is not provided).
CSV_PROBE_ROWS = 1000
_SHOWN_CHARS = 40


def _shown(text: str) -> str:
    """A field's text for a one-line error: at most ``_SHOWN_CHARS`` characters, with its length when cut."""
    return repr(text) if len(text) <= _SHOWN_CHARS else f"{text[:_SHOWN_CHARS]!r}... ({len(text)} characters)"


def _undecoded(text: str) -> bool:
    """True when ``text`` holds bytes the file's encoding could not decode (surrogateescape)."""
    return any("\udc80" <= ch <= "\udcff" for ch in text)


def _encoding(path: Path) -> str:
    """The text encoding of a CSV file from its first 64 kB: UTF-16 / UTF-8 with their byte-order marks,
    UTF-8, else Latin-1 (any byte is a character: a header in a legacy code page still reads; the numbers
    are ASCII in all of them)."""
    with open(path, "rb") as f:
        head = f.read(65536)
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "utf-16"
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:       # not just a character cut at the 64 kB boundary
            return "latin-1"
    return "utf-8-sig"                      # the BOM, when there is one, is not part of the first name


class CsvStream:
    """A CSV file of a drive's trace read block by block (bounded memory, any size): :attr:`channels`,
    :attr:`ignored` (columns that are not channels) and :meth:`blocks` (arrays of at most
    :data:`CSV_BLOCK_ROWS` rows).  The header and the first :data:`CSV_PROBE_ROWS` rows are read when it is
    made: a channel whose column is empty in all of them is not provided.  Every error is an
    :class:`InputError` naming the file and the line."""

    def __init__(self, path, maps: Optional[dict] = None, block_rows: int = CSV_BLOCK_ROWS):
        self.path = Path(path)
        self.grid: Optional[StampGrid] = None      # the time base (stream/stamps.py), made by batches()
        self.block_rows = int(block_rows)
        self.rows_read = 0
        if csv.field_size_limit() < _FIELD_LIMIT:
            csv.field_size_limit(_FIELD_LIMIT)  # any field length: a long field is an error of its own, later
        try:
            if not self.path.is_file():
                raise InputError(f"CSV {self.path}: " + ("not a regular file" if self.path.exists()
                                                         else "no such file"))
            self.encoding = _encoding(self.path)
            # undecodable bytes are kept as lone surrogates: an error names its exact line when a used column
            # holds them, an ignored column may hold anything
            self._file = open(self.path, newline="", encoding=self.encoding, errors="surrogateescape")
        except OSError as exc:
            raise InputError(f"CSV {self.path}: {exc.strerror or exc}") from None
        self._reader = csv.reader(self._file)
        try:
            header = self._next_row()
            if header is None:
                raise InputError(f"CSV {self.path}: empty file")
            header = [h.strip() for h in header]
            maps = dict(maps or {})
            source = {}                       # channel -> (column index, scale)
            for ch, (col, k) in maps.items():
                if col not in header:
                    raise InputError(f"--map {ch}={col}: column {col!r} not in the header of CSV {self.path} "
                                     f"{header[:20]}")
                source[ch] = (header.index(col), k)
            mapped_cols = {col for col, _ in maps.values()}
            for i, h in enumerate(header):
                if h in KNOWN_CHANNELS and h not in source and h not in mapped_cols:
                    source[h] = (i, 1.0)
            if "t" not in source:
                raise InputError(f"CSV {self.path}: no time column 't' (header {header[:20]}; use "
                                 "--map t=<column>:<scale to s>)")
            self.header = header
            self.ignored = [h for h in header if h not in KNOWN_CHANNELS and h not in mapped_cols]
            channels = ("t",) + tuple(c for c in KNOWN_CHANNELS if c in source and c != "t")
            self._source = [source[c] for c in channels]
            self.channels = channels
            probe = self._read(CSV_PROBE_ROWS)
            if probe.shape[0] == 0:
                raise InputError(f"CSV {self.path}: a header and no data rows")
            absent = [j for j, ch in enumerate(channels) if ch != "t" and np.isnan(probe[:, j]).all()]
            keep = [j for j in range(len(channels)) if j not in absent]
            self.channels = tuple(channels[j] for j in keep)
            self._source = [self._source[j] for j in keep]
            self._probe = probe[:, keep]
        except BaseException:
            self._file.close()
            raise

    def _next_row(self):
        try:
            return next(self._reader)
        except StopIteration:
            return None
        except csv.Error as exc:
            raise InputError(f"CSV {self.path} line {self._reader.line_num + 1}: {exc}") from None
        except UnicodeError as exc:
            raise InputError(f"CSV {self.path} after line {self._reader.line_num}: not {self.encoding} text "
                             f"({exc})") from None

    def _read(self, n: int) -> np.ndarray:
        """Up to ``n`` rows as an array (fewer at the end of the file)."""
        out = np.empty((n, len(self._source)))
        width = len(self.header)
        r = 0
        while r < n:
            row = self._next_row()
            if row is None:
                break
            line = self._reader.line_num
            if len(row) != width:
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue                  # a blank line
                raise InputError(f"CSV {self.path} line {line}: {len(row)} fields, the header has {width}")
            for j, (i, k) in enumerate(self._source):
                text = row[i].strip()
                try:
                    out[r, j] = k * float(text) if text else math.nan
                except ValueError:
                    what = (f"holds bytes that are not {self.encoding} text" if _undecoded(text)
                            else "is not a number")
                    raise InputError(f"CSV {self.path} line {line}: column {self.header[i]!r} value "
                                     f"{_shown(text)} {what}") from None
            r += 1
        self.rows_read += r
        return out[:r]

    def jitter(self) -> dict:
        """The time base's summary (:meth:`~jident_ros.stream.stamps.StampGrid.summary`; {} before :meth:`batches`)."""
        return {} if self.grid is None else self.grid.summary()

    def batches(self, sample_period_s: float, batch_rows: int = 50):
        """The rows in batches of ``batch_rows`` through the stream's time base (:attr:`grid`, a
        :class:`~jident_ros.stream.stamps.StampGrid`: stamps that are the sampling instants put on the T_s grid)."""
        self.grid = StampGrid(sample_period_s, self.channels.index("alpha1") if "alpha1" in self.channels else None)
        for block in self.blocks():
            rows = self.grid.feed(block)
            yield from stream_batches(rows, batch_rows)

    def blocks(self):
        """The rows as arrays (n <= block_rows, channels); closes the file at the end."""
        try:
            probe, self._probe = self._probe, None
            if probe is not None and probe.shape[0]:
                # keep the block boundaries on multiples of block_rows from the first row
                rest = self._read(self.block_rows - probe.shape[0] % self.block_rows) \
                    if probe.shape[0] % self.block_rows else np.empty((0, probe.shape[1]))
                first = np.concatenate([probe, rest])
                for s in range(0, first.shape[0], self.block_rows):
                    yield first[s:s + self.block_rows]
            while True:
                block = self._read(self.block_rows)
                if block.shape[0] == 0:
                    return
                yield block
        finally:
            self._file.close()

    def close(self) -> None:
        self._file.close()


_FIELD_LIMIT = min(sys.maxsize, 2**31 - 1)


def read_csv(path, maps: Optional[dict] = None) -> tuple:
    """(array (n, c), channels, ignored columns) of a whole CSV file (module docstring; :class:`CsvStream`
    reads one of any size block by block)."""
    stream = CsvStream(path, maps)
    blocks = list(stream.blocks())
    data = np.concatenate(blocks) if blocks else np.empty((0, len(stream.channels)))
    return data, stream.channels, stream.ignored


__all__ = ["CsvStream", "InputError", "JOINT_CHANNELS", "JOINTSTATE_CHANNELS", "JointStateAdapter",
           "parse_map", "read_csv"]
