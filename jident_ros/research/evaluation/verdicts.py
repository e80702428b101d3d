"""Verdicts that never mislead (issue 12): the image method's margin threshold and the stress evaluation
of the publishing policy (:mod:`jident_ros.identify.verdict`).

* :func:`choose_image_threshold`: the smallest fused margin t such that, among the evaluation windows
  whose margin is >= t, the image method's class is wrong in <= 1 % -- with at least ``min_count``
  windows answered (below 100 windows "<= 1 %" cannot be told from 1 error).  None when no t achieves
  it: then the image method never publishes alone (``image_min_margin`` 0).
* :func:`image_evaluation_set`: the windows it is chosen on: the paper's grid (168 cases) noise-free,
  at 40 and 30 dB (two noise seeds each), without the noise-free eta_k = 0.025 pattern runs (the
  library itself: distance 0, margin infinite); the image method with the true K2's library width.
* :func:`stress_evaluation`: every window diagnosed by
  :class:`jident_ros.identify.diagnosis.Diagnoser` as the diagnostic node does, on the grid with
  K2 given right and x0.5, x0.8, x0.9, x1.1, x1.25, x2 (the paper mode's detector cuts a window at the same entry
  with a too-small K2 and never enters with x2 in this model, so the windows are diagnosed directly
  with the wrong ``backlash_width_m``), off-grid J1, clean and at 30 dB; plus random-data and 10-sample
  windows.  Per set: windows, J1 published, published J1 more than 10 % from the truth (target 0), the
  largest |error| published, statuses, and on-class windows flagged ambiguous (target <= 2 % at 30 dB).

Commands (print a table; numbers in the report and docs/interfaces.md come from them)::

    python -m jident_ros.research.evaluation.verdicts threshold     # image_min_margin for config/nodes.yaml
    python -m jident_ros.research.evaluation.verdicts stress        # the stress table

Plain numpy; never imports rclpy.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig, WindowInput, mirrored, rotation_sign
from jident_ros.identify.library import default_library_path, load_pattern_library
from jident_ros.identify.verdict import VerdictPolicy
from jident_ros.method.patterns import identify_window
from jident_ros.research.evaluation.robustness import OFFGRID_J1, noise_seed, offgrid_j1_cases
from jident_ros.sim import add_measurement_noise, paper_grid_cases, simulate_grid

#: Largest error rate of the image method's published class.
MAX_ERROR_RATE = 0.01
#: Fewest answered windows a threshold may rest on.
MIN_COUNT = 100
#: K2 factors of the stress set (1 = the true K2).
K2_FACTORS = (1.0, 0.5, 0.8, 0.9, 1.1, 1.25, 2.0)
#: A published J1 farther than this from the truth misleads (issue 12's target: none).
MISLEADING_REL_ERROR = 0.10


@dataclass(frozen=True)
class ThresholdChoice:
    """The image method's margin threshold and what it rests on.

    threshold : smallest margin meeting the target, or None (the image method never publishes alone)
    answered, wrong : windows with margin >= threshold, and how many of them the image method got wrong
    total, total_wrong : all windows of the evaluation set, and the wrong ones among them
    max_error_rate, min_count : the target
    """

    threshold: Optional[float]
    answered: int
    wrong: int
    total: int
    total_wrong: int
    max_error_rate: float = MAX_ERROR_RATE
    min_count: int = MIN_COUNT

    @property
    def parameter_value(self) -> float:
        """The value of the ``image_min_margin`` parameter: the threshold, 0 (never) without one."""
        return 0.0 if self.threshold is None else float(self.threshold)

    def describe(self) -> str:
        head = (f"evaluation set: {self.total} windows, image method wrong in {self.total_wrong} "
                f"({self.total_wrong / max(self.total, 1):.1%}); target: wrong in <= {self.max_error_rate:.0%} of "
                f">= {self.min_count} answered windows")
        if self.threshold is None:
            return head + "\nno margin threshold meets it: image_min_margin = 0 (the image method never publishes alone)"
        return head + (f"\nimage_min_margin = {self.threshold:.6g}: {self.answered} windows answered, "
                       f"{self.wrong} wrong ({self.wrong / self.answered:.2%})")


def choose_image_threshold(margins, correct, max_error_rate: float = MAX_ERROR_RATE,
                           min_count: int = MIN_COUNT) -> ThresholdChoice:
    """The smallest margin t with (wrong among margin >= t) <= max_error_rate x (count of margin >= t)
    and that count >= min_count; see the module docstring.  ``margins``: the image method's fused margin
    per window (inf allowed); ``correct``: whether its class was the true one."""
    m = np.asarray(margins, dtype=float)
    ok = np.asarray(correct, dtype=bool)
    if m.shape != ok.shape or m.ndim != 1:
        raise ValueError(f"margins and correct: expected two 1-D arrays of one length, got {m.shape}, {ok.shape}")
    if np.isnan(m).any():
        raise ValueError("margins: NaN")
    total, total_wrong = int(m.size), int((~ok).sum())
    order = np.argsort(-m, kind="stable")           # descending margin
    ms, wrong = m[order], np.cumsum(~ok[order])     # wrong[k]: wrong among the k+1 largest margins
    best = None
    for k in range(m.size):
        if k + 1 < m.size and ms[k + 1] == ms[k]:
            continue                                 # take ties together: threshold = this margin
        n = k + 1
        if n >= min_count and wrong[k] <= max_error_rate * n and np.isfinite(ms[k]):
            best = (float(ms[k]), n, int(wrong[k]))  # keep going: a smaller margin may still qualify
    if best is None:
        return ThresholdChoice(None, 0, 0, total, total_wrong, max_error_rate, min_count)
    return ThresholdChoice(best[0], best[1], best[2], total, total_wrong, max_error_rate, min_count)


@dataclass
class ImageSet:
    """The image method's answer on each evaluation window."""

    labels: list = field(default_factory=list)     # data set of each window
    margins: list = field(default_factory=list)
    correct: list = field(default_factory=list)


def image_evaluation_set(system, method, library, p: float = 2.0, snr_db: Sequence[float] = (40.0, 30.0),
                         seeds: Sequence[int] = (1, 2), log=None) -> ImageSet:
    """The image method's fused class and margin on the grid (module docstring)."""
    cases = paper_grid_cases(system)
    clean = simulate_grid(system, cases)
    classes = [float(c) for c in library.classes_kgm2]
    pattern_eta = system.grid.pattern_consistency_pa_sn
    out = ImageSet()
    sets = [("noise-free", clean)] + [(f"SNR {s:g} dB seed {sd}", add_measurement_noise(clean, s, noise_seed(sd, s)))
                                      for s in snr_db for sd in seeds]
    for label, ws in sets:
        for i, c in enumerate(ws.cases):
            if label == "noise-free" and c.consistency_pa_sn == pattern_eta:
                continue
            idn = identify_window(ws.case(i), ws.entry_index, c.backlash_width_m, library, method, p)
            out.labels.append(label)
            out.margins.append(idn.fused_margin)
            out.correct.append(classes[idn.fused_class_index] == c.inertia_kgm2)
        if log:
            log(f"image method on {label}: {len(out.margins)} windows so far")
    return out


# --------------------------------------------------------------------------- stress


@dataclass
class StressRow:
    """The policy on one set of windows."""

    label: str
    windows: int = 0
    published: int = 0
    misleading: int = 0                     # published J1 > MISLEADING_REL_ERROR from the truth
    max_abs_error: float = float("nan")     # largest |relative error| of a published J1
    class_wrong: int = 0                    # a class named (published) that is not the true class (on-class truth)
    on_class: int = 0                       # windows whose true J1 is a class
    ambiguous_on_class: int = 0
    statuses: Counter = field(default_factory=Counter)
    levels: Counter = field(default_factory=Counter)
    gap_only_max_abs_error: float = float("nan")   # the gap fit's largest |error| whether published or not


def _diagnose_set(label, ws, k2_factor, system, method, library, policy, p, truth=True) -> StressRow:
    row = StressRow(label)
    classes = [float(c) for c in library.classes_kgm2]
    errs, gap_errs = [], []
    diagnoser = Diagnoser(system, method, DiagnosisConfig(p), policy, library)
    for i, c in enumerate(ws.cases):
        d = diagnoser.diagnose(WindowInput(ws.case(i), ws.entry_index, c.backlash_width_m * k2_factor,
                                           system.load.wheel_radius_m, ws.sample_period_s))
        row.windows += 1
        row.statuses[d.status] += 1
        row.levels[d.level_name] += 1
        on_class = c.inertia_kgm2 in classes
        row.on_class += on_class
        row.ambiguous_on_class += on_class and d.status == "ambiguous"
        if d.gap is not None:
            gap_errs.append(abs(d.gap.inertia_kgm2 - c.inertia_kgm2) / c.inertia_kgm2)
        if d.inertia_kgm2 is not None:
            row.published += 1
            e = abs(d.inertia_kgm2 - c.inertia_kgm2) / c.inertia_kgm2
            errs.append(e)
            row.misleading += e > MISLEADING_REL_ERROR
            if on_class and d.class_kgm2 is not None and d.class_kgm2 != c.inertia_kgm2:
                row.class_wrong += 1
    row.max_abs_error = max(errs) if errs else float("nan")
    row.gap_only_max_abs_error = max(gap_errs) if gap_errs else float("nan")
    return row


def _junk_row(label, make, n, system, method, library, policy, p, seed=0) -> StressRow:
    """Windows that carry no backlash entry: anything published misleads."""
    rng = np.random.default_rng(seed)
    row = StressRow(label)
    r, ts = system.load.wheel_radius_m, system.sampling.sample_period_s
    diagnoser = Diagnoser(system, method, DiagnosisConfig(p), policy, library)
    for k in range(n):
        data, entry = make(rng, k)
        d = diagnoser.diagnose(WindowInput(data, entry, 0.005, r, ts))
        row.windows += 1
        row.statuses[d.status] += 1
        row.levels[d.level_name] += 1
        if d.inertia_kgm2 is not None:
            row.published += 1
            row.misleading += 1
    return row


CHANNELS = ("t", "alpha1", "alpha2", "omega2", "a1", "m_el", "omega1", "a2", "v2")


def random_window(rng, k, n: int = 2048):
    """Random data in every channel (angle scale alternating 1e-3 and 1 rad, so some windows start
    inside the zone and some outside), entry at 48."""
    scale = 1e-3 if k % 2 == 0 else 1.0
    w = {c: rng.standard_normal(n) * (scale if c.startswith("alpha") else 10.0) for c in CHANNELS}
    w["t"] = np.arange(n) * 5e-4
    return w, 48


def stress_evaluation(system, method, library, policy: Optional[VerdictPolicy] = None, p: float = 2.0,
                      k2_factors: Sequence[float] = K2_FACTORS, snr_db: Sequence = (None, 30.0), seed: int = 1,
                      offgrid: bool = True, junk: int = 20, log=None) -> list:
    """The rows of the stress table (module docstring)."""
    policy = VerdictPolicy() if policy is None else policy
    clean = simulate_grid(system, paper_grid_cases(system))
    rows = []
    for snr in snr_db:
        ws = clean if snr is None else add_measurement_noise(clean, snr, noise_seed(seed, snr))
        tag = "clean" if snr is None else f"{snr:g} dB"
        for f in k2_factors:
            t0 = time.perf_counter()
            rows.append(_diagnose_set(f"grid, K2 x{f:g}, {tag}", ws, f, system, method, library, policy, p))
            if log:
                log(f"{rows[-1].label}: {time.perf_counter() - t0:.1f} s")
    if offgrid:
        og = simulate_grid(system, offgrid_j1_cases(system, OFFGRID_J1))
        for snr in snr_db:
            ws = og if snr is None else add_measurement_noise(og, snr, noise_seed(seed, snr, 7))
            tag = "clean" if snr is None else f"{snr:g} dB"
            rows.append(_diagnose_set(f"off-grid J1, K2 x1, {tag}", ws, 1.0, system, method, library, policy, p))
    if junk:
        rows.append(_junk_row("random data", random_window, junk, system, method, library, policy, p))
        rows.append(_junk_row("10-sample windows", lambda rng, k: ({c: v[:10] for c, v in clean.case(k).items()}, 4),
                              junk, system, method, library, policy, p))
    return rows


def render_stress(rows: Sequence[StressRow]) -> str:
    """The stress table in Markdown."""
    head = ("| set | windows | J1 published | published > 10 % off | max |error| published | class wrong | "
            "on-class ambiguous | statuses | levels | gap fit max |error| (published or not) |")
    lines = [head, "|" + "---|" * 10]

    def pct(x):
        return "–" if not np.isfinite(x) else f"{x * 100:.3g} %"
    for r in rows:
        amb = f"{r.ambiguous_on_class}/{r.on_class} ({r.ambiguous_on_class / r.on_class:.1%})" if r.on_class else "–"
        st = ", ".join(f"{k} {v}" for k, v in sorted(r.statuses.items()))
        lv = ", ".join(f"{k} {v}" for k, v in sorted(r.levels.items()))
        lines.append(f"| {r.label} | {r.windows} | {r.published} | {r.misleading} | {pct(r.max_abs_error)} | "
                     f"{r.class_wrong} | {amb} | {st} | {lv} | {pct(r.gap_only_max_abs_error)} |")
    return "\n".join(lines)


def _load(p: float):
    system, method = load_system_config(), load_method_config()
    library, err = load_pattern_library(default_library_path(system, method), system, method, True,
                                        log=lambda t: print(t, file=sys.stderr))
    if err:
        raise SystemExit(f"verdicts: {err}")
    library.p_index(p)
    return system, method, library


def reverse_evaluation(system, method, library, p: float = 2.0) -> dict:
    """The image method on reversed windows (every channel but t mirrored) of the grid, noise-free: its fused class
    on the forward window, on the mirrored window as it is (what it did before the mirror), and on the mirrored
    window through diagnosis.rotation_sign + mirrored (what the Diagnoser does now), and the margins."""
    cases = paper_grid_cases(system)
    ws = simulate_grid(system, cases)
    out = {"windows": 0, "forward_correct": 0, "reverse_raw_correct": 0, "reverse_raw_same": 0,
           "reverse_mirrored_same": 0, "reverse_detected": 0, "reverse_raw_margin_min": math.inf}
    classes = [float(c) for c in library.classes_kgm2]
    for i, c in enumerate(ws.cases):
        fwd = ws.case(i)
        rev = mirrored(fwd)
        a = identify_window(fwd, ws.entry_index, c.backlash_width_m, library, method, p)
        b = identify_window(rev, ws.entry_index, c.backlash_width_m, library, method, p)
        sign = rotation_sign(rev, ws.entry_index)
        m = identify_window(mirrored(rev) if sign < 0 else rev, ws.entry_index, c.backlash_width_m, library, method, p)
        out["windows"] += 1
        out["forward_correct"] += classes[a.fused_class_index] == c.inertia_kgm2
        out["reverse_raw_correct"] += classes[b.fused_class_index] == c.inertia_kgm2
        out["reverse_raw_same"] += b.fused_class_index == a.fused_class_index
        out["reverse_mirrored_same"] += (m.fused_class_index == a.fused_class_index and m.fused_margin == a.fused_margin)
        out["reverse_detected"] += sign < 0
        out["reverse_raw_margin_min"] = min(out["reverse_raw_margin_min"], float(b.fused_margin))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m jident_ros.research.evaluation.verdicts", description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("threshold", "stress", "reverse"),
                    help="threshold: image_min_margin; stress: the table; reverse: the image method on mirrored windows")
    ap.add_argument("--p", type=float, default=2.0, help="KHM exponent (default 2, the diagnostic node's p)")
    ap.add_argument("--image-min-margin", type=float,
                    help="stress: the policy's image_min_margin (default: VerdictPolicy's default)")
    ap.add_argument("--policy", action="append", default=[], metavar="FIELD=VALUE",
                    help="stress: another VerdictPolicy field, e.g. torque_offset_rel_base=0 (repeatable)")
    args = ap.parse_args(argv)
    overrides = {}
    names = {f.name: f for f in dataclasses.fields(VerdictPolicy)}
    for item in args.policy:
        name, _, value = item.partition("=")
        if name not in names or not value:
            ap.error(f"argument --policy: not FIELD=VALUE with a VerdictPolicy field: {item!r}")
        try:
            overrides[name] = value.lower() in ("1", "true") if isinstance(names[name].default, bool) else float(value)
        except ValueError:
            ap.error(f"argument --policy: {name} must be a number, got {value!r}")
    t0 = time.perf_counter()
    system, method, library = _load(args.p)
    log = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    if args.what == "threshold":
        s = image_evaluation_set(system, method, library, args.p, log=log)
        choice = choose_image_threshold(s.margins, s.correct)
        print(choice.describe())
        print(f"image_min_margin: {choice.parameter_value!r}   "
              f"# jident_ros/parameters.py DIAGNOSTIC, config/nodes.yaml, identify/verdict.py VerdictPolicy")
    elif args.what == "reverse":
        print(json.dumps(reverse_evaluation(system, method, library, args.p)))
    else:
        if args.image_min_margin is not None:
            overrides["image_min_margin"] = args.image_min_margin
        policy = VerdictPolicy(**overrides)
        for name, what in policy.problems():
            ap.error(f"argument --policy: {name} must be {what}, got {getattr(policy, name)!r}")
        rows = stress_evaluation(system, method, library, policy, args.p, log=log)
        print(f"policy: {policy}")
        print(render_stress(rows))
    print(f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
