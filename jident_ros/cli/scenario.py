"""``jident simulate --scenario wear``: a long simulated run written as a recording.

the ``drive/signals`` layout the simulator node publishes (50-sample std_msgs/Float64MultiArray batches,
with ``drive/true_inertia``, ``drive/backlash_width`` and a ``drive/case`` row before each event).  The drive
clock jumps between events: event i's stream starts ``gap_samples + 48`` samples before its entry time
``scenario.entry_times_s[i]`` (a steady stretch), runs 2000 samples from the entry and stops; the next
event's stream starts an interval later.  ``jident diagnose`` restarts the detector's history at such a
jump (:class:`jident_ros.bag.drive_replay.DriveReplay`, ``clock_jumps``), so no window is lost and no entry is
faked.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from jident_ros.bag.writer import BagWriter
from jident_ros.cli.argtypes import count_arg as _count
from jident_ros.cli.argtypes import finite_float_arg as _finite_float
from jident_ros.cli.offline import OfflineError, multiarray_message
from jident_ros.config import load_system_config
from jident_ros.sim import PAPER_SIGNALS, add_measurement_noise, simulate_grid
from jident_ros.sim.scenarios import SCENARIOS, Scenario, wear_scenario
from jident_ros.stream.detector import embed_windows
from jident_ros.stream.layout import CASE_LABEL, DEFAULT_CHANNELS

#: Channels add_measurement_noise perturbs by default (the angles are left to the encoder model).
NOISY_CHANNELS = PAPER_SIGNALS + ("omega2",)


def write_scenario_recording(out, system, scenario: Scenario, *, snr_db: Optional[float] = None, seed: int = 0,
                             gap_samples: int = 100, batch_size: int = 50, namespace: str = "",
                             chunk_cases: int = 200, progress: Optional[Callable[[int], Any]] = None,
                             tail_samples: int = 32) -> Path:
    """Simulate ``scenario`` (``chunk_cases`` events at a time) and write it as an MCAP bag directory
    ``out`` in the simulator node's topics (see the module docstring).  ``snr_db``: white noise as
    ``jident simulate --snr-db`` (add_measurement_noise, per event, seed ``seed`` + chunk).
    ``progress(n)`` is called after every n events written.  ``tail_samples`` steady samples follow each
    event's window (its last sample held, both angles advanced at the motor's last speed; noise as the steady
    stretch before it): the flank detector refines the entry by up to 16 samples and needs them to close
    its window before the clock jumps to the next event."""
    if int(gap_samples) != gap_samples or gap_samples < 0:
        raise ValueError(f"gap_samples: must be an integer >= 0, got {gap_samples!r}")
    if int(tail_samples) != tail_samples or tail_samples < 0:
        raise ValueError(f"tail_samples: must be an integer >= 0, got {tail_samples!r}")
    if int(batch_size) != batch_size or batch_size < 1:
        raise ValueError(f"batch_size: must be an integer >= 1, got {batch_size!r}")
    out = Path(out)
    ns = namespace.rstrip("/")

    def topic(rel):
        return f"{ns}/{rel}"
    case_cols = CASE_LABEL.split(",")
    with BagWriter(out, flush_every_s=None) as bag:
        bag.add_topic(topic("drive/signals"), "std_msgs/msg/Float64MultiArray")
        for rel in ("drive/true_inertia", "drive/backlash_width"):
            bag.add_topic(topic(rel), "std_msgs/msg/Float64", qos="transient_local")
        bag.add_topic(topic("drive/case"), "std_msgs/msg/Float64MultiArray", qos="transient_local")
        n = len(scenario)
        for c0 in range(0, n, chunk_cases):
            cases = scenario.cases[c0:c0 + chunk_cases]
            clean = simulate_grid(system, cases)
            stream, entry_rows = embed_windows(clean, int(gap_samples), 0.0, DEFAULT_CHANNELS)
            ts = clean.sample_period_s
            per = int(gap_samples) + len(clean.t)
            if snr_db is not None:
                # the window as `jident simulate --snr-db` (add_measurement_noise); the steady stretch before
                # it gets noise of the same power (the angles stay clean: encoders, as add_measurement_noise)
                rng = np.random.default_rng([int(seed), c0])
                noisy = add_measurement_noise(clean, snr_db, int(rng.integers(2 ** 31)))
                lead = np.zeros(per, dtype=bool)
                lead[:int(gap_samples)] = True
                for j, name in enumerate(DEFAULT_CHANNELS):
                    if name not in NOISY_CHANNELS:
                        continue
                    x = clean.signals[name]
                    sd = np.sqrt(np.mean(x * x, axis=1) / 10.0 ** (snr_db / 10.0))
                    block = stream[:, j].reshape(len(cases), per)
                    block[:, ~lead] = noisy.signals[name]
                    block[:, lead] += sd[:, None] * rng.standard_normal((len(cases), int(gap_samples)))
            n_tail = int(tail_samples)
            i1, i2 = DEFAULT_CHANNELS.index("alpha1"), DEFAULT_CHANNELS.index("alpha2")
            w1 = DEFAULT_CHANNELS.index("omega1")
            steps = np.arange(1, n_tail + 1) * ts
            for i, c in enumerate(cases):
                rows = stream[i * per:(i + 1) * per]
                if n_tail:
                    tail = np.repeat(rows[-1:], n_tail, axis=0)
                    tail[:, i1] += rows[-1, w1] * steps
                    tail[:, i2] += rows[-1, w1] * steps     # one speed: the clutch stays where it is
                    if snr_db is not None:
                        for j, name in enumerate(DEFAULT_CHANNELS):
                            if name in NOISY_CHANNELS:
                                x = clean.signals[name][i]
                                tail[:, j] = x[-1] + np.sqrt(np.mean(x * x) / 10.0 ** (snr_db / 10.0)) * \
                                    rng.standard_normal(n_tail)
                    rows = np.vstack([rows, tail])
                t_entry = float(scenario.entry_times_s[c0 + i])
                rows[:, 0] = t_entry + (np.arange(per + n_tail) - (entry_rows[i] - i * per)) * ts
                t_case = int(round((rows[0, 0] - ts / 2) * 1e9))
                bag.write(topic("drive/true_inertia"), {"data": c.inertia_kgm2}, t_case)
                bag.write(topic("drive/backlash_width"), {"data": c.backlash_width_m}, t_case)
                row = np.array([[c0 + i, c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn, t_entry]])
                bag.write(topic("drive/case"), multiarray_message(row, case_cols), t_case)
                for s in range(0, per + n_tail, int(batch_size)):
                    b = rows[s:s + int(batch_size)]
                    bag.write(topic("drive/signals"), multiarray_message(b, DEFAULT_CHANNELS),
                              int(round(b[-1, 0] * 1e9)))
            if progress is not None:
                progress(len(cases))
    return out


def write_signals_bag(path, data: np.ndarray, channels, namespace: str = "", batch_size: int = 50,
                      log_offset_s: float = 0.0) -> Path:
    """A bag directory ``path`` holding only ``<namespace>/drive/signals``: ``data`` ((n, c) samples, columns
    ``channels`` with ``t`` among them) in batches of ``batch_size``, each logged at its last sample's time
    plus ``log_offset_s`` (what a drive records: no truth topics; an offset: a recorder's clock that is not
    the drive's, e.g. across a drive restart)."""
    path = Path(path)
    ti = list(channels).index("t")
    topic = f"{namespace.rstrip('/')}/drive/signals"
    with BagWriter(path, flush_every_s=None) as bag:
        bag.add_topic(topic, "std_msgs/msg/Float64MultiArray")
        for s0 in range(0, len(data), int(batch_size)):
            b = data[s0:s0 + int(batch_size)]
            bag.write(topic, multiarray_message(b, channels), int(round((b[-1, ti] + log_offset_s) * 1e9)))
    return path


def add_scenario_arguments(s) -> None:
    """The ``jident simulate --scenario ...`` options (added to the simulate subparser)."""
    s.add_argument("--scenario", choices=SCENARIOS,
                   help="a long run written as a recording (--out DIR): 'wear' = the backlash width grows "
                        "linearly and J1 steps once (sim/scenarios.py)")
    s.add_argument("--windows", type=_count("--windows", 1), default=40,
                   help="scenario: number of backlash entries (default 40)")
    s.add_argument("--interval-s", type=_finite_float("--interval-s"), default=3600.0,
                   help="scenario: drive time between entries, s (default 3600)")
    s.add_argument("--width-start-m", type=_finite_float("--width-start-m"), default=0.0025,
                   help="scenario: K2 at the first entry, m (default 0.0025)")
    s.add_argument("--width-end-m", type=_finite_float("--width-end-m"),
                   help="scenario: K2 at the last entry, m (default 0.0035)")
    s.add_argument("--width-growth-m-per-day", type=_finite_float("--width-growth-m-per-day", False),
                   help="scenario: wear rate instead of --width-end-m, m/day")
    s.add_argument("--j1-step-at", type=_count("--j1-step-at", 0),
                   help="scenario: first entry (0-based) with the stepped J1 (default: half-way)")
    s.add_argument("--j1-step-pct", type=_finite_float("--j1-step-pct", False), default=2.5,
                   help="scenario: J1 step, %% (default 2.5; 0: no step)")
    s.add_argument("--gap-samples", type=_count("--gap-samples", 0), default=100,
                   help="scenario: steady samples before each entry's 48 pre-entry samples (default 100)")
    s.add_argument("--namespace", default="", help="scenario: the drive's namespace (e.g. /drive_07)")


def cmd_simulate_scenario(args) -> int:
    """``jident simulate --scenario wear --windows N --interval-s S --out REC``."""
    if not args.out:
        raise OfflineError("--out: the scenario needs a bag directory to write")
    if args.grid or args.backlash is not None or args.plot:
        raise OfflineError("--scenario: drop --grid/--backlash/--plot (the scenario sets K2 per entry)")
    if args.encoder_counts is not None:
        raise OfflineError("--encoder-counts: not supported with --scenario (raw encoders, one bag per entry: "
                           "python -m jident_ros.research.evaluation.raw_scenario)")
    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise OfflineError(f"--out {out}: already exists and is not an empty directory")
    system = load_system_config(args.config)
    n = args.windows
    step_at = args.j1_step_at if args.j1_step_at is not None else (n // 2 if args.j1_step_pct else None)
    if step_at is not None and step_at >= n:
        raise OfflineError(f"--j1-step-at: must be < --windows ({n}), got {step_at}")
    if args.j1_step_pct == 0:
        step_at = None
    sc = wear_scenario(system, n, args.interval_s, args.width_start_m, args.width_end_m, args.width_growth_m_per_day,
                       args.j1, step_at, args.j1_step_pct, args.eta)
    bar = None
    if not args.quiet:
        from tqdm import tqdm
        bar = tqdm(total=n, desc="simulating + writing", unit="window", file=sys.stderr, leave=False)
    t0 = time.perf_counter()
    try:
        write_scenario_recording(out, system, sc, snr_db=args.snr_db, seed=args.seed, namespace=args.namespace,
                                 gap_samples=args.gap_samples, progress=None if bar is None else bar.update)
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        w = sc.true_width_m
        step = ("no J1 step" if sc.j1_step_at_window is None else
                f"J1 {sc.cases[0].inertia_kgm2:g} -> {sc.cases[sc.j1_step_at_window].inertia_kgm2:.5g} kg m^2 at "
                f"entry {sc.j1_step_at_window} (t = {sc.j1_step_time_s:.0f} s)")
        print(f"wear scenario: {n} entries every {args.interval_s:g} s (t = {sc.entry_times_s[0]:.0f} .. "
              f"{sc.entry_times_s[-1]:.0f} s), K2 {w[0] * 1e3:.4g} -> {w[-1] * 1e3:.4g} mm "
              f"({sc.wear_rate_m_per_day * 1e3:.4g} mm/day), {step}"
              + ("" if args.snr_db is None else f", {args.snr_db:g} dB noise")
              + f"; written in {time.perf_counter() - t0:.1f} s -> {out}")
    return 0


__all__ = ["NOISY_CHANNELS", "add_scenario_arguments", "cmd_simulate_scenario", "write_scenario_recording",
           "write_signals_bag"]
