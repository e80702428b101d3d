"""``jident``: the offline command line (no ROS needed).

jident simulate --j1 1.073 --backlash 0.005 --eta 0.025 --out case.npz --plot case.png
jident simulate --grid --out grid.npz
jident diagnose out/run1 --json out/run1.json
jident simulate --scenario wear --windows 40 --snr-db 30 --out out/wear && jident trend out/wear --out out/trend
jident info
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from jident_ros import __version__
from jident_ros.parameters import (  # light: dataclasses only
    DIAGNOSTIC_PARAMS,
    GAP_METHODS,
    POLICY_CLI_FLAGS,
    WINDOWING_PARAMS,
    cli_help,
)

# Every subcommand imports what it runs inside its cmd_* function (issue 23): `jident --help` and
# `jident simulate` do not pay for scipy.stats, the offline diagnosis, the bag layer or rclpy
# (test_cli_imports.py checks which modules each one loads).

#: The one list of gap methods (jident_ros/parameters.py, light: `jident --help` does not import the method)
CLI_GAP_METHODS = GAP_METHODS
#: method.pipeline.VARIANTS, spelled out so that `jident --help` does not import the method (test_cli_imports)
CLI_VARIANTS = ("paper", "load_scaled", "sensor_matched")
#: `jident trend`'s one-line help in the command list (cli.trend.add_trend_parser registers the same text;
#: test_cli_imports compares the two listings)
TREND_HELP = ("trend of J1 and the backlash width over many recordings (diagnose every window, time order, change "
              "detection, wear rate): trend.csv, trend.png, a summary")


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage dump
        raise CliError(message)


def _positive(name, signed: bool = False):
    """A finite number > 0 (``signed``: any finite non-zero number)."""
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(v) or v == 0 or (v < 0 and not signed):
            raise argparse.ArgumentTypeError(f"{name} must be {'a non-zero number' if signed else '> 0'}, got {text}")
        return v
    return parse


def _progress(total, desc, enabled):
    """A tqdm progress callback (k, n) on stderr, or None when disabled."""
    if not enabled:
        return None, (lambda: None)
    from tqdm import tqdm
    bar = tqdm(total=total, desc=desc, unit="sample", file=sys.stderr, leave=False)

    def update(k, n):
        bar.update(1)
    return update, bar.close


def cmd_simulate(args) -> int:
    if getattr(args, "scenario", None):     # parsed only when given (main: the scenario options live in cli.scenario)
        from jident_ros.cli.scenario import cmd_simulate_scenario
        return cmd_simulate_scenario(args)
    from jident_ros.config import load_system_config
    from jident_ros.sim import Case, add_measurement_noise, paper_grid_cases, quantise_encoders, simulate_grid
    cfg = load_system_config(args.config)
    if args.grid:
        if any(v is not None for v in (args.j1, args.backlash, args.eta)):
            raise CliError("--grid simulates the whole K1 x K2 x eta_k grid; drop --j1/--backlash/--eta")
        cases = paper_grid_cases(cfg)
    else:
        j1 = cfg.motor.nominal_inertia_kgm2 if args.j1 is None else args.j1
        width = cfg.grid.backlash_widths_m[0] if args.backlash is None else args.backlash
        eta = cfg.grid.pattern_consistency_pa_sn if args.eta is None else args.eta
        cases = [Case(j1, width, eta)]
    show = not args.quiet and (args.grid or len(cases) > 1)
    update, close = _progress(cfg.sampling.window_length, f"simulating {len(cases)} cases", show)
    t0 = time.perf_counter()
    try:
        ws = simulate_grid(cfg, cases, progress=update)
    finally:
        close()
    elapsed = time.perf_counter() - t0
    if args.snr_db is not None:
        ws = add_measurement_noise(ws, args.snr_db, args.seed)
    if args.encoder_counts is not None:
        ws = quantise_encoders(ws, args.encoder_counts)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        ws.save_npz(args.out)
    if args.plot:
        from jident_ros.research.evaluation.plotting import plot_case
        plot_case(ws, 0, args.plot)
    if not args.quiet:
        print(f"simulated {len(cases)} case(s), {cfg.sampling.window_length} samples each "
              f"(Ts = {ws.sample_period_s * 1e3:g} ms) in {elapsed:.2f} s")
        if len(cases) == 1:
            c, s = cases[0], ws.case(0)
            gap = (s["clutch_torque"][ws.entry_index:] > 0).argmax()
            print(f"  J1 = {c.inertia_kgm2:g} kg m^2, backlash = {c.backlash_width_m:g} m, "
                  f"eta_k = {c.consistency_pa_sn:g} Pa s^n: slip {ws.initial_slip[0] * 100:.2f} %, "
                  f"load {s['clutch_torque'][0]:.1f} N m, inside the zone for {gap} samples "
                  f"({gap * ws.sample_period_s * 1e3:.1f} ms)")
        for what, p in (("windows", args.out), ("plot", args.plot)):
            if p:
                print(f"  {what}: {p}")
    return 0


def cmd_info(args) -> int:
    """Base values and the loaded steady state at every eta_k (docs/model.md)."""
    import numpy as np

    from jident_ros.cli.drive_file import read_drive_file
    from jident_ros.cli.drive_info import identification_lines, library_line, model_problem
    from jident_ros.config import load_method_config, load_system_config
    from jident_ros.identify.library import default_library_path
    from jident_ros.sim import Case, steady_state
    from jident_ros.sim.model import Model
    from jident_ros.sim.motor import breakdown_slip, steady_state_phasors
    cfg = load_system_config(args.config)
    m, b = cfg.motor, cfg.motor.base
    s_bd = breakdown_slip(m)
    print("Per-unit base values (derived from J1 nominal, T_m, pole pairs, f):")
    print(f"  omega_b = {b.electrical_speed_rad_s:.2f} rad/s, Omega_b = {b.mechanical_speed_rad_s:.2f} rad/s "
          f"({b.mechanical_speed_rad_s * 30 / math.pi:.0f} rpm synchronous)")
    print(f"  S_b = J1 Omega_b^2 / T_m = {b.power_va / 1e3:.2f} kVA, M_b = {b.torque_nm:.1f} N m, "
          f"U_b = {b.voltage_peak_v:.1f} V peak, I_b = {b.current_peak_a:.1f} A peak, Z_b = {b.impedance_ohm:.3f} ohm")
    print(f"  w = x_s x_w - x_m^2 = {m.sigma_determinant_pu:.4f}; pull-out torque "
          f"{steady_state_phasors(m, s_bd)['torque_pu']:.3f} p.u. at slip {s_bd * 100:.1f} %")
    declared = read_drive_file(args.config)
    for line in identification_lines(cfg, declared.diagnostic, declared.windowing):
        print(line)
    if declared.lines():
        print(f"Declared in {declared.path} (jident diagnose and trend use these; the nodes get them with "
              f"--params-file; a flag overrides them):")
        for line in declared.lines():
            print(line)
    problem = model_problem(cfg)
    method = load_method_config()
    lib = default_library_path(cfg, method)
    print(library_line(cfg, method, lib, lib.exists(), problem))
    if problem:
        print(f"Loaded steady state: not available: {problem}")
        return 0
    cases = [Case(m.nominal_inertia_kgm2, cfg.grid.backlash_widths_m[0], e)
             for e in cfg.grid.consistency_indices_pa_sn]
    y, slip = steady_state(cfg, cases, 0.0)
    model = Model(cfg)
    v2 = y[9]
    eta = np.array([c.consistency_pa_sn for c in cases])
    film = model.film_force(v2, eta)
    r = cfg.load.wheel_radius_m
    print("Loaded steady state before the event:")
    print("  eta_k [Pa s^n] | slip [%] | speed [rpm] | v2 [m/s] | load [N m] | load [p.u.] | film share [%] | P_mech [kW]")
    for i, c in enumerate(cases):
        load = r * (cfg.load.process_force_n + film[i])
        print(f"  {c.consistency_pa_sn:14g} | {slip[i] * 100:8.3f} | {y[4, i] * 30 / math.pi:11.1f} | "
              f"{v2[i]:8.3f} | {load:10.2f} | {load / b.torque_nm:11.3f} | "
              f"{100 * film[i] / (cfg.load.process_force_n + film[i]):14.3g} | {load * y[4, i] / 1e3:11.2f}")
    return 0


def _method_config(args):
    from jident_ros.config import load_method_config
    m = load_method_config(getattr(args, "method_config", None))
    if getattr(args, "p", None):
        m = m.replace(p_values=tuple(args.p))
    if getattr(args, "variant", None):
        m = m.replace(variant=args.variant)
    return m


def cmd_build_patterns(args) -> int:
    """Build the pattern library from simulations (default) or from calibration recordings with known J1."""
    if not args.from_recordings and (args.label or args.backlash_width_m is not None):
        raise CliError("--label and --backlash-width-m need --from-recordings")
    from jident_ros.cli.calibration import library_from_labelled_windows, parse_labels, pattern_grid, read_recordings
    from jident_ros.config import load_system_config
    from jident_ros.identify.library import default_library_path
    from jident_ros.method.patterns import PatternLibrary
    system = load_system_config(args.config)
    method = _method_config(args)
    out = Path(args.out) if args.out else default_library_path(system, method)
    t0 = time.perf_counter()
    if args.from_recordings:
        labels = parse_labels(args.label or [], args.from_recordings)
        log = (lambda text: None) if args.quiet else (
            lambda text: print(f"jident build-patterns: {text}", file=sys.stderr, flush=True))
        windows, recordings = read_recordings(args.from_recordings, system, labels=labels,
                                              backlash_width_m=args.backlash_width_m, log=log)
        classes, widths, _, _ = pattern_grid(windows)   # checked before the features are computed
        log(f"{len(windows)} windows -> J1 classes {', '.join(f'{c:g}' for c in classes)} kg m^2 x "
            f"widths {', '.join(f'{w:g}' for w in widths)} m")
        update, close = _progress(len(method.wavelets), "pattern signals", not args.quiet)
        try:
            lib = library_from_labelled_windows(windows, system, method, progress=update, recordings=recordings)
        finally:
            close()
        n_windows = sum(map(sum, lib.metadata["pattern_window_counts"]))
        source = f"from {n_windows} windows of {len(args.from_recordings)} recording(s)"
    else:
        matched = method.variant == "sensor_matched"   # its progress counts noise seeds, not signals
        update, close = _progress(method.matched_seeds if matched else len(method.wavelets),
                                  "noise seeds" if matched else "pattern signals", not args.quiet)
        try:
            lib = PatternLibrary.build(system, method, progress=update)
        finally:
            close()
        source = "from simulations"
    lib.save(out)
    if not args.quiet:
        print(f"pattern library: {len(lib.classes_kgm2)} J1 classes x {len(lib.widths_m)} widths x "
              f"{len(lib.signals)} signals x p in {list(lib.p_values)} ({method.variant}) built {source} in "
              f"{time.perf_counter() - t0:.1f} s -> {out}")
    return 0


def cmd_evaluate(args) -> int:
    t_start = time.perf_counter()
    from concurrent.futures import ProcessPoolExecutor

    from jident_ros.config import load_system_config
    from jident_ros.research.evaluation.evaluate import VALIDITY_FILM_SHARES, run_evaluation
    from jident_ros.research.evaluation.report import render_markdown, write_figures, write_results_section
    from jident_ros.research.evaluation.report_robustness import write_robustness_figures
    from jident_ros.research.evaluation.robustness import run_robustness
    system = load_system_config(args.config)
    method = _method_config(args)
    log = (lambda *a: None) if args.quiet else (lambda msg: print(msg, flush=True))
    if args.full:
        args.validity_map = "full"
    readings = ("dyadic", "linear", "swt") if args.full else ()
    snr = () if args.quick else ((40.0, 30.0) if args.full else (30.0,))
    heavy = load_system_config("heavy_film")
    stress = None if heavy == system else heavy
    shares = VALIDITY_FILM_SHARES if not args.quick else (0.01,)
    if args.validity_map == "off":
        shares, stress = (), None
    # the robustness sweeps run in a process of their own beside the method part's pool, their gap-only sweeps in
    # another (jobs=2): the same numbers, less wall time (the 2-minute budget)
    rob_pool = ProcessPoolExecutor(max_workers=1)
    rob_future = rob_pool.submit(run_robustness, system, method, log=None if args.quiet else print, quick=args.quick,
                                 jobs=2)
    ev = run_evaluation(system, method, snr_db=snr, seeds=(2,) if snr == (30.0,) else (1, 2)[:len(snr)],
                        readings=readings, log=log,
                        # the 2-minute budget: load_scaled and sensor_matched on noise-free windows with --full only
                        variants=("paper", "load_scaled", "sensor_matched") if args.full else ("paper", "sensor_matched"),
                        matched_noise_free=args.full, library_cache=True,
                        film_shares=shares, stress_system=stress, full_map=args.validity_map == "full")
    ev.command = "jident evaluate" + (" --quick" if args.quick else "") + (" --full" if args.full else (
        f" --validity-map {args.validity_map}" if args.validity_map != "default" else "")) + (
        f" --config {args.config}" if args.config else "")
    figs = {} if args.no_figures else write_figures(ev, system, method, Path(args.results).parent / "figures")
    with rob_pool:
        rob = rob_future.result()
    rob.command = ev.command
    rfigs = {} if args.no_figures else write_robustness_figures(rob, Path(args.results).parent / "figures")
    total = time.perf_counter() - t_start
    md = render_markdown(ev, figs, robustness=(rob, rfigs), total_seconds=total)
    if args.results != "-":
        write_results_section(md, args.results)
        log(f"wrote the generated section of {args.results} (method part {ev.seconds:.0f} s, robustness "
            f"{rob.seconds:.0f} s, {total:.0f} s in all)")
    else:
        print(md)
    return 0


def cmd_diagnose(args) -> int:
    """Diagnose every backlash entry of a recording as the windowing + diagnostic nodes do (offline.py)."""
    from jident_ros.cli.drive_file import read_drive_file, resolve
    from jident_ros.cli.offline import (
        TABLE_HEADER,
        OfflineError,
        default_policy,
        diagnose_recording,
        diagnose_samples,
        format_window_line,
        summary_line,
        write_json,
    )
    from jident_ros.config import load_method_config, load_system_config
    from jident_ros.identify.library import load_pattern_library
    from jident_ros.stream.inputs import parse_map
    system = load_system_config(args.config)
    method = load_method_config(args.method_config)
    log = (lambda text: None) if args.quiet else (lambda text: print(f"jident diagnose: {text}", file=sys.stderr,
                                                                     flush=True))
    header_printed = False
    library = None
    if args.library and not args.no_image:
        # an explicitly given library must be usable: one line naming the file and the problem, exit 2
        library, error = load_pattern_library(Path(args.library).expanduser(), system, method,
                                              build_if_missing=False)
        if error:
            raise CliError(error)

    def show(window):
        nonlocal header_printed
        if not header_printed:
            print(TABLE_HEADER)
            header_printed = True
        print(format_window_line(window), flush=True)

    declared = read_drive_file(args.config)
    overrides = dict(declared.policy())
    overrides.update({k: getattr(args, k) for k in POLICY_CLI_FLAGS if getattr(args, k) is not None})
    detector = resolve(args.detector, declared, "detector")
    detector = None if detector == "auto" else detector
    gear_ratio = resolve(args.gear_ratio, declared, "gear_ratio")
    common = dict(system=system, method=method, p=resolve(args.p, declared, "p"), library=library,
                  library_path=args.library, gap_method=resolve(args.gap_method, declared, "gap_method"),
                  image_method=not args.no_image, log=log, on_window=show,
                  policy=default_policy(**overrides))
    samples = dict(gear_ratio=gear_ratio, motor_joint=resolve(args.motor_joint, declared, "motor_joint"),
                   load_joint=resolve(args.load_joint, declared, "load_joint"),
                   imu_axis=resolve(args.imu_axis, declared, "imu_axis"), topic=args.topic,
                   backlash_width_m=args.backlash_width_m, detector=detector or "flank")
    if str(args.recording).lower().endswith(".csv"):
        result = diagnose_samples(args.recording, maps=parse_map(args.map) if args.map else None, **common, **samples)
    else:
        try:
            result = diagnose_recording(args.recording, backlash_width_m=args.backlash_width_m,
                                        signals_topic=args.topic, detector=detector or "auto",
                                        gear_ratio=gear_ratio, **common)
        except OfflineError as exc:
            if "no drive/signals topic" not in str(exc):
                raise
            result = diagnose_samples(args.recording, **common, **samples)     # a bag of /joint_states
    if args.quiet:  # a recording read by salvaging it, dropped batches: said even when quiet
        for text in result.notes:
            print(f"jident diagnose: {text}", file=sys.stderr)
    if args.json:
        write_json(result, args.json)
    print(summary_line(result) + (f"; JSON: {args.json}" if args.json else ""))
    if not result.windows:
        print(f"jident diagnose: no {'window diagnosed from' if result.windows_lost else 'backlash entry found in'} "
              f"{result.signals_topic}"
              + (f": {result.no_entry_hint}" if result.no_entry_hint else ""), file=sys.stderr)
        return 1
    return 0


def build_parser(command: str | None = None, scenario: bool = True) -> argparse.ArgumentParser:
    """The ``jident`` parser.  ``command`` given: only that subcommand gets its arguments (the others, all of
    them for "", are listed with their one-line help), so that a run imports only what it needs; ``scenario=False`` leaves out
    ``simulate --scenario ...`` (its options come from cli.scenario, which imports the offline diagnosis)."""
    def wanted(name):
        return command is None or command == name

    p = _Parser(prog="jident", description="Identify the inertia J1 of an induction-motor drive "
                "from its backlash-zone transient (offline tools).")
    p.add_argument("--version", action="version", version=f"jident {__version__}")
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")
    s = sub.add_parser("simulate", help="simulate backlash-entry windows of the motor-load model")
    if wanted("simulate"):
        _simulate_arguments(s, scenario)
    b = sub.add_parser("build-patterns", help="build the pattern library (simulated eta_k = 0.025 runs, or "
                       "calibration recordings with known J1: --from-recordings)")
    if wanted("build-patterns"):
        _build_patterns_arguments(b)
    e = sub.add_parser("evaluate", help="evaluate the method on the full grid; regenerate docs/results.md's section")
    if wanted("evaluate"):
        _evaluate_arguments(e)
    g = sub.add_parser("diagnose", help="diagnose every backlash entry of a recording (drive/signals or "
                       "/joint_states bag, or CSV) as the "
                       "windowing and diagnostic nodes do, without ROS")
    if wanted("diagnose"):
        _diagnose_arguments(g)
    if wanted("trend"):
        from jident_ros.cli.trend import add_trend_parser
        add_trend_parser(sub)
    else:
        sub.add_parser("trend", help=TREND_HELP)
    sub.add_parser("salvage", help="recover every complete chunk of a truncated MCAP recording "
                   "(jident salvage <truncated.mcap> <out_dir>)", add_help=False)
    sub.add_parser("samples", help="one message per sample, stamped with drive time, for plotting in Foxglove "
                   "(jident samples <recording> <out_dir>)", add_help=False)
    sub.add_parser("demo", help="end-to-end demo: simulator, windowing and diagnostic nodes over DDS on a few "
                   "cases (jident demo --help)", add_help=False)
    i = sub.add_parser("info", help="print base values and the steady state of the model")
    if wanted("info"):
        i.add_argument("--config", help="system config YAML or drive profile (config/profiles/, e.g. heavy_film); "
                       "default config/system.yaml")
        i.set_defaults(func=cmd_info)
    return p


def _simulate_arguments(s, scenario: bool) -> None:
    s.add_argument("--j1", type=_positive("--j1"), help="J1 in kg m^2 (default: the nominal 1.16)")
    s.add_argument("--backlash", type=_positive("--backlash"),
                   help="backlash zone width at the wheel circumference, m (default: K2[0])")
    s.add_argument("--eta", type=_positive("--eta"), help="consistency index eta_k, Pa s^n (default 0.025)")
    s.add_argument("--grid", action="store_true", help="the paper's full grid (7 x 6 x 4 = 168 cases)")
    s.add_argument("--snr-db", type=float, help="add white measurement noise at this SNR (dB)")
    s.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    s.add_argument("--encoder-counts", type=int, help="quantise alpha1/alpha2 to this many counts per revolution")
    s.add_argument("--out", help="write the windows to this .npz file")
    s.add_argument("--plot", help="write a PNG of the five signals of the (first) case")
    s.add_argument("--config", help="system config YAML or drive profile (config/profiles/, e.g. heavy_film); default config/system.yaml")
    s.add_argument("--quiet", action="store_true")
    if scenario:
        from jident_ros.cli.scenario import add_scenario_arguments
        add_scenario_arguments(s)
    s.set_defaults(func=cmd_simulate)


def _build_patterns_arguments(b) -> None:
    b.add_argument("--from-recordings", nargs="+", metavar="REC",
                   help="build from these calibration recordings (bag directories or .mcap files; "
                   "docs/recording.md, 'Calibration recordings') instead of simulations")
    b.add_argument("--label", action="append", metavar="REC=J1",
                   help="J1 in kg m^2 of every window of recording REC (repeatable; default: the recording's "
                   "drive/case or drive/true_inertia messages)")
    b.add_argument("--backlash-width-m", type=_positive("--backlash-width-m"),
                   help="K2 of the recordings, m (default: their drive/backlash_width messages)")
    b.add_argument("--out", help="library file (default: ~/.cache/jident_ros/patterns-<hash>.npz)")
    b.add_argument("--p", type=_positive("--p"), action="append", help="KHM exponent p (repeatable; default: config)")
    b.add_argument("--variant", choices=CLI_VARIANTS, help="method variant (default: config; docs/method.md)")
    b.add_argument("--config", help="system config YAML or drive profile (config/profiles/, e.g. heavy_film); default config/system.yaml")
    b.add_argument("--method-config", help="method config YAML (default: config/method.yaml)")
    b.add_argument("--quiet", action="store_true")
    b.set_defaults(func=cmd_build_patterns)


def _evaluate_arguments(e) -> None:
    e.add_argument("--results", default="docs/results.md", help="results file to update ('-' prints)")
    e.add_argument("--quick", action="store_true", help="noise-free only, no reading comparison (smoke run)")
    e.add_argument("--no-figures", action="store_true")
    e.add_argument("--full", action="store_true", help="also the sweeps beyond the 2-minute budget: SNR 40 dB, the "
                   "'linear' and 'swt' readings of level 10 (~3 CPU minutes), the variant load_scaled, the variant "
                   "sensor_matched on noise-free windows, the width-error sweep and --validity-map full")
    e.add_argument("--validity-map", choices=("default", "full", "off"), default="default",
                   help="film-share validity map: default = noise-free at every share + the equal-load ablation on the "
                   "heavy-film profile, p = 2 and 3; full = every p, the ablation and the default sensor set at every share")
    e.add_argument("--p", type=_positive("--p"), action="append", help="KHM exponent p (repeatable; default: config)")
    e.add_argument("--config", help="system config YAML or drive profile (config/profiles/, e.g. heavy_film); default config/system.yaml")
    e.add_argument("--method-config", help="method config YAML (default: config/method.yaml)")
    e.add_argument("--quiet", action="store_true")
    e.set_defaults(func=cmd_evaluate)


def _diagnose_arguments(g) -> None:
    g.add_argument("recording", help="bag directory or .mcap file (a diagnostic node's record_dir, or a "
                   "`ros2 bag record` of joint_states [+ imu]), or a .csv file")
    # None: not given; then the drive file's (--config, cli/drive_file.py), else the node's default
    g.add_argument("--p", type=_positive("--p"), default=None, help=cli_help("p"))
    g.add_argument("--library", help="pattern library .npz (default: build-patterns' default path; built when missing)")
    g.add_argument("--gap-method", choices=CLI_GAP_METHODS, default=None,
                   help=cli_help("gap_method") + "; auto: the acceleration fit when a1 is recorded, else the angle "
                        "fit when alpha1 is, else speed")
    g.add_argument("--no-image", action="store_true", help="skip the paper's image method (gap estimate only)")
    g.add_argument("--backlash-width-m", type=_positive("--backlash-width-m"),
                   help="K2 of inequality (1), m, paper detector only (default for drive/signals recordings: their "
                        "drive/backlash_width, else 0.005)")
    g.add_argument("--detector", choices=("flank", "paper", "dynamics"),
                   help="entry detector: flank (no K2, raw encoder angles; the default for JointState bags and CSV), "
                        "paper (inequality 1 with K2, zone-centred angles; the default for drive/signals recordings "
                        "whose K2 is known: --backlash-width-m or their drive/backlash_width; flank otherwise) or dynamics "
                        "(no angles needed: the load-torque step from m_el and a1 or the alpha1 encoder)")
    g.add_argument("--gear-ratio", type=_positive("--gear-ratio", signed=True), default=None,
                   help=cli_help("gear_ratio", WINDOWING_PARAMS, "windowing"))
    g.add_argument("--motor-joint", default=None, help="JointState name of the motor joint (default motor)")
    g.add_argument("--load-joint", default=None, help="JointState name of the load joint (default load)")
    g.add_argument("--imu-axis", choices=("x", "y", "z"), default=None,
                   help="sensor_msgs/Imu linear_acceleration axis that is a1 (default x)")
    g.add_argument("--map", metavar="CH=COL[:SCALE],...",
                   help="CSV: other column names and scale factors to SI, e.g. alpha1=enc_motor:0.0000958738,t=time_ms:0.001")
    g.add_argument("--topic", help="the drive/signals or joint_states topic (default: the recording's only one)")
    for name in POLICY_CLI_FLAGS:   # the node's publishing policy (VerdictPolicy's fields but the input bounds)
        if isinstance(DIAGNOSTIC_PARAMS[name].default, bool):
            g.add_argument("--" + name.replace("_", "-"), action=argparse.BooleanOptionalAction, default=None,
                           help=cli_help(name))
        else:
            g.add_argument("--" + name.replace("_", "-"), type=float, help=cli_help(name))
    g.add_argument("--json", metavar="OUT", help="also write every window's diagnosis to this JSON file")
    g.add_argument("--config", help="system config YAML, drive file or drive profile (config/profiles/, e.g. "
                   "heavy_film); default config/system.yaml. A drive file's /**/jident_diagnostic and "
                   "/**/jident_windowing sections set the options above that are not given (docs/your_drive.md)")
    g.add_argument("--method-config", help="method config YAML (default: config/method.yaml)")
    g.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    g.set_defaults(func=cmd_diagnose)


def _parse(argv: list, command: str) -> argparse.Namespace:
    """Parse with the parser of ``command`` alone.  ``jident simulate`` first without the scenario options
    (they import cli.scenario and with it the offline diagnosis): only when something is left over (or help is
    asked for) is it parsed again with them, so every error and the help text are the full parser's."""
    if command == "simulate" and not {"-h", "--help"} & set(argv):
        args, rest = build_parser(command, scenario=False).parse_known_args(argv)
        if not rest:
            return args
    return build_parser(command).parse_args(argv)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["demo"]:  # `jident demo [...]`: demo.py owns its arguments (the only command with rclpy)
        from jident_ros.cli.demo import main as demo_main
        return demo_main(argv[1:])
    if argv[:1] == ["salvage"]:  # `jident salvage <truncated.mcap> <out_dir>`: cli/salvage.py owns its arguments
        from jident_ros.cli.salvage import salvage_main
        return salvage_main(argv[1:])
    if argv[:1] == ["samples"]:  # `jident samples <recording> <out_dir>`: cli/samples.py owns its arguments
        from jident_ros.cli.samples import samples_main
        return samples_main(argv[1:])
    # the subcommand (""  for `jident`, `jident --help`, `jident --version`: the command list only)
    command = argv[0] if argv and not argv[0].startswith("-") else ""
    try:
        args = _parse(argv, command)
        if not getattr(args, "command", None):
            build_parser(command="").print_help()
            return 2
        return args.func(args)
    except (CliError, ValueError, FileNotFoundError) as exc:    # config.ConfigError is a ValueError
        print(f"jident: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jident: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
