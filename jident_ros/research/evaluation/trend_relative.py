"""Issue 21's targets on real diagnosed windows of each drive model of the validation zoo.

    python -m jident_ros.research.evaluation.trend_relative [--models ours,second_drive,vector_drive] [--trials 400]
                                                   [--recordings 40] [--work DIR] [--seed 0]

1. **Windows as a drive records them**: per model, single-event recordings at 30 dB with 2^16-count encoders
   and raw angles, every channel the model records (with ``--drive-only`` the drive's own signals only:
   ``t, alpha1, omega1, m_el, alpha2, omega2``, no accelerometer -- :data:`jident_ros.research.evaluation.raw_scenario.DRIVE_CHANNELS`;
   on our simulator the flank detector's entry refinement then puts half the entries late, docs/results.md), K2 spread over 2.5-6 mm,
   J1 = 1.16 (the baseline) and 1.131 (-2.5 %, the next paper class); ``--no-entry-refinement``: an experiment
   with the flank detector's entry sample = its departure sample (:func:`~jident_ros.research.evaluation.
   raw_scenario.entry_refinement`):

   * ``ours``: :func:`jident_ros.research.evaluation.raw_inputs.raw_recordings` (our simulator);
   * ``second_drive``: ``python -m jident_ros.research.second_drive --format csv --scenario grid`` (docs/second_drive.md);
   * ``vector_drive``: ``python -m jident_ros.research.vector_drive --formats csv`` (motulator; skipped when missing),
     one call per recording with its own seed (a call draws all its recordings' noise from one seed), the
     noise-free simulation cached in the work directory.

   Every recording is diagnosed by ``jident diagnose``'s path (:func:`jident_ros.cli.offline.diagnose_samples`,
   flank detector, gap estimator, no image method) and each window turned into the tracker's inputs by the
   node's rule (:func:`jident_ros.cli.trend_run.trend_window`: every J1 physics allows, published or not).  The
   pools say how many windows named a class alone (published), how many were ambiguous, and how many refused.
2. **Step detection**: series of ``commissioning_windows`` (5) + 25 steady windows drawn (with replacement)
   from the 1.16 pool, then windows from the 1.131 pool: the first J1 change at or after the step, and any
   before it (the tracker's defaults).  Also with whole recordings drawn (each with its windows in order: since
   the flank detector's return traversals, a second-drive or vector-drive recording gives an entry window and a
   return window, whose standard errors differ ~7x on the vector drive).
3. **False changes**: 10 series of 5 + 1,000 steady windows (bootstrap of the 1.16 pool); the changes in
   the commissioning phase (the windows while the baseline is refined, 5..19) counted apart, from 2,000
   series, as a rate per window.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from jident_ros.cli.offline import OfflineError, diagnose_samples
from jident_ros.cli.trend_run import trend_window
from jident_ros.config import load_system_config
from jident_ros.identify.trend import TrendConfig, TrendTracker
from jident_ros.research.evaluation.raw_inputs import raw_recordings
from jident_ros.research.evaluation.raw_scenario import DRIVE_CHANNELS, entry_refinement
from jident_ros.research.evaluation.trend_simulation import delay_summary, step_delay, step_trials

MODELS = ("ours", "second_drive", "vector_drive")
SNR_DB = 30.0
J1_BASE, J1_STEP = 1.16, 1.131
WINDOW_PERIOD_S = 3600.0


def _write_csv(path: Path, data: np.ndarray, channels, keep=None) -> Path:
    cols = [channels.index(c) for c in (keep or channels) if c in channels]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([channels[c] for c in cols])
        w.writerows(data[:, cols].tolist())
    return path


def _drive_only(src: Path, dst: Path) -> Path:
    """A CSV with the drive's own channels only."""
    with open(src, newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0]
    keep = [head.index(c) for c in DRIVE_CHANNELS if c in head]
    dst = dst.with_name(dst.name.replace(".drive.csv", "_drive.csv"))
    with open(dst, "w", newline="") as f:
        w = csv.writer(f)
        for r in rows:
            w.writerow([r[k] for k in keep])
    return dst


def recordings(model: str, work: Path, n_per_j1: int, seed: int, system, drive_only: bool = False) -> list:
    """[(CSV path, true J1, wheel radius r in m, gear ratio N)] of ``model`` (module docstring): every channel the
    model records, or with ``drive_only`` the drive's own
    (:data:`~jident_ros.research.evaluation.raw_scenario.DRIVE_CHANNELS`).  r and N are the drive's geometry as
    its user configures it: ``system``'s for ours, the truth file's ``reference_radius_m`` and ``gear_ratio`` for
    the other models (the second drive's r is 0.08 m, not our 0.1 m)."""
    work.mkdir(parents=True, exist_ok=True)
    widths = np.linspace(0.0025, 0.006, 8)
    out = []
    if model == "ours":
        for j1 in (J1_BASE, J1_STEP):
            for k in range(math.ceil(n_per_j1 / len(widths))):
                for rec in raw_recordings(system, [j1], list(widths), snr_db=SNR_DB, steady_s=0.3,
                                          seed=seed * 7919 + k + (0 if j1 == J1_BASE else 100_000)):
                    p = work / f"ours_{j1:.3f}_{len(out):04d}.csv"
                    out.append((_write_csv(p, rec.data, list(rec.channels), DRIVE_CHANNELS if drive_only else None),
                                j1, system.load.wheel_radius_m, 1.0))
        return out
    module = {"second_drive": "jident_ros.research.second_drive",
              "vector_drive": "jident_ros.research.vector_drive"}[model]
    calls = []       # (folder, seed, J1 values, widths)
    if model == "second_drive":
        # one call per 8 widths: its noise is drawn per case (rng [seed, case])
        for k in range(math.ceil(n_per_j1 / len(widths))):
            calls.append((work / f"{model}_{k}", seed * 1000 + k, (J1_BASE, J1_STEP), widths))
    else:
        # the vector drive draws every recording of one call from the same rng ([seed, counts, snr]): the same
        # noise and encoder offsets for every J1 and width of a call.  One call per recording (its own seed), the
        # noise-free simulation cached in the work directory (the J1 x width cases are simulated once)
        for j1, off in ((J1_BASE, 0), (J1_STEP, 500)):
            for k in range(n_per_j1):
                calls.append((work / f"{model}_{j1:.3f}_{k:03d}", seed * 1000 + off + k, (j1,),
                              (widths[k % len(widths)],)))
    for d, call_seed, j1s, ws in calls:
        done = d / ".complete"
        if model == "second_drive":
            args = ["--format", "csv", "--scenario", "grid", "--direction", "forward", "--snr-db", str(SNR_DB),
                    "--inertias", ",".join(f"{j:g}" for j in j1s), "--widths", ",".join(f"{w:.5f}" for w in ws)]
        else:
            args = ["--formats", "csv", "--events", "speed_step_down", "--directions", "forward", "--counts", "65536",
                    "--snr-db", f"{SNR_DB:g}", "--inertias", ",".join(f"{j:g}" for j in j1s),
                    "--widths", ",".join(f"{w:.5f}" for w in ws), "--cache", str(work / "simulation_cache")]
        cmd = [sys.executable, "-m", module, "--out", str(d), "--seed", str(call_seed)] + args
        if not (done.exists() and done.read_text() == " ".join(cmd[1:])):
            # simulate; a folder already written by the same command in this work directory is reused (its
            # .complete names the command)
            done.unlink(missing_ok=True)
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"{model}: {proc.stderr.strip().splitlines()[-1] if proc.stderr else proc.returncode}")
            done.write_text(" ".join(cmd[1:]))
        for csv_path in sorted(p for p in d.rglob("*.csv") if not p.name.endswith("_drive.csv")):
            tr = _truth(csv_path)
            out.append((_drive_only(csv_path, csv_path.with_suffix(".drive.csv")) if drive_only else csv_path,
                        float(tr["inertia_kgm2"]), float(tr["reference_radius_m"]), float(tr.get("gear_ratio", 1.0))))
    return out


def _truth(csv_path: Path) -> dict:
    """The truth record of one recording (its own ``.truth.json``, else its row in the folder's truth.json)."""
    own = csv_path.with_suffix(".truth.json")
    if own.exists():
        return json.loads(own.read_text())
    index = json.loads((csv_path.parent / "truth.json").read_text())
    for r in index.get("recordings", []):
        if Path(r["file"]).name == csv_path.name:
            return r
    raise KeyError(f"{csv_path}: no truth")


def pools(recs: list, system) -> dict:
    """{true J1: {"j1": array, "se": array}} of the windows the trend takes, and the counts of what happened."""
    out = {J1_BASE: ([], [], []), J1_STEP: ([], [], [])}
    counts = {"recordings": len(recs), "windows": 0, "published": 0, "ambiguous_fed": 0, "other_fed": 0,
              "refused": {}, "no_window": 0, "errors": 0}
    for rec_index, (path, j1, radius_m, gear_ratio) in enumerate(recs):
        sysr = system if radius_m == system.load.wheel_radius_m else \
            replace(system, load=replace(system.load, wheel_radius_m=radius_m))
        try:
            res = diagnose_samples(path, system=sysr, image_method=False, build_if_missing=False, gear_ratio=gear_ratio)
        except OfflineError:
            counts["errors"] += 1
            continue
        if not res.windows:
            counts["no_window"] += 1
        for ow in res.windows:
            counts["windows"] += 1
            tw = trend_window(ow, str(path))
            if tw.inertia_kgm2 is None:
                counts["refused"][tw.refused_kind] = counts["refused"].get(tw.refused_kind, 0) + 1
                continue
            key = "published" if ow.diagnosis.inertia_kgm2 is not None else (
                "ambiguous_fed" if ow.diagnosis.status == "ambiguous" else "other_fed")
            counts[key] += 1
            out[j1][0].append(tw.inertia_kgm2)
            out[j1][2].append(rec_index)
            out[j1][1].append(tw.inertia_se_kgm2)
    p = {j: {"j1": np.array(a), "se": np.array(b), "rec": np.array(c, dtype=int)} for j, (a, b, c) in out.items()}
    for j, d in p.items():
        if d["j1"].size:
            z = (d["j1"] - j) / d["se"]
            d.update(n=int(d["j1"].size), se_pct_median=float(np.median(d["se"] / j * 100)),
                     z_sd=float(z.std(ddof=1)) if z.size > 1 else math.nan, z_mean=float(z.mean()))
    return {"pools": p, "counts": counts}


def save_pools(pl: dict, path: Path) -> None:
    """The diagnosed windows (J1, se per true J1) and their counts, so that a tracker design can be tried again
    on them without simulating and diagnosing again (``--work DIR``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    d = {"counts": pl["counts"], "pools": {str(j): {"j1": v["j1"].tolist(), "se": v["se"].tolist(),
                                                    "rec": v["rec"].tolist()}
                                            for j, v in pl["pools"].items()}}
    path.write_text(json.dumps(d))


def load_pools(path: Path) -> dict | None:
    """What :func:`save_pools` wrote (with the pools' statistics recomputed), or None when absent."""
    if not path.exists():
        return None
    d = json.loads(path.read_text())
    p = {}
    for j, v in d["pools"].items():
        jf = float(j)
        a = {"j1": np.array(v["j1"], dtype=float), "se": np.array(v["se"], dtype=float),
             "rec": np.array(v.get("rec", range(len(v["j1"]))), dtype=int)}
        if a["j1"].size:
            z = (a["j1"] - jf) / a["se"]
            a.update(n=int(a["j1"].size), se_pct_median=float(np.median(a["se"] / jf * 100)),
                     z_sd=float(z.std(ddof=1)) if z.size > 1 else math.nan, z_mean=float(z.mean()))
        p[jf] = a
    return {"pools": p, "counts": d["counts"]}


def detection(p: dict, trials: int, seed: int, config: TrendConfig, pre: int = 25, post: int = 20,
              by_recording: bool = False) -> dict:
    """The step trials.  Windows drawn one by one from the pools (default), or ``by_recording``: whole recordings
    drawn, each bringing its windows in their order (a drive whose every recording has an entry and a return
    traversal feeds them alternately), the step at the first window of the first stepped recording, the delay
    still counted in windows."""
    rng = np.random.default_rng(seed)
    base, step = p[J1_BASE], p[J1_STEP]
    comm = config.commissioning_windows

    def draw(pool, n):
        if not by_recording:
            return rng.integers(0, pool["j1"].size, n)
        recs = np.unique(pool["rec"])
        idx: list = []
        while len(idx) < n:
            idx.extend(np.flatnonzero(pool["rec"] == recs[rng.integers(0, recs.size)]).tolist())
        return np.array(idx, dtype=int)

    def series(_):
        i0 = draw(base, comm + pre)
        i1 = draw(step, post)
        j = np.concatenate([base["j1"][i0], step["j1"][i1]])
        se = np.concatenate([base["se"][i0], step["se"][i1]])
        series.step_at = i0.size
        return WINDOW_PERIOD_S * np.arange(j.size), j, se, -1
    if not by_recording:
        r = step_trials(trials, series, config, comm + pre)
    else:
        delays, missed, before = [], 0, 0
        for trial in range(trials):
            t, j, se, sign = series(trial)
            found, false = step_delay(TrendTracker(config), t, j, se, series.step_at, sign)
            before += false
            if found is None:
                missed += 1
            else:
                delays.append(found)
        r = delay_summary(trials, delays, missed, before)
    r["within_5"] = sum(v for k, v in r["histogram"].items() if k <= 5)
    return r


def false_changes(base: dict, seed: int, config: TrendConfig, series: int = 10, monitored: int = 1000,
                  commissioning_series: int = 2000) -> dict:
    """Changes after commissioning (``series`` x ``monitored`` windows) and while the baseline is refined
    (windows commissioning_windows .. baseline_refine_windows - 1 of ``commissioning_series`` series)."""
    rng = np.random.default_rng(seed)
    comm, refine = config.commissioning_windows, max(config.baseline_refine_windows, config.commissioning_windows)
    after = 0
    for _ in range(series):
        idx = rng.integers(0, base["j1"].size, comm + monitored)
        us = TrendTracker(config).batch(WINDOW_PERIOD_S * np.arange(idx.size), base["j1"][idx], base["se"][idx])
        after += sum(1 for u in us if any(c.quantity == "inertia" for c in u.changes))
    early = early_series = 0
    for _ in range(commissioning_series):
        idx = rng.integers(0, base["j1"].size, refine)
        us = TrendTracker(config).batch(WINDOW_PERIOD_S * np.arange(idx.size), base["j1"][idx], base["se"][idx])
        hit = sum(1 for u in us[comm:] if u.changes)
        early += hit
        early_series += bool(hit)
    n_early = commissioning_series * (refine - comm)
    return {"monitored": series * monitored, "changes": after,
            "per_10k_upper95": 1e4 * float(chi2.ppf(0.95, 2 * (after + 1))) / 2 / (series * monitored),
            "commissioning_windows": n_early, "commissioning_changes": early,
            "commissioning_series_with_change": early_series, "commissioning_series": commissioning_series,
            "commissioning_rate_per_window": early / n_early,
            "commissioning_rate_upper95": float(chi2.ppf(0.95, 2 * (early + 1))) / 2 / n_early}


def run_model(model: str, work: Path, n_per_j1: int, trials: int, seed: int, system, config: TrendConfig,
              drive_only: bool = False, refine: bool = True) -> dict:
    t0 = time.perf_counter()
    mdir = work / (model + ("_drive_only" if drive_only else ""))
    cache = mdir / f"pools_v2_n{n_per_j1}_s{seed}{'' if refine else '_norefine'}.json"
    pl = load_pools(cache)
    if pl is None:
        recs = recordings(model, mdir, n_per_j1, seed, system, drive_only)
        with entry_refinement(refine):
            pl = pools(recs, system)
        save_pools(pl, cache)
    p = pl["pools"]
    if not (p[J1_BASE]["j1"].size and p[J1_STEP]["j1"].size):
        return {"model": model, "counts": pl["counts"], "error": "no window reached the trend"}
    return {"model": model, "counts": pl["counts"],
            "pools": {str(j): {k: v for k, v in d.items() if not isinstance(v, np.ndarray)} for j, d in p.items()},
            "detection": detection(p, trials, seed + 1, config),
            "detection_by_recording": detection(p, trials, seed + 1, config, by_recording=True),
            "false": false_changes(p[J1_BASE], seed + 2, config), "seconds": time.perf_counter() - t0}


def format_rows(results: list) -> str:
    lines = ["| model | windows (published alone / ambiguous, fed / refused) | se median | -2.5 % step: within 5 "
             "windows / detected / trials, delay median, max; before the step | the same, whole recordings drawn "
             "| false changes after commissioning | commissioning phase (windows 5-19) |", "|---|---|---|---|---|---|---|"]
    for r in results:
        c = r["counts"]
        if "error" in r:
            lines.append(f"| {r['model']} | {c} | | {r['error']} | | | |")
            continue
        d, f = r["detection"], r["false"]
        dr = r.get("detection_by_recording") or d
        se = r["pools"][str(J1_BASE)]["se_pct_median"]
        lines.append(
            f"| {r['model']} | {c['windows']} ({c['published']} / {c['ambiguous_fed']} / "
            f"{sum(c['refused'].values())} {c['refused']}) | {se:.2f} % | {d['within_5']} / {d['detected']} / "
            f"{d['trials']} = {100 * d['within_5'] / d['trials']:.1f} %, median {d['median']:g}, max {d['max']:g}; "
            f"{d['false_before_step']} | {dr['within_5']} / {dr['detected']} / {dr['trials']} = "
            f"{100 * dr['within_5'] / dr['trials']:.1f} %, median {dr['median']:g}, max {dr['max']:g}; "
            f"{dr['false_before_step']} | {f['changes']} in {f['monitored']:,} (95 % upper bound "
            f"{f['per_10k_upper95']:.2g} per 10,000) | {f['commissioning_changes']} in {f['commissioning_windows']:,} "
            f"windows = {f['commissioning_rate_per_window']:.2g} per window (upper {f['commissioning_rate_upper95']:.2g}); "
            f"{f['commissioning_series_with_change']} of {f['commissioning_series']} commissionings |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="issue 21's trend targets on each drive model")
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--recordings", type=int, default=40, help="recordings per J1 and model (default 40)")
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", help="work directory (default: a temporary one)")
    ap.add_argument("--drive-only", action="store_true",
                    help="keep only the drive's own channels (t, alpha1, omega1, m_el, alpha2, omega2)")
    ap.add_argument("--no-entry-refinement", action="store_true",
                    help="experiment: the flank detector's entry sample = its departure sample "
                         "(raw_scenario.entry_refinement), to tell the detector's share from the estimator's")
    a = ap.parse_args(argv)
    system = load_system_config()
    work = Path(a.work or tempfile.mkdtemp(prefix="trend_relative_"))
    results = []
    for m in a.models.split(","):
        try:
            results.append(run_model(m, work, a.recordings, a.trials, a.seed, system, TrendConfig(), a.drive_only,
                                     not a.no_entry_refinement))
        except RuntimeError as exc:
            results.append({"model": m, "counts": {}, "error": str(exc)})
        print(json.dumps(results[-1], default=str), file=sys.stderr)
    print(format_rows(results))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
