"""End-to-end demo: the three nodes as separate processes over DDS on a few grid cases.

``jident demo`` (what ``bash scripts/demo.sh`` runs):

1. loads the pattern library of the default configuration, building it first if it is missing
   (about 5 s, cached under ~/.cache/jident_ros);
2. starts ``diagnostic`` (recording to ``<out>/recording``), ``windowing`` and ``simulator`` as three
   processes, found the way ``ros2 run jident_ros <exe>`` finds them (ament index prefix +
   ``lib/jident_ros/<exe>``; ``python -m jident_ros.nodes.<exe>`` when the package is not indexed);
   all three use the drive clock (``/clock`` from the simulator, ``use_sim_time``);
3. listens like any user would: ``drive/case`` (the true J1 and entry time of each case),
   ``inertia_estimate`` and ``/diagnostics``; matches each diagnosis to its case by the backlash-entry
   time and prints true and identified J1;
4. stops the nodes with SIGINT (as Ctrl-C would), checks that the MCAP recording was finalised, and
   writes ``summary.png``, ``summary.json`` and ``summary.md``.

Exit status 0 when every case was diagnosed (whatever the answer), 1 when a case got no answer or a
node failed, 2 on bad arguments.  rclpy is needed (``bash scripts/setup.sh`` installs it).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from jident_ros.bag.reader import read_bag
from jident_ros.cli.offline import OfflineError
from jident_ros.cli.trend import format_summary, plot_trend, run_trend, write_trend_csv
from jident_ros.config import load_method_config, load_system_config
from jident_ros.identify.levels import LEVEL_NAMES
from jident_ros.identify.library import default_library_path
from jident_ros.identify.trend import TrendConfig
from jident_ros.identify.trend_status import TREND_STATUS_NAME
from jident_ros.method.patterns import LibraryMismatch, PatternLibrary
from jident_ros.nodes.diagnostics import status_task
from jident_ros.nodes.ros_io import array_from_multiarray, qos_diagnostics, qos_latched, qos_signals, status_level, status_values
from jident_ros.resources import node_command, stop_process
from jident_ros.sim.scenarios import wear_scenario

#: Default cases (J1 kg m^2, backlash width m, eta_k Pa s^n): five of the paper's seven classes, five
#: widths, and every eta_k but the pattern runs' 0.025 -- none is a pattern run.
DEFAULT_CASES = (
    (1.16, 0.005, 0.0375),
    (1.073, 0.0025, 0.05),
    (1.218, 0.0075, 0.0125),
    (0.957, 0.01, 0.0375),
    (1.131, 0.00375, 0.05),
)
NAMESPACE = "/demo"
STATUS_NAME = "jident_diagnostic: inertia"   # without the namespace (nodes/diagnostics.status_task)


@dataclass
class CaseResult:
    """One case: what the simulator ran and what the diagnostic node answered."""

    case_index: int
    true_inertia_kgm2: float
    backlash_width_m: float
    consistency_pa_sn: float
    entry_time_s: float
    estimate_kgm2: float = math.nan       # value published on inertia_estimate (best continuous J1)
    ci95_kgm2: tuple = (math.nan, math.nan)
    identified_class_kgm2: float = math.nan
    image_class_kgm2: float = math.nan    # the paper's image method, fused over the five signals
    level: str = ""
    message: str = ""
    values: dict = field(default_factory=dict)

    @property
    def diagnosed(self) -> bool:
        return bool(self.level) and self.level != "ERROR"

    @property
    def error_percent(self) -> float:
        return (self.estimate_kgm2 - self.true_inertia_kgm2) / self.true_inertia_kgm2 * 100.0

    @property
    def class_correct(self) -> bool:
        return math.isclose(self.identified_class_kgm2, self.true_inertia_kgm2, rel_tol=1e-9)

    @property
    def image_agrees(self) -> bool:
        """The image method (the paper's fused H) names the same class as the gap estimate."""
        return self.image_class_kgm2 == self.identified_class_kgm2


def _explanation(results) -> list[str]:
    """What the two answers are, for a newcomer, and what this run's numbers say."""
    n = len(results)
    agree = sum(r.image_agrees for r in results)
    right = sum(r.class_correct for r in results)
    run = (f"In this run the two methods name the same class in {agree} of {n} cases"
           + (" — each answer is corroborated by the other." if agree == n else
              ("; where they differ the gap estimate is kept and the status says so (WARN)." if agree else
               "; nowhere do they agree: trust the gap estimate and see docs/results.md (validity map)."))
           + f" The published class is right in {right} of {n}.")
    return ["**How to read this.** For every entry into the backlash zone two independent methods answer:",
            "",
            "* *Gap estimate* (physics; the published J1): while the clutch flanks are apart the motor's torque "
            "accelerates only the masses on the shaft, J1·dω1/dt = m_el, so a fit over those few milliseconds gives "
            "J1 with a 95 % interval. Its nearest class is the identified class.",
            "* *Image method* (the paper's): the one-second transient of five signals is turned into wavelet images "
            "and compared with stored patterns of the seven classes; the closest pattern names its class.",
            "",
            "Status OK: the nominal class 1.16 and both methods agree. WARN: another class (J1 changed), the two "
            "disagree, or the J1 lies between classes. " + run]


def _parse_case(text: str):
    try:
        j1, width, eta = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--case {text!r}: expected J1,WIDTH,ETA (kg m^2, m, Pa s^n), "
                                         f"e.g. 1.16,0.005,0.0375") from None
    if not all(math.isfinite(v) and v > 0 for v in (j1, width, eta)):
        raise argparse.ArgumentTypeError(f"--case {text!r}: every value must be a positive number")
    return j1, width, eta


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jident demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--case", dest="cases", type=_parse_case, action="append",
                   help="J1,WIDTH,ETA of one case (repeatable; default: five cases across the grid)")
    p.add_argument("--real-time-factor", type=float, default=0.0,
                   help="drive seconds per wall second; 0 (default) = as fast as the windowing node reads "
                        "(fast_sleep_s per batch, back-pressure from drive/progress)")
    p.add_argument("--p", type=float, default=2.0, help="KHM exponent of the image method (default 2)")
    p.add_argument("--timeout", type=float, default=180.0, help="give up after this many seconds (default 180)")
    p.add_argument("--scenario", choices=("wear",),
                   help="wear: instead of --case, a drive whose backlash K2 grows 2.5 -> 3.5 mm over --windows "
                        "entries and whose J1 steps +2.5 %% half-way, through the same three nodes (windowing with "
                        "the flank detector, the diagnostic node's trend on); at the end the trend plot "
                        "(<out>/trend.png, jident trend on the node's recording) and the node's last trend status")
    p.add_argument("--windows", type=int, default=30,
                   help="--scenario wear: number of backlash entries (default 30, >= 8)")
    p.add_argument("--commissioning-windows", type=int, default=10,
                   help="--scenario wear: windows that learn the trend's baseline (default 10, >= 2)")
    return p


# --------------------------------------------------------------------------- processes


class NodeProcess:
    """One node executable, its output in ``<logs>/<name>.log``."""

    def __init__(self, name: str, logs: Path, ros_args: list[str], env: dict):
        self.name = name
        self.cmd = node_command(name) + ["--ros-args", "-r", f"__ns:={NAMESPACE}", *ros_args]
        self.log_path = logs / f"{name}.log"
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen(self.cmd, stdout=self._log, stderr=subprocess.STDOUT, env=env)

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, sig=signal.SIGINT, timeout: float = 20.0) -> int:
        rc = stop_process(self.proc, sig, timeout)
        self._log.close()
        return rc

    def tail(self, n: int = 15) -> str:
        if not self._log.closed:
            self._log.flush()
        lines = self.log_path.read_text(errors="replace").splitlines()[-n:]
        return "\n".join(f"    {line}" for line in lines)


def _ensure_library(p: float) -> Path:
    system, method = load_system_config(), load_method_config()
    if p not in [float(x) for x in method.p_values]:
        raise SystemExit(f"jident demo: error: --p {p:g} is not one of method.p_values {list(method.p_values)}")
    path = default_library_path(system, method)
    try:
        PatternLibrary.load(path, system, method)
        print(f"[demo] pattern library {path}")
        return path
    except (FileNotFoundError, LibraryMismatch):
        pass
    print(f"[demo] building the pattern library (eta_k = {system.grid.pattern_consistency_pa_sn:g} runs, "
          f"{len(system.grid.inertia_classes_kgm2)} J1 x {len(system.grid.backlash_widths_m)} widths) ...", flush=True)
    t0 = time.perf_counter()
    PatternLibrary.build(system, method).save(path)
    print(f"[demo] pattern library built in {time.perf_counter() - t0:.1f} s -> {path}")
    return path


# --------------------------------------------------------------------------- listening


def _listen(cases, procs, timeout, start_simulator, trend: bool = False):
    """Listen like a user: subscribe, wait until the diagnostic node's outputs are matched (they are not
    latched on /diagnostics, so a late listener would miss statuses), then ``start_simulator()`` and
    spin until every case has a diagnosis (or a node died / timeout)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64, Float64MultiArray


    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node("jident_demo_listener", namespace=NAMESPACE, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    results: dict[float, CaseResult] = {}
    statuses = []
    trend_statuses = []
    estimates = []

    def on_case(msg):
        arr, names = array_from_multiarray(msg)
        row = dict(zip(names, arr[0]))
        r = CaseResult(int(row["case_index"]), float(row["inertia_kgm2"]), float(row["backlash_width_m"]),
                       float(row["consistency_pa_sn"]), float(row["entry_time_s"]))
        results[round(r.entry_time_s, 6)] = r

    def on_diag(arr):
        for s in arr.status:
            if status_task(s.name) == STATUS_NAME and s.hardware_id == f"{NAMESPACE}/drive":
                statuses.append(s)
            elif status_task(s.name) == TREND_STATUS_NAME and s.hardware_id == f"{NAMESPACE}/drive":
                trend_statuses.append(s)

    node.create_subscription(Float64MultiArray, "drive/case", on_case, qos_latched(100))
    # a subscriber of drive/signals too, so that the simulator (wait_for_subscribers 3) streams only once this
    # listener is discovered: under load its latched drive/case rows were otherwise missed (ci, 0 cases run)
    node.create_subscription(Float64MultiArray, "drive/signals", lambda m: None, qos_signals())
    sub_est = node.create_subscription(Float64, "inertia_estimate", lambda m: estimates.append(m.data),
                                       qos_latched(100))
    sub_diag = node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, qos_diagnostics())

    def assign():
        pending = []
        for s in statuses:
            v = status_values(s)
            if "entry_time_s" not in v:
                continue
            r = results.get(round(float(v["entry_time_s"]), 6))
            if r is None:  # its drive/case message has not arrived yet
                pending.append(s)
                continue
            if r.level:
                continue
            r.level, r.message, r.values = LEVEL_NAMES[status_level(s)], s.message, v
            r.estimate_kgm2 = float(v.get("inertia_estimate_kgm2", "nan"))
            r.identified_class_kgm2 = float(v.get("identified_class_kgm2", "nan"))
            r.image_class_kgm2 = float(v.get("fused_class_kgm2", "nan"))
            if "gap_ci95_kgm2" in v:
                r.ci95_kgm2 = tuple(float(x) for x in v["gap_ci95_kgm2"].split())
            if r.case_index < len(cases):   # not the closing case of --scenario
                print(f"[demo] case {r.case_index + 1}: true J1 = {r.true_inertia_kgm2:.4f} kg m^2 "
                      f"(K2 = {r.backlash_width_m * 1e3:g} mm, eta_k = {r.consistency_pa_sn:g})  ->  identified "
                      f"{r.estimate_kgm2:.4f} kg m^2 ({r.error_percent:+.2f} %), class {r.identified_class_kgm2:g} "
                      f"[{'right' if r.class_correct else 'WRONG'}], image method {r.image_class_kgm2:g}, "
                      f"status {r.level}", flush=True)
        statuses[:] = pending

    deadline = time.monotonic() + timeout
    try:
        # the diagnostic node's inertia_estimate and the /diagnostics of windowing + diagnostic
        while time.monotonic() < deadline and not (sub_est.get_publisher_count() >= 1
                                                   and sub_diag.get_publisher_count() >= 2):
            ex.spin_once(timeout_sec=0.05)
            if not all(p.alive() for p in procs.values()):
                break
        start_simulator()
        while time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
            assign()
            if len(results) >= len(cases) and all(results[k].level for k in sorted(results)[:len(cases)]):
                break
            if not all(p.alive() for name, p in procs.items() if name != "simulator"):
                break
        # a little longer for the last messages (the trend status is periodic: one more period)
        end = time.monotonic() + (1.5 if trend else 0.5)
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assign()
    finally:
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    ordered = [results[k] for k in sorted(results)][:len(cases)]   # a closing case (--scenario) is not shown
    return ordered, estimates, (trend_statuses[-1] if trend_statuses else None)


# --------------------------------------------------------------------------- summary


def _write_summary(out: Path, results, meta):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (out / "summary.json").write_text(json.dumps(
        dict(meta, cases=[dict(asdict(r), error_percent=r.error_percent, class_correct=r.class_correct,
                               image_agrees=r.image_agrees) for r in results]), indent=2, default=str))
    lines = ["# jident demo", "", f"{meta['command']}", "", *_explanation(results), "",
             "| case | true J1 kg·m² | K2 mm | η_k | gap estimate J1 kg·m² (95 % interval) | error % | its class "
             "| image method's class | same class? | status |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        ci = "" if not all(math.isfinite(v) for v in r.ci95_kgm2) else \
            f" ({r.ci95_kgm2[0]:.4f}–{r.ci95_kgm2[1]:.4f})"
        lines.append(f"| {r.case_index + 1} | {r.true_inertia_kgm2:g} | {r.backlash_width_m * 1e3:g} | "
                     f"{r.consistency_pa_sn:g} | {r.estimate_kgm2:.4f}{ci} | {r.error_percent:+.2f} | "
                     f"{r.identified_class_kgm2:g} ({'right' if r.class_correct else 'wrong'}) | "
                     f"{r.image_class_kgm2:g} | {'yes' if r.image_agrees else 'no'} | {r.level or 'none'} |")
    lines += ["", f"Wall time {meta['wall_s']:.1f} s; recording `{meta['recording']}` "
              f"({meta['recorded_messages']} messages)."]
    (out / "summary.md").write_text("\n".join(lines) + "\n")

    fig, ax = plt.subplots(figsize=(8, 4.2), dpi=110)
    x = np.arange(len(results))
    true = np.array([r.true_inertia_kgm2 for r in results])
    est = np.array([r.estimate_kgm2 for r in results])
    lo = np.array([r.ci95_kgm2[0] for r in results])
    hi = np.array([r.ci95_kgm2[1] for r in results])
    image = np.array([r.image_class_kgm2 for r in results])
    ax.bar(x - 0.2, true, 0.4, label="true J1", color="0.75")
    yerr = np.vstack([np.nan_to_num(est - lo), np.nan_to_num(hi - est)])
    ax.bar(x + 0.2, est, 0.4, yerr=yerr, capsize=3, label="inertia_estimate (gap fit, 95 % CI)", color="tab:blue")
    ax.plot(x, image, "r_", markersize=22, mew=2, label="image method's class (paper)")
    ax.set_xticks(x, [f"case {r.case_index + 1}\nK2 {r.backlash_width_m * 1e3:g} mm\nη_k {r.consistency_pa_sn:g}"
                      for r in results], fontsize=8)
    finite = np.concatenate([true, est[np.isfinite(est)], image[np.isfinite(image)]])
    ax.set_ylim(finite.min() * 0.95, finite.max() * 1.07)
    ax.set_ylabel("J1 [kg m²]")
    n_right = sum(r.class_correct for r in results)
    n_agree = sum(r.image_agrees for r in results)
    ax.set_title(f"jident demo: {n_right}/{len(results)} classes right (gap estimate, max |error| "
                 f"{np.nanmax(np.abs([r.error_percent for r in results])):.2f} %); image method agrees in "
                 f"{n_agree}/{len(results)}", fontsize=9)
    ax.legend(fontsize=8, loc="upper left", ncol=3)
    fig.tight_layout()
    fig.savefig(out / "summary.png")
    plt.close(fig)


def _count_recording(bag: Path):
    counts = {}
    for m in read_bag(bag):
        counts[m.topic] = counts.get(m.topic, 0) + 1
    return counts


# --------------------------------------------------------------------------- main


def run(args) -> int:
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        print(f"jident demo: error: rclpy is not importable ({exc}); run `bash scripts/setup.sh` "
              "or source a ROS 2 distribution", file=sys.stderr)
        return 2
    scenario = None
    if args.scenario == "wear":
        scenario = wear_scenario(load_system_config(), args.windows, j1_step_at_window=args.windows // 2)
        cases = [(c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn) for c in scenario.cases]
    else:
        cases = args.cases or list(DEFAULT_CASES)
    out = Path(args.out)
    bag = out / "recording"
    logs = out / "logs"
    if bag.exists():
        shutil.rmtree(bag)
    logs.mkdir(parents=True, exist_ok=True)
    library = _ensure_library(args.p) if scenario is None else None
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.setdefault("ROS_DOMAIN_ID", str(os.getpid() % 100 + 1))
    os.environ.setdefault("ROS_DOMAIN_ID", env["ROS_DOMAIN_ID"])
    sim_time = ["-p", "use_sim_time:=true"]
    t0 = time.monotonic()
    procs: dict[str, NodeProcess] = {}
    try:
        if scenario is None:
            diag_args = ["-p", f"pattern_library:={library}", "-p", f"p:={args.p}"]
            win_args = ["-p", "backlash_width_from_topic:=true"]
        else:   # the trend follows the gap J1 and the flank detector's K2: no image method, no K2 given
            state = out / "trend_state.json"
            if state.exists():
                state.unlink()
            diag_args = ["-p", "image_method:=false", "-p", f"trend_commissioning_windows:={args.commissioning_windows}",
                         "-p", f"trend_state_file:={state}"]
            win_args = ["-p", "detector:=flank"]
        procs["diagnostic"] = NodeProcess("diagnostic", logs, [*sim_time, *diag_args, "-p", f"record_dir:={bag}",
                                                              "-p", "stale_after_s:=0.0"], env)
        procs["windowing"] = NodeProcess("windowing", logs, [*sim_time, *win_args], env)
        # --scenario: one closing case after the last entry (not counted, not waited for): the simulator's stream
        # ends with the last window, and the flank detector needs up to 16 samples more to close it
        lists = [[c[i] for c in cases + ([cases[-1]] if scenario is not None else [])] for i in range(3)]

        def start_simulator():
            procs["simulator"] = NodeProcess("simulator", logs, [
                "-p", "cases:=zip", "-p", f"inertias_kgm2:={lists[0]}", "-p", f"backlash_widths_m:={lists[1]}",
                "-p", f"consistencies_pa_sn:={lists[2]}", "-p", f"real_time_factor:={args.real_time_factor}",
                # windowing, the diagnostic node's recorder and this demo's listener subscribe to drive/signals
                "-p", "wait_for_subscribers:=3", "-p", "wait_timeout_s:=60.0"], env)
            print(f"[demo] started {', '.join(f'{n} ({p.cmd[0]})' for n, p in procs.items())} in namespace "
                  f"{NAMESPACE}, ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}; {len(cases)} case(s)", flush=True)

        results, estimates, trend_status = _listen(cases, procs, args.timeout, start_simulator, scenario is not None)
    finally:
        exited_early = {name: p.proc.poll() for name, p in procs.items()}  # None: still running, as it should
        codes = {name: p.stop(signal.SIGINT) for name, p in reversed(procs.items())}
    wall = time.monotonic() - t0
    # a node that ended before the demo stopped it with a non-zero status failed the run; one that crashed
    # while shutting down after Ctrl-C (seen rarely: SIGSEGV inside rclpy/rmw teardown of the windowing
    # node) lost nothing -- the recording is checked below -- and is reported as a warning
    failed = [n for n, c in codes.items() if c not in (0, -signal.SIGINT) and exited_early.get(n) is not None]
    for name, c in codes.items():
        if c not in (0, -signal.SIGINT):
            what = "FAILED" if name in failed else "warning: crashed while shutting down after SIGINT"
            print(f"[demo] {what}: node {name} exited with status {c}; last lines of {procs[name].log_path}:\n"
                  f"{procs[name].tail()}", file=sys.stderr)
    try:
        counts = _count_recording(bag)
    except Exception as exc:
        print(f"[demo] the recording {bag} could not be read: {type(exc).__name__}: {exc}", file=sys.stderr)
        counts, failed = {}, failed + ["recording"]
    meta = dict(command="jident demo " + " ".join(sys.argv[2:] if sys.argv[1:2] == ["demo"] else sys.argv[1:]),
                wall_s=wall, recording=str(bag), recorded_messages=sum(counts.values()), recorded_topics=counts,
                estimates_published=len(estimates), node_exit_codes=codes)
    missing = len(cases) - sum(r.diagnosed for r in results)
    if scenario is not None:
        # a gap J1 refused by the verdict policy is an answer (ERROR, said why), not a lost case
        missing = len(cases) - sum(bool(r.level) for r in results)
        failed += _show_trend(out, bag, scenario, trend_status, args.commissioning_windows)
    if results:
        _write_summary(out, results, meta)
    n_right = sum(r.class_correct for r in results)
    print(f"[demo] {len(results)} case(s) run, {len(results) - missing} diagnosed, {n_right} class(es) right; "
          f"{len(estimates)} estimate(s) on {NAMESPACE}/inertia_estimate; {wall:.1f} s wall")
    print(f"[demo] recording {bag} ({sum(counts.values())} messages: "
          + ", ".join(f"{t} {n}" for t, n in sorted(counts.items())) + ")")
    print(f"[demo] summary {out / 'summary.png'}, {out / 'summary.md'}; node logs in {logs}")
    if missing or failed or len(results) < len(cases):
        print(f"[demo] FAILED: {missing} case(s) without a diagnosis, nodes failed: {failed or 'none'}",
              file=sys.stderr)
        return 1
    return 0


def _show_trend(out: Path, bag: Path, scenario, status, commissioning_windows: int) -> list:
    """The end of ``--scenario wear``: the node's last "jident_diagnostic: trend" status, then ``jident trend``
    on the node's recording (drive/signals and the true values) -> <out>/trend.csv, trend.png and its
    summary.  Returns the failures (names) for the exit status."""
    failed = []
    if status is None:
        print("[demo] FAILED: no 'jident_diagnostic: trend' status received", file=sys.stderr)
        failed.append("trend status")
    else:
        v = status_values(status)
        print(f"[demo] the diagnostic node's trend ({LEVEL_NAMES[status_level(status)]}, "
              f"{v.get('windows_updated', '?')} windows, width from the flank detector in "
              f"{v.get('width_from_flank_detector', '?')}, from the gap estimator in "
              f"{v.get('width_from_gap_estimator', '?')}): {status.message}", flush=True)
    config = TrendConfig(commissioning_windows=commissioning_windows)
    try:
        run = run_trend([bag], config=config)
    except OfflineError as exc:
        print(f"[demo] FAILED: jident trend on {bag}: {exc}", file=sys.stderr)
        return failed + ["trend"]
    write_trend_csv(run, out / "trend.csv")
    png = plot_trend(run, out / "trend.png", config)
    print(f"[demo] truth: K2 {scenario.true_width_m[0] * 1e3:.4g} -> {scenario.true_width_m[-1] * 1e3:.4g} mm, "
          f"J1 +2.5 % at entry {scenario.j1_step_at_window}; jident trend on the recording:")
    print("\n".join("[demo]   " + line for line in format_summary(run, config).splitlines()))
    print(f"[demo] trend plot {png}", flush=True)
    return failed


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.scenario is not None and args.cases:
        print("jident demo: error: --case: not with --scenario (the scenario sets the cases)", file=sys.stderr)
        return 2
    if args.windows < 8 or args.commissioning_windows < 2 or args.commissioning_windows >= args.windows // 2:
        print(f"jident demo: error: --windows must be >= 8 and --commissioning-windows >= 2 and below the J1 step "
              f"at --windows / 2, got {args.windows} and {args.commissioning_windows}", file=sys.stderr)
        return 2
    if args.real_time_factor < 0 or not math.isfinite(args.real_time_factor):
        print(f"jident demo: error: --real-time-factor must be >= 0, got {args.real_time_factor}", file=sys.stderr)
        return 2
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
