"""The trend tracker's state file (:mod:`jident_ros.identify.trend`): JSON, versioned, written atomically, and
**checked on load** (issue 24): every number of the right type and finite, variances and standard errors
positive, J1 and the width plausible, no time after the last window's, counts and indices in range.  A state
that fails is refused with :class:`TrendStateError` naming the field (``inertia.P = -1: ...``); the diagnostic
node then moves it aside and reports ERROR.  Nothing from a refused state is ever published.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict
from typing import Any, Optional

from jident_ros.identify.trend_channels import ChangeEvent, TrendStateError
from jident_ros.identify.trend_config import TrendConfig

STATE_KIND = "jident_ros.identify.trend"
STATE_VERSION = 1
#: Without a plausible band from the caller, a J1 of the state must lie within this factor of its reference
#: (the commissioned baseline): the paper's classes span -17.5 % .. +5 %.
RELATIVE_PLAUSIBLE = 1.5
#: Without a plausible band from the caller, a width must lie in (0, this x width_limit_m].
WIDTH_LIMIT_FACTOR = 10.0


def state_to_dict(tr) -> dict:
    """JSON-serialisable state of tracker ``tr`` (with the configuration), versioned."""
    return {"kind": STATE_KIND, "version": STATE_VERSION, "config": tr.config.to_dict(),
            "n_windows": tr.n_windows, "last_time_s": tr.last_time_s,
            "changes": [asdict(c) for c in tr.changes],
            "inertia": tr._inertia.to_dict(), "width": tr._width.to_dict(),
            "inputs": {"inertia_fed": tr.inertia_fed, "inertia_refused": dict(tr.inertia_refused),
                       "windows_skipped": dict(tr.windows_skipped), "last_skip": tr.last_skip,
                       "time_segment": tr.time_segment, "last_discontinuity": tr.last_discontinuity},
            "recording_cursor": None if tr.recording_cursor is None else list(tr.recording_cursor)}


def state_from_dict(cls, d: Any, config: Optional[TrendConfig] = None, plausible: Optional[dict] = None):
    """A ``cls`` (TrendTracker) rebuilt from :func:`state_to_dict`'s output and checked
    (:func:`check_state`).  ``config`` replaces the saved configuration.  TrendStateError on anything unusable."""
    if not isinstance(d, dict):
        raise TrendStateError(f"trend state: expected a JSON object, got {type(d).__name__}")
    if d.get("kind") != STATE_KIND:
        raise TrendStateError(f"trend state: kind {d.get('kind')!r}, expected {STATE_KIND!r}")
    if d.get("version") != STATE_VERSION:
        raise TrendStateError(f"trend state: version {d.get('version')!r}, this code reads version {STATE_VERSION}")
    try:
        _check_types(d)
        cfg = config if config is not None else TrendConfig.from_dict(d["config"])
        tr = cls(cfg)
        tr.n_windows = int(d["n_windows"])
        tr.last_time_s = None if d["last_time_s"] is None else float(d["last_time_s"])
        tr.changes = [ChangeEvent(**c) for c in d["changes"]]
        tr._inertia.load(d["inertia"])
        tr._width.load(d["width"])
        inputs = d.get("inputs", {})
        tr.inertia_fed = int(inputs.get("inertia_fed", tr._inertia.n))
        tr.inertia_refused = {str(k): int(v) for k, v in inputs.get("inertia_refused", {}).items()}
        tr.windows_skipped = {str(k): int(v) for k, v in inputs.get("windows_skipped", {}).items()}
        tr.last_skip = None if inputs.get("last_skip") is None else (int(inputs["last_skip"][0]),
                                                                      str(inputs["last_skip"][1]))
        tr.time_segment = int(inputs.get("time_segment", 0))
        ld = inputs.get("last_discontinuity")
        tr.last_discontinuity = None if ld is None else (int(ld[0]), str(ld[1]))
        tr.recording_cursor = _cursor(d.get("recording_cursor"))
    except TrendStateError:
        raise
    except KeyError as e:
        raise TrendStateError(f"trend state: missing field {e.args[0]!r}") from e
    except (TypeError, ValueError, IndexError) as e:
        raise TrendStateError(f"trend state: bad content ({e})") from e
    check_state(tr, plausible)
    return tr


def _cursor(c) -> Optional[tuple]:
    """The saved ``recording_cursor`` (start of the last recording fed, ns or None; its last window's drive time,
    s), checked: None, or [integer >= 0 or null, finite number]."""
    if c is None:
        return None
    if not isinstance(c, list) or len(c) != 2:
        _bad("recording_cursor", c, "must be [start_ns or null, time_s]")
    ns, t = c
    if ns is not None and (not isinstance(ns, int) or isinstance(ns, bool) or ns < 0):
        _bad("recording_cursor[0]", ns, "must be an integer >= 0 (ns) or null")
    if not _is_number(t) or not math.isfinite(t):
        _bad("recording_cursor[1]", t, "must be a finite number")
    return (ns, float(t))


# --------------------------------------------------------------------------- checks

def _bad(field: str, value, rule: str):
    raise TrendStateError(f"trend state: {field} = {value!r}: {rule}")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_types(d: dict):
    """Every number a JSON number (not a string, a bool or null where a value is required)."""
    for key in ("n_windows",):
        if not isinstance(d.get(key), int) or isinstance(d.get(key), bool):
            _bad(key, d.get(key), "must be an integer")
    if d.get("last_time_s") is not None and not _is_number(d["last_time_s"]):
        _bad("last_time_s", d["last_time_s"], "must be a number or null")
    for ch in ("inertia", "width"):
        c = d.get(ch)
        if not isinstance(c, dict):
            _bad(ch, c, "must be an object")
        for key, v in c.items():
            if key == "phase":
                continue
            vals = v if isinstance(v, list) else [v]
            flat = [x for x in vals for x in (x if isinstance(x, list) else [x])]
            if not all(x is None or _is_number(x) for x in flat):
                bad = next(x for x in flat if not (x is None or _is_number(x)))
                _bad(f"{ch}.{key}", bad, "must be a number")


def _finite(field: str, v, minimum: Optional[float] = None, strict: bool = False, optional: bool = True):
    if v is None:
        if not optional:
            _bad(field, v, "missing")
        return
    if not math.isfinite(v):
        _bad(field, v, "must be finite")
    if minimum is not None and (v < minimum or (strict and v == minimum)):
        _bad(field, v, f"must be {'>' if strict else '>='} {minimum:g}")


def _in_band(field: str, v, band):
    if v is not None and band is not None and not band[0] <= v <= band[1]:
        _bad(field, v, f"outside the plausible {band[0]:.4g}..{band[1]:.4g}")


def check_state(tr, plausible: Optional[dict] = None):
    """TrendStateError naming the first field of tracker ``tr`` that cannot be trusted.  ``plausible``:
    {"inertia_kgm2": (lo, hi), "width_m": (lo, hi)} (the caller's plausible bands); without it J1 must lie
    within x/÷ :data:`RELATIVE_PLAUSIBLE` of the state's own reference and the width in (0, 10 x width_limit_m]."""
    plausible = plausible or {}
    last = tr.last_time_s
    _finite("last_time_s", last)
    for name, v in (("n_windows", tr.n_windows), ("inputs.inertia_fed", tr.inertia_fed),
                    ("inputs.time_segment", tr.time_segment)):
        if v < 0:
            _bad(name, v, "must be >= 0")
    for name, counts in (("inputs.inertia_refused", tr.inertia_refused), ("inputs.windows_skipped", tr.windows_skipped)):
        for k, v in counts.items():
            if v < 0:
                _bad(f"{name}.{k}", v, "must be >= 0")
    J, W = tr._inertia, tr._width
    ref = J.reference
    j_band = plausible.get("inertia_kgm2")
    if j_band is None and ref is not None and ref > 0 and math.isfinite(ref):
        j_band = (ref / RELATIVE_PLAUSIBLE, ref * RELATIVE_PLAUSIBLE)
    w_band = plausible.get("width_m") or (0.0, WIDTH_LIMIT_FACTOR * tr.config.width_limit_m)
    _check_channel("inertia", J, tr, j_band)
    _check_channel("width", W, tr, w_band)
    _finite("inertia.x", J.x, 0.0, strict=True)
    _in_band("inertia.x", J.x, j_band)
    _finite("inertia.P", J.P, 0.0)
    _finite("inertia.seg_sw", J.seg_sw, 0.0)
    _finite("inertia.seg_swy", J.seg_swy, 0.0)
    if J.seg_n < 0:
        _bad("inertia.seg_n", J.seg_n, "must be >= 0")
    _finite("inertia.scale_ss", J.scale_ss, 0.0)
    if J.scale_dof < 0:
        _bad("inertia.scale_dof", J.scale_dof, "must be >= 0")
    for i, (w, yw, zr) in enumerate(J.refine_pending):
        _finite(f"inertia.refine_pending[{i}]", w, 0.0, strict=True, optional=False)
        _finite(f"inertia.refine_pending[{i}]", zr, optional=False)
        _in_band(f"inertia.refine_pending[{i}]", yw, j_band)
    if J.base_start is not None and not 0 <= J.base_start <= tr.n_windows:
        _bad("inertia.base_start", J.base_start, f"must be a window index 0..{tr.n_windows}")
    for k in range(W.count):
        _finite(f"width.t[{k}]", float(W.t[k]))
        _finite(f"width.y[{k}]", float(W.y[k]), 0.0, strict=True)
        _in_band(f"width.y[{k}]", float(W.y[k]), w_band)
        _finite(f"width.w[{k}]", float(W.w[k]), 0.0, strict=True)
    _finite("width.t0", W.t0)
    seg_start = _segment_start(tr)
    for i, c in enumerate(tr.changes):
        for f in ("time_s", "onset_time_s", "size", "size_se", "size_pct"):
            _finite(f"changes[{i}].{f}", getattr(c, f), optional=False)
        if last is not None and c.window_index >= seg_start and c.time_s > last:
            _bad(f"changes[{i}].time_s", c.time_s, f"after the last window's time {last!r}")


def _segment_start(tr) -> int:
    """First window of the current time segment: earlier windows may carry later times (the clock went back)."""
    return 0 if tr.last_discontinuity is None else tr.last_discontinuity[0]


def _check_channel(name: str, ch, tr, band):
    last = tr.last_time_s
    seg_start = _segment_start(tr)
    _finite(f"{name}.scale", ch.scale, 0.0, strict=True)
    if not min(tr.config.se_scale_min, 1.0) <= ch.scale <= max(tr.config.se_scale_max, 1.0):
        _bad(f"{name}.scale", ch.scale, f"outside se_scale_min..se_scale_max ({tr.config.se_scale_min:g}.."
                                        f"{tr.config.se_scale_max:g})")
    for f in ("baseline", "reference"):
        _finite(f"{name}.{f}", getattr(ch, f), 0.0, strict=True)
        _in_band(f"{name}.{f}", getattr(ch, f), band)
    for f in ("baseline_var", "reference_var"):
        _finite(f"{name}.{f}", getattr(ch, f), 0.0)
    if ch.phase != "commissioning" and (ch.baseline is None or ch.baseline_var is None):
        _bad(f"{name}.baseline", ch.baseline, f"missing in phase {ch.phase}")
    _finite(f"{name}.first_time", ch.first_time)
    if ch.n < 0:
        _bad(f"{name}.n", ch.n, "must be >= 0")
    c = ch.cusum
    for f, v in (("pos", c.pos), ("neg", c.neg)):
        _finite(f"{name}.cusum.{f}", v, 0.0)
    for f, pts in (("history", ch.history), ("comm", ch.comm), ("relearn", ch.relearn)):
        for k, (idx, t, y, se) in enumerate(pts):
            where = f"{name}.{f}[{k}]"
            if not 0 <= idx < max(tr.n_windows, 1):
                _bad(where + ".index", idx, f"outside 0..{tr.n_windows - 1}")
            _finite(where + ".time", t)
            if last is not None and idx >= seg_start and t > last:
                _bad(where + ".time", t, f"after the last window's time {last!r} (in the future)")
            _finite(where + ".value", y, 0.0, strict=True)
            _in_band(where + ".value", y, band)
            _finite(where + ".se", se, 0.0, strict=True)


# --------------------------------------------------------------------------- file

def save_state(tr, path: str | os.PathLike):
    """Write the state atomically: temp file in the same directory, fsync, os.replace."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    text = json.dumps(state_to_dict(tr), allow_nan=False, separators=(",", ":"))
    fd, tmp = tempfile.mkstemp(prefix=os.path.basename(path) + ".", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    try:
        dfd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def load_state(cls, path: str | os.PathLike, config: Optional[TrendConfig] = None, plausible: Optional[dict] = None):
    """Read a state written by :func:`save_state`.  TrendStateError when the file is unreadable, not JSON, of
    another kind or version, incomplete or fails the checks (FileNotFoundError when it does not exist)."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            d = json.load(f)
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise TrendStateError(f"{path}: not a readable trend state ({e})") from e
    try:
        return state_from_dict(cls, d, config, plausible)
    except TrendStateError as e:
        raise TrendStateError(f"{path}: {e}") from e
