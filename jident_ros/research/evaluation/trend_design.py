"""Try tracker designs on windows already diagnosed (no simulation): the numbers of docs/trend.md, "The drive's
error scale", and docs/results.md, "Trend: the drive's error scale".

    python -m jident_ros.research.evaluation.trend_design --targets-pools out/trw/targets_pools.npz
        [--work out/trw --models ours,second_drive,vector_drive] [--trials 400 --monitored 100000]
        [--config "" --config "error_scale_prior_dof=None" ...] [--precision]

* ``--targets-pools``: the .npz of ``trend_targets --pools`` (our simulator's 4,000 + 2 x 2,000 windows): per
  configuration, :func:`trend_targets.false_changes` (``--monitored`` bootstrapped steady windows, seed 3) and
  :func:`trend_targets.detection` (``--trials``, seed 4), as ``trend_targets`` runs them;
* ``--work``: a ``trend_relative --work`` directory: per model its cached pools (``pools_v2_n40_s0.json``, or
  ``--pools-file``), :func:`trend_relative.detection` (windows and whole recordings drawn) and
  :func:`trend_relative.false_changes`, seeds as ``trend_relative`` (1, 2);
* ``--config``: ``name=value`` pairs, comma-separated, of :class:`TrendConfig` (value a number, ``None``, ``True`` or
  ``False``); ``""`` is the default configuration;
* ``--by-kind``: an experiment, not the tracker: per model, whole recordings drawn and one tracker per window
  position in its recording (0: the entry, 1: the return traversal), the drive's change the first of either;
* ``--precision``: synthetic calibrated Gaussian pools (4,000 windows per level, scatter = se = 0.5 ... 1.5 % of
  J1, seed 7): the -2.5 % step within 5 windows per scatter, default and Gaussian z (400 trials, seed 1).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from jident_ros.identify.trend import TrendConfig, TrendTracker
from jident_ros.research.evaluation import trend_relative as trl
from jident_ros.research.evaluation import trend_targets as tt
from jident_ros.research.evaluation.trend_simulation import delay_summary


def parse_config(text: str) -> TrendConfig:
    kw = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, _, value = part.partition("=")
        v = {"None": None, "True": True, "False": False}.get(value.strip(), value.strip())
        if isinstance(v, str):
            v = int(v) if v.lstrip("-").isdigit() else float(v)
        kw[name.strip()] = v
    return TrendConfig(**kw)


def load_targets_pools(path) -> tuple:
    with np.load(path, allow_pickle=False) as z:
        return tuple({k[len(n) + 1:]: z[k] for k in z.files if k.startswith(n + ".")} for n in ("steady", "up", "down"))


def on_targets(pools: tuple, cfg: TrendConfig, trials: int, monitored: int) -> dict:
    s, u, d = pools
    f = tt.false_changes(s, monitored, 3, cfg)
    det = tt.detection(s, u, d, trials, 4, cfg)
    return {"false": f["changes"], "monitored": f["monitored"], "own_order": f["own_order_changes"],
            "before": det["false_before_step"], "detected": det["detected"], "trials": det["trials"],
            "within_5": sum(v for k, v in det["histogram"].items() if k <= 5), "histogram": det["histogram"]}


def on_model(pool_file: Path, cfg: TrendConfig, trials: int) -> dict:
    p = trl.load_pools(pool_file)["pools"]
    det = trl.detection(p, trials, 1, cfg)
    rec = trl.detection(p, trials, 1, cfg, by_recording=True)
    f = trl.false_changes(p[trl.J1_BASE], 2, cfg)
    return {"within_5": det["within_5"], "before": det["false_before_step"], "histogram": det["histogram"],
            "by_recording_within_5": rec["within_5"], "by_recording_before": rec["false_before_step"],
            "false": f["changes"], "commissioning_changes": f["commissioning_changes"]}


def by_kind(pool_file: Path, cfg: TrendConfig, trials: int, seed: int = 1, pre: int = 25, post: int = 20) -> dict:
    """Step trials drawing whole recordings (as :func:`trend_relative.detection` with ``by_recording``), each window
    fed to the tracker of its position in the recording: a baseline per window kind."""
    p = trl.load_pools(pool_file)["pools"]
    rng = np.random.default_rng(seed)
    pos = {}
    for j, d in p.items():
        k = np.zeros(d["rec"].size, dtype=int)
        for i in range(1, k.size):
            k[i] = k[i - 1] + 1 if d["rec"][i] == d["rec"][i - 1] else 0
        pos[j] = k

    def draw(j, n):
        recs = np.unique(p[j]["rec"])
        idx: list = []
        while len(idx) < n:
            idx.extend(np.flatnonzero(p[j]["rec"] == recs[rng.integers(0, recs.size)]).tolist())
        return idx
    delays, missed, before = [], 0, 0
    for _ in range(trials):
        i0 = draw(trl.J1_BASE, cfg.commissioning_windows + pre)
        i1 = draw(trl.J1_STEP, post)
        seq = [(trl.J1_BASE, i) for i in i0] + [(trl.J1_STEP, i) for i in i1]
        trackers: dict = {}
        found = None
        for n, (j, i) in enumerate(seq):
            tr = trackers.setdefault(int(pos[j][i]), TrendTracker(cfg))
            u = tr.update(trl.WINDOW_PERIOD_S * n, float(p[j]["j1"][i]), float(p[j]["se"][i]))
            for c in u.changes:
                if c.quantity != "inertia":
                    continue
                if n < len(i0):
                    before += 1
                elif c.sign == -1 and found is None:
                    found = n - len(i0) + 1
            if found is not None:
                break
        if found is None:
            missed += 1
        else:
            delays.append(found)
    r = delay_summary(trials, delays, missed, before)
    return {"within_5": sum(v for k, v in r["histogram"].items() if k <= 5), "before": before,
            "histogram": r["histogram"], "detected": r["detected"]}


def precision(seed: int = 7) -> list:
    rng = np.random.default_rng(seed)
    rows = []
    for sig in (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2, 1.5):
        p = {}
        for j in (trl.J1_BASE, trl.J1_STEP):
            x = j * (1 + sig / 100 * rng.standard_normal(4000))
            p[j] = {"j1": x, "se": np.full(4000, j * sig / 100), "rec": np.arange(4000)}
        rows.append({"scatter_pct": sig, "within_5": trl.detection(p, 400, 1, TrendConfig())["within_5"],
                     "within_5_gaussian_z": trl.detection(p, 400, 1, TrendConfig(error_scale_prior_dof=None))["within_5"]})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.trend_design",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--targets-pools")
    ap.add_argument("--work")
    ap.add_argument("--models", default=",".join(trl.MODELS))
    ap.add_argument("--pools-file", default="pools_v2_n40_s0.json")
    ap.add_argument("--config", action="append", default=None)
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--monitored", type=int, default=100_000)
    ap.add_argument("--precision", action="store_true")
    ap.add_argument("--by-kind", action="store_true", help="experiment: one tracker per window kind (module docstring)")
    a = ap.parse_args(argv)
    try:
        configs = [(c, parse_config(c)) for c in (a.config if a.config is not None else [""])]
    except (ValueError, TypeError) as exc:
        ap.error(f"--config: {exc}")
    tp = load_targets_pools(a.targets_pools) if a.targets_pools else None
    for text, cfg in configs:
        if tp is not None:
            print(json.dumps({"pool": "trend_targets", "config": text, **on_targets(tp, cfg, a.trials, a.monitored)}),
                  flush=True)
        if a.work:
            for m in a.models.split(","):
                f = Path(a.work) / m / a.pools_file
                if not f.exists():
                    print(f"{m}: no {f}", file=sys.stderr)
                    continue
                print(json.dumps({"pool": m, "config": text, **on_model(f, cfg, a.trials)}), flush=True)
                if a.by_kind:
                    print(json.dumps({"pool": m, "config": text, "by_kind": by_kind(f, cfg, a.trials)}), flush=True)
    if a.precision:
        for r in precision():
            print(json.dumps(r), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
