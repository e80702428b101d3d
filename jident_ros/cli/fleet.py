"""``jident trend --fleet DIR... --out OUT``: the trend of every drive of a fleet (issue 21).

* **Recordings**: every bag directory (with ``metadata.yaml``) or ``.mcap`` file found under the arguments
  (recursively; a directory that is a bag is not searched further).
* **Drives**: a recording belongs to the drive(s) whose namespace it holds: the prefix of its ``drive/signals``
  (or ``joint_states``) topics, ``/press3/drive/signals`` -> ``press3`` (the root namespace -> ``drive``).  A
  recording with several drives' topics feeds each of them (``signals_topic``).  ``--drive-id FILE`` maps
  recordings to drives instead (CSV lines ``recording,drive``; a recording path relative to the FILE's folder
  or absolute); ``--drive-id parent`` takes the name of the recording's folder.
* **One trend per drive**: :func:`drive_trend` (a pure function of one drive's recordings, the options and the
  configuration) diagnoses the drive's recordings in recording order and runs one
  :class:`~jident_ros.identify.trend.TrendTracker` (the same as ``jident trend`` on that drive alone).  The
  drives run in a process pool (``--jobs``); the same function runs on Dask or Ray unchanged (docs/trend.md).
* **State** (``--state DIR``): one tracker state per drive, ``DIR/<drive>.json`` (the drive id percent-encoded):
  each drive resumes from its own when it exists (what it already holds is left out, as ``jident trend
  --state``) and saves it back atomically; a drive whose state is unusable gets an error row naming the file,
  the others carry on.
* **Outputs**: ``OUT/fleet.csv`` (one row per drive: recordings, windows, J1 fed, J1 drift from the
  drive's commissioned baseline with its 95 % interval, width, wear rate, time to the limit, level, changes,
  the status line), ``OUT/fleet.png`` (small multiples: J1 drift and width against time per drive),
  ``OUT/drives/<drive>/trend.csv`` (each drive's windows), and a table on stdout.
"""
from __future__ import annotations

import csv
import math
import os
import re
import time
import urllib.parse
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

from mcap.reader import make_reader

from jident_ros.bag.reader import bag_files
from jident_ros.cli.offline import OfflineError
from jident_ros.cli.trend_run import TrendOptions, run_trend, write_trend_csv
from jident_ros.identify.trend import LEVEL_NAMES, SECONDS_PER_DAY, Z95, TrendConfig, TrendStateError, TrendTracker

_SIGNALS = re.compile(r"^(.*?)/?(drive/signals|joint_states)$")
FLEET_COLUMNS = ("drive", "recordings", "windows", "inertia_fed", "inertia_drift_pct", "inertia_drift_low_pct",
                 "inertia_drift_high_pct", "inertia_kgm2", "inertia_baseline_kgm2", "backlash_width_mm",
                 "wear_rate_mm_per_day", "time_to_limit_days", "level", "changes", "last_change", "message", "error")


def find_recordings(paths) -> list:
    """Every bag directory or .mcap file under ``paths`` (sorted)."""
    out = []
    for p in map(Path, paths):
        if p.is_file() and p.suffix == ".mcap":
            out.append(p)
        elif (p / "metadata.yaml").is_file() or (p.is_dir() and any(p.glob("*.mcap"))):
            out.append(p)
        elif p.is_dir():
            out.extend(find_recordings(sorted(c for c in p.iterdir() if c.is_dir() or c.suffix == ".mcap")))
        else:
            raise OfflineError(f"recording {p}: no such bag directory or .mcap file")
    return out


def recording_namespaces(path) -> dict:
    """{drive id: its signals topic} of one recording, from the MCAP summaries (no message is read)."""
    found = {}
    for f in bag_files(path):
        try:
            with open(f, "rb") as fh:
                summary = make_reader(fh).get_summary()
        except Exception as exc:  # noqa: BLE001 -- a damaged file: diagnosed (and reported) later
            raise OfflineError(f"recording {path}: its topics cannot be read ({exc}); `jident salvage` it") from None
        for ch in (summary.channels.values() if summary is not None else ()):
            m = _SIGNALS.match(ch.topic)
            if m:
                found[m.group(1).strip("/").replace("/", "_") or "drive"] = ch.topic
    return found


def group_by_drive(recordings, drive_id: Optional[str] = None) -> dict:
    """{drive: [(recording, signals topic or None), ...]} (module docstring)."""
    groups: dict = {}
    if drive_id == "parent":
        for r in recordings:
            groups.setdefault(Path(r).parent.name or "drive", []).append((str(r), None))
        return groups
    if drive_id:
        mapping = _read_mapping(Path(drive_id))
        for r in recordings:
            key = str(Path(r).resolve())
            if key not in mapping:
                raise OfflineError(f"--drive-id {drive_id}: no drive for recording {r}")
            groups.setdefault(mapping[key], []).append((str(r), None))
        return groups
    for r in recordings:
        ns = recording_namespaces(r)
        if not ns:
            raise OfflineError(f"recording {r}: no drive/signals or joint_states topic")
        for drive, topic in ns.items():
            groups.setdefault(drive, []).append((str(r), topic if len(ns) > 1 else None))
    return groups


def _read_mapping(path: Path) -> dict:
    try:
        rows = list(csv.reader(path.read_text(encoding="utf-8").splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise OfflineError(f"--drive-id {path}: cannot be read ({exc})") from None
    out = {}
    for k, row in enumerate(rows, 1):
        if not row or row[0].startswith("#"):
            continue
        if len(row) != 2 or not row[1].strip():
            raise OfflineError(f"--drive-id {path}, line {k}: expected 'recording,drive', got {','.join(row)!r}")
        rec = Path(row[0].strip())
        key = str((rec if rec.is_absolute() else path.parent / rec).resolve())
        if key in out and out[key] != row[1].strip():
            raise OfflineError(f"--drive-id {path}, line {k}: {row[0]} mapped twice ({out[key]}, {row[1].strip()})")
        out[key] = row[1].strip()
    return out


@dataclass
class DriveTrend:
    """One drive's result: its summary row, its time series (for the small multiples), its windows' csv."""

    drive: str
    row: dict
    time_s: list = field(default_factory=list)
    drift_pct: list = field(default_factory=list)
    width_mm: list = field(default_factory=list)
    change_times_s: list = field(default_factory=list)
    seconds: float = 0.0


def state_file(state_dir, drive: str) -> Path:
    """The state file of ``drive`` in the fleet's ``--state`` directory: ``<drive>.json``, the drive id
    percent-encoded (no separator or other character of the id can leave the directory or collide)."""
    return Path(state_dir) / (urllib.parse.quote(drive, safe="") + ".json")


def _resumed(path: Path, config: TrendConfig, overrides: Optional[dict]) -> Optional[TrendTracker]:
    """The tracker saved at ``path`` (None: no such file yet; then ``config`` starts a new one) under its saved
    configuration with ``overrides`` (the flags given).  TrendStateError when it cannot be used."""
    if not path.exists():
        return None
    saved = TrendTracker.load(path)
    return TrendTracker.load(path, TrendConfig.from_dict({**saved.config.to_dict(), **(overrides or {})}))


def drive_trend(drive: str, recordings: list, options: TrendOptions, config: TrendConfig,
                out_dir: Optional[str] = None, state_dir: Optional[str] = None,
                overrides: Optional[dict] = None) -> DriveTrend:
    """One drive's trend (picklable in and out: a process pool, Dask or Ray can run it).  ``recordings``:
    [(path, signals topic or None)]; all of one drive share one topic or the recording's only one.
    ``out_dir``: where the drive's trend.csv goes (None: not written).  ``state_dir``: the drive resumes from
    :func:`state_file` when it exists (its saved configuration with ``overrides``) and saves its tracker there.
    Never raises on a bad recording or state: the row's ``error`` says what failed."""
    t0 = time.perf_counter()
    paths = [r for r, _ in recordings]
    topics = {t for _, t in recordings}
    opts = options if len(topics) != 1 else TrendOptions(**{**asdict_shallow(options), "signals_topic": topics.pop()})
    state = None if state_dir is None else state_file(state_dir, drive)
    try:
        tracker = None if state is None else _resumed(state, config, overrides)
        run = run_trend(paths, opts, config=config, tracker=tracker)
        if state is not None:
            run.tracker.save(state)
    except TrendStateError as exc:
        return DriveTrend(drive, _row(drive, len(paths), None, f"--state {state}: {exc}"),
                          seconds=time.perf_counter() - t0)
    except (OfflineError, OSError) as exc:
        return DriveTrend(drive, _row(drive, len(paths), None, str(exc)), seconds=time.perf_counter() - t0)
    if out_dir is not None:
        d = Path(out_dir) / "drives" / drive
        d.mkdir(parents=True, exist_ok=True)
        write_trend_csv(run, d / "trend.csv")
    ok = [(w, u) for w, u in zip(run.windows, run.updates) if not u.skipped]
    res = DriveTrend(drive, _row(drive, len(paths), run, None), seconds=time.perf_counter() - t0)
    for w, u in ok:
        res.time_s.append(w.time_s)
        res.drift_pct.append(math.nan if u.inertia_drift_pct is None else u.inertia_drift_pct)
        res.width_mm.append(math.nan if u.width_m is None else 1e3 * u.width_m)
    res.change_times_s = [c.time_s for c in run.tracker.changes if c.quantity == "inertia"]
    return res


def asdict_shallow(obj) -> dict:
    return {f: getattr(obj, f) for f in obj.__dataclass_fields__}


def _row(drive: str, n_rec: int, run, error: Optional[str]) -> dict:
    row = dict.fromkeys(FLEET_COLUMNS, "")
    row.update(drive=drive, recordings=n_rec, error=error or "")
    if run is None or not run.updates:
        row["level"] = "ERROR" if error else "OK"
        row["message"] = error or "no window"
        return row
    u = run.updates[-1]
    # the drift from the commissioned baseline (kept over re-baselines after a change), with the drift's interval
    drift = u.inertia_drift_from_reference_pct
    half = None if u.inertia_drift_se_pct is None else Z95 * u.inertia_drift_se_pct
    lo_hi = (None, None) if drift is None or half is None else (drift - half, drift + half)
    last = next((c for c in reversed(run.tracker.changes) if c.quantity == "inertia"), None)
    row.update(windows=len(run.windows), inertia_fed=u.inertia_windows_fed, inertia_drift_pct=_n(drift),
               inertia_drift_low_pct=_n(lo_hi[0]), inertia_drift_high_pct=_n(lo_hi[1]), inertia_kgm2=_n(u.inertia_kgm2),
               inertia_baseline_kgm2=_n(u.inertia_baseline_kgm2),
               backlash_width_mm=_n(None if u.width_m is None else 1e3 * u.width_m),
               wear_rate_mm_per_day=_n(None if u.wear_rate_m_per_day is None else 1e3 * u.wear_rate_m_per_day),
               time_to_limit_days=_n(None if u.time_to_limit_s is None else u.time_to_limit_s / SECONDS_PER_DAY),
               level=LEVEL_NAMES[u.level], changes=len(run.tracker.changes),
               last_change="" if last is None else f"{last.size_pct:+.2f} % at t = {last.time_s:.0f} s",
               message=u.message)
    return row


def _n(v) -> str:
    return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{float(v):.6g}"


def run_fleet(groups: dict, options: TrendOptions, config: TrendConfig, out_dir, jobs: int = 1,
              on_drive=None, state_dir=None, overrides: Optional[dict] = None) -> list:
    """:func:`drive_trend` for every drive of ``groups`` in a pool of ``jobs`` processes (1: in this process);
    the results in the drives' order.  ``on_drive(result)`` as each finishes.  ``state_dir``: one state per
    drive (:func:`state_file`)."""
    drives = sorted(groups)
    one = dataclasses_replace_jobs(options)
    sd = None if state_dir is None else str(state_dir)
    if jobs <= 1 or len(drives) <= 1:
        out = []
        for d in drives:
            out.append(drive_trend(d, groups[d], one, config, str(out_dir), sd, overrides))
            if on_drive is not None:
                on_drive(out[-1])
        return out
    with ProcessPoolExecutor(max_workers=min(jobs, len(drives))) as pool:
        futures = {d: pool.submit(drive_trend, d, groups[d], one, config, str(out_dir), sd, overrides)
                   for d in drives}
        out = []
        for d in drives:
            out.append(futures[d].result())
            if on_drive is not None:
                on_drive(out[-1])
    return out


def dataclasses_replace_jobs(options: TrendOptions) -> TrendOptions:
    """The options with jobs = 1: the pool is over drives, each drive's recordings run in its worker."""
    return TrendOptions(**{**asdict_shallow(options), "jobs": 1})


def write_fleet_csv(results: list, path) -> Path:
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, FLEET_COLUMNS)
        w.writeheader()
        for r in results:
            w.writerow(r.row)
    return path


def plot_fleet(results: list, path) -> Path:
    """Small multiples: per drive, the J1 drift (%) and the width (mm, right axis) against drive time (days)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = max(1, len(results))
    cols = min(10, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(1.9 * cols, 1.5 * rows), squeeze=False, sharex=False)
    for ax in axes.flat[n:]:
        ax.axis("off")
    for ax, r in zip(axes.flat, results):
        t0 = r.time_s[0] if r.time_s else 0.0
        days = [(t - t0) / SECONDS_PER_DAY for t in r.time_s]
        ax.plot(days, r.drift_pct, ".", ms=1.5, color="C0")
        for tc in r.change_times_s:
            ax.axvline((tc - t0) / SECONDS_PER_DAY, color="C3", lw=0.8)
        ax2 = ax.twinx()
        ax2.plot(days, r.width_mm, "-", lw=0.8, color="C1")
        ax.set_title(f"{r.drive} [{r.row['level']}]", fontsize=6, color="C3" if r.row["level"] != "OK" else "k")
        ax.tick_params(labelsize=5)
        ax2.tick_params(labelsize=5, colors="C1")
    fig.suptitle("J1 drift from each drive's baseline, % (blue; red: a detected change) and backlash width, "
                 "mm (orange), against drive time, days", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def format_fleet(results: list) -> str:
    head = f"{'drive':<16} {'rec':>4} {'J1 fed':>6} {'J1 drift %':>20} {'width mm':>8} {'wear mm/d':>9} " \
           f"{'limit d':>7} {'level':<5} changes"
    lines = [head]
    for r in results:
        x = r.row
        drift = "" if x["inertia_drift_pct"] == "" else (
            f"{float(x['inertia_drift_pct']):+.2f} [{float(x['inertia_drift_low_pct']):+.1f},"
            f"{float(x['inertia_drift_high_pct']):+.1f}]")
        lines.append(f"{r.drive:<16} {x['recordings']:>4} {x['inertia_fed']!s:>6} {drift:>20} "
                     f"{_short(x['backlash_width_mm']):>8} {_short(x['wear_rate_mm_per_day']):>9} "
                     f"{_short(x['time_to_limit_days']):>7} {x['level']:<5} {x['changes']}"
                     + (f" {x['last_change']}" if x["last_change"] else "") + (f" ERROR: {x['error']}" if x["error"] else ""))
    return "\n".join(lines)


def _short(v) -> str:
    return "" if v == "" else f"{float(v):.3g}"


def cmd_fleet(args, options: TrendOptions, config: TrendConfig, overrides: Optional[dict] = None) -> int:
    """``jident trend --fleet``: group, run, write (module docstring).  ``overrides``: the trend flags given
    (they replace a resumed state's saved values)."""
    t0 = time.perf_counter()
    recordings = find_recordings(args.recordings)
    if not recordings:
        raise OfflineError(f"--fleet: no bag directory or .mcap file under {' '.join(args.recordings)}")
    groups = group_by_drive(recordings, args.drive_id)
    out = Path(args.out)
    state_dir = None
    if getattr(args, "state", None):
        state_dir = Path(args.state)
        if state_dir.exists() and not state_dir.is_dir():
            raise OfflineError(f"--state {state_dir}: with --fleet, a directory for one state per drive "
                               f"(<drive>.json), and this is a file")
        state_dir.mkdir(parents=True, exist_ok=True)
    out.mkdir(parents=True, exist_ok=True)
    jobs = options.jobs if options.jobs > 0 else (os.cpu_count() or 1)
    results = run_fleet(groups, options, config, out, jobs, state_dir=state_dir, overrides=overrides)
    csv_path = write_fleet_csv(results, out / "fleet.csv")
    png_path = plot_fleet(results, out / "fleet.png")
    print(format_fleet(results))
    print(f"{len(groups)} drive(s), {len(recordings)} recording(s); wrote {csv_path}, {png_path} and "
          f"{out / 'drives'}/<drive>/trend.csv" + (f"; states in {state_dir}" if state_dir else "")
          + f" ({time.perf_counter() - t0:.1f} s, {jobs} process(es))")
    return 0 if all(not r.row["error"] for r in results) else 1


__all__ = ["DriveTrend", "FLEET_COLUMNS", "cmd_fleet", "drive_trend", "find_recordings", "format_fleet",
           "group_by_drive", "plot_fleet", "recording_namespaces", "run_fleet", "state_file", "write_fleet_csv"]
