"""diagnose_window (jident_ros/diagnosis.py) and `jident diagnose` (jident_ros/offline.py), without ROS.

The recording is written as the simulator node + the diagnostic node's recorder write it: drive/signals
batches of 50 samples in the 2-D layout, drive/true_inertia, drive/backlash_width and drive/case before
each case's first sample.  The end-to-end comparison with the live nodes (live == replay == offline) is
test_nodes.py::test_offline_diagnosis_gives_the_same_estimates.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
JIDENT = REPO / ".venv" / "bin" / "jident"
TRUE_J1 = (1.16, 1.073)


@pytest.fixture(scope="module")
def configs():
    from jident_ros.config import load_method_config, load_system_config
    return load_system_config(), load_method_config()


@pytest.fixture(scope="module")
def library_file(default_library_file):
    """Pattern library of the default configuration (conftest: built once per run)."""
    return default_library_file


@pytest.fixture(scope="module")
def library(library_file):
    from jident_ros.method.patterns import PatternLibrary
    return PatternLibrary.load(library_file)


@pytest.fixture(scope="module")
def windows(configs):
    """Simulated windows: 0 nominal, 1 another class, 2 nominal off the pattern runs (eta_k 0.0375),
    3 between the classes 1.073 and 1.131."""
    from jident_ros.sim import Case, simulate_grid
    cases = [Case(1.16, 0.005, 0.025), Case(1.073, 0.005, 0.025), Case(1.16, 0.005, 0.0375),
             Case(1.10, 0.005, 0.025)]
    return simulate_grid(configs[0], cases)


def write_recording(bag_dir: Path, system, inertias=TRUE_J1, eta=0.0375, namespace="/t", batch=50, gap=400,
                    start_time_s=1.0, cases=None):
    """Simulate the cases (``cases``, else J1 ``inertias`` at K2 5 mm and ``eta``) and write them as the
    diagnostic node records the simulator's topics (also scripts/golden.py's demo recording)."""
    from jident_ros.bag.writer import BagWriter
    from jident_ros.cli.offline import multiarray_message
    from jident_ros.sim import Case, simulate_grid
    from jident_ros.stream.detector import embed_windows
    from jident_ros.stream.layout import CASE_LABEL, DEFAULT_CHANNELS
    cases = [Case(j, 0.005, eta) for j in inertias] if cases is None else list(cases)
    ws = simulate_grid(system, cases)
    stream, entry_rows = embed_windows(ws, gap, start_time_s, DEFAULT_CHANNELS)
    per, ts = gap + len(ws.t), ws.sample_period_s
    topic = lambda rel: f"{namespace}/{rel}"  # noqa: E731
    with BagWriter(bag_dir) as bag:
        bag.add_topic(topic("drive/signals"), "std_msgs/msg/Float64MultiArray")
        for rel in ("drive/true_inertia", "drive/backlash_width"):
            bag.add_topic(topic(rel), "std_msgs/msg/Float64", qos="transient_local")
        bag.add_topic(topic("drive/case"), "std_msgs/msg/Float64MultiArray", qos="transient_local")
        for i, c in enumerate(cases):
            t_case = int((stream[i * per, 0] - ts / 2) * 1e9)  # just before the case's first sample
            bag.write(topic("drive/true_inertia"), {"data": c.inertia_kgm2}, t_case)
            bag.write(topic("drive/backlash_width"), {"data": c.backlash_width_m}, t_case)
            row = np.array([[i, c.inertia_kgm2, c.backlash_width_m, c.consistency_pa_sn, stream[entry_rows[i], 0]]])
            bag.write(topic("drive/case"), multiarray_message(row, CASE_LABEL.split(",")), t_case)
            for s in range(i * per, (i + 1) * per, batch):
                b = stream[s:min(s + batch, (i + 1) * per)]
                bag.write(topic("drive/signals"), multiarray_message(b, DEFAULT_CHANNELS), int(b[-1, 0] * 1e9))
    return bag_dir


@pytest.fixture(scope="module")
def recording(configs, tmp_path_factory):
    return write_recording(tmp_path_factory.mktemp("rec") / "run", configs[0])


def diagnose_window(data, entry_index, backlash_width_m, wheel_radius_m, sample_period_s, *, library, system,
                    method, p, gap_method="auto", image_method=True, policy=None, library_error="",
                    on_estimate=None, **window):
    """One window through a Diagnoser built for it (the former diagnose_window's arguments)."""
    from jident_ros.identify.diagnosis import Diagnoser, DiagnosisConfig, WindowInput
    diagnoser = Diagnoser(system, method, DiagnosisConfig(p, gap_method, image_method), policy, library,
                          library_error)
    return diagnoser.diagnose(WindowInput(data, entry_index, backlash_width_m, wheel_radius_m, sample_period_s,
                                          **window), on_estimate=on_estimate)


def _diagnose(windows, i, configs, library, **kw):
    system, method = configs
    data = kw.pop("data", None) or windows.case(i)
    return diagnose_window(data, windows.entry_index, windows.cases[i].backlash_width_m,
                           system.load.wheel_radius_m, windows.sample_period_s, library=library,
                           system=system, method=method, p=2.0, **kw)


# --------------------------------------------------------------------------- diagnose_window


def test_nominal_window_is_ok(windows, configs, library):
    from jident_ros.identify.levels import OK
    d = _diagnose(windows, 0, configs, library)
    v = d.value_dict()
    assert d.level == OK, d.message
    assert d.message == f"J1 = {d.inertia_kgm2:.5g} kg m^2: nominal class 1.16"
    assert d.source == "gap" and abs(d.inertia_kgm2 - 1.16) / 1.16 < 1e-3 and d.class_kgm2 == 1.16
    assert v["verdict_class_kgm2"] == 1.16 and v["verdict_agree"] is True and v["verdict_between_classes"] is False
    assert v["image_class_kgm2"] == 1.16 and v["identified_class_kgm2"] == 1.16
    assert d.status == "nominal" and d.refused_reason is None and v["status"] == "nominal"
    lo, hi = v["gap_ci95_kgm2"]
    assert lo < v["gap_j1_kgm2"] < hi
    assert abs(v["backlash_width_estimate_m"] - 0.005) < 3 * v["backlash_width_estimate_std_m"] + 1e-4
    assert len(v["h.a1"]) == 7 and v["estimate_latency_ms"] <= v["processing_ms"]
    assert "problems" not in v


def test_other_class_is_warn(windows, configs, library):
    from jident_ros.identify.levels import WARN
    d = _diagnose(windows, 1, configs, library)
    assert d.level == WARN and "class 1.073 deviates from the nominal 1.16 by -7.5 %" in d.message, d.message
    assert d.value_dict()["deviation_percent"] == pytest.approx(-7.5, abs=0.05)


def test_image_method_agrees_with_the_gap_on_the_default_profile(windows, configs, library):
    """Nominal J1 at eta_k = 0.0375 (off the pattern runs) on the paper-consistent default drive: the gap and the
    image method both give 1.16, so the status is OK."""
    from jident_ros.identify.levels import OK
    d = _diagnose(windows, 2, configs, library)
    v = d.value_dict()
    assert d.class_kgm2 == 1.16 and v["verdict_agree"] is True and v["image_class_kgm2"] == 1.16
    assert d.level == OK and "disagrees" not in d.message and "information" not in d.message, d.message


@pytest.fixture(scope="module")
def heavy(configs):
    """The heavy-film stress profile (config/profiles/heavy_film.yaml): the eta_k groups differ in load by
    +-15 %, so at eta_k = 0.0375 the image method answers another class than the gap's nominal 1.16."""
    from jident_ros.config import load_system_config
    from jident_ros.method.patterns import PatternLibrary
    from jident_ros.sim import Case, simulate_grid
    system = load_system_config("heavy_film")
    cfg = (system, configs[1])
    return simulate_grid(system, [Case(1.16, 0.005, 0.0375)]), cfg, PatternLibrary.build(*cfg)


def test_image_method_disagreeing_outside_its_domain_is_information(heavy):
    """With image_min_margin 0 (the image method is never trusted alone) a disagreement is information, not
    a WARN (issue 12: a WARN must mean "look at this drive")."""
    from jident_ros.identify.levels import OK
    from jident_ros.identify.verdict import VerdictPolicy
    ws, cfg, lib = heavy
    d = _diagnose(ws, 0, cfg, lib, policy=VerdictPolicy(image_min_margin=0.0))
    v = d.value_dict()
    assert d.class_kgm2 == 1.16 and v["verdict_agree"] is False and v["image_class_kgm2"] != 1.16
    assert v["image_in_domain"] is False and "image_min_margin 0" in v["image_domain_reason"]
    assert d.level == OK and "nominal class 1.16; information: the image method answers class" in d.message, d.message
    assert "not a warning" in d.message
    # without the image method nothing disagrees
    g = _diagnose(ws, 0, cfg, None, image_method=False)
    assert g.level == OK and g.value_dict()["verdict_agree"] == "unknown" and g.inertia_kgm2 == d.inertia_kgm2


def test_image_method_disagreeing_inside_its_domain_is_warn(heavy):
    from jident_ros.identify.levels import WARN
    from jident_ros.identify.verdict import VerdictPolicy
    ws, cfg, lib = heavy
    margin = _diagnose(ws, 0, cfg, lib).value_dict()["image_margin"]
    d = _diagnose(ws, 0, cfg, lib, policy=VerdictPolicy(image_min_margin=max(1.0, margin * 0.999)))
    assert d.value_dict()["image_in_domain"] is True
    assert d.level == WARN and "nominal class 1.16; the image method disagrees: its class" in d.message, d.message
    # above its margin the same disagreement is information again
    e = _diagnose(ws, 0, cfg, lib, policy=VerdictPolicy(image_min_margin=margin * 1.01))
    assert e.level == 0 and "information" in e.message


def test_between_classes_is_warn(windows, configs, library):
    """J1 = 1.10, 0.2 % below the class 1.102: with the simulator's exact torque declared (no offset band) the
    interval is ± 0.05 % and no class lies within 3 standard errors: between classes, WARN.  With the default
    torque offset band (± 1 % of M_b) 1.102 is within them: its class."""
    from jident_ros.identify.levels import WARN
    from jident_ros.identify.verdict import VerdictPolicy
    d = _diagnose(windows, 3, configs, library, policy=VerdictPolicy(torque_offset_rel_base=0.0))
    v = d.value_dict()
    assert v["verdict_between_classes"] is True and math.isnan(v["verdict_class_kgm2"]), d.message
    assert d.level == WARN and "between classes" in d.message and abs(d.inertia_kgm2 - 1.10) / 1.10 < 1e-3
    banded = _diagnose(windows, 3, configs, library).value_dict()
    assert banded["verdict_between_classes"] is False and banded["verdict_class_kgm2"] == pytest.approx(1.102)


def test_no_gap_and_no_library_is_error(windows, configs):
    from jident_ros.identify.levels import ERROR
    data = {k: v for k, v in windows.case(0).items() if k != "m_el"}  # the gap fit needs m_el
    d = _diagnose(windows, 0, configs, None, data=data, library_error="pattern library missing: no.npz")
    assert d.level == ERROR and not d.diagnosed and d.inertia_kgm2 is None
    assert d.message == ("window could not be diagnosed: gap: no electromagnetic torque: the gap fit needs m_el; "
                         "pattern library missing: no.npz")
    # with a gap but without the library the image method was asked for: the gap estimate, flagged ERROR
    e = _diagnose(windows, 0, configs, None, library_error="pattern library missing: no.npz")
    assert e.level == ERROR and e.source == "gap" and "(from the gap only)" in e.message, e.message
    assert e.message.endswith("; pattern library missing: no.npz"), e.message


def test_no_gap_publishes_the_image_class_only_above_its_margin(windows, configs, library):
    """Gap off: the image method's class goes out only inside its validity domain (margin >= image_min_margin,
    a library width matching K2); else nothing, and the status says why."""
    from jident_ros.identify.levels import ERROR, OK
    from jident_ros.identify.verdict import VerdictPolicy
    published = []
    never = VerdictPolicy(image_min_margin=0.0)
    d = _diagnose(windows, 0, configs, library, gap_method="off", on_estimate=published.append, policy=never)
    assert d.inertia_kgm2 is None and published == [] and d.level == ERROR and d.status == "undiagnosed"
    assert "image method: class 1.16 not published: image_min_margin 0" in d.message, d.message
    trusted = VerdictPolicy(image_min_margin=1.5)   # window 0 is a pattern run: margin inf
    d = _diagnose(windows, 0, configs, library, gap_method="off", on_estimate=published.append, policy=trusted)
    assert d.source == "image" and d.inertia_kgm2 == d.value_dict()["image_class_kgm2"] == 1.16 and d.level == OK
    assert published == [1.16] and "image method, margin inf >= image_min_margin 1.5" in d.message, d.message
    # a K2 whose nearest library width (0.005) is 10 % off: outside the domain, nothing published
    system, method = configs
    d = diagnose_window(windows.case(0), windows.entry_index, 0.0045, system.load.wheel_radius_m,
                        windows.sample_period_s, library=library, system=system, method=method, p=2.0,
                        gap_method="off", policy=trusted)
    assert d.inertia_kgm2 is None and "library width 0.005 m is not within 5%" in d.message, d.message


def test_the_gap_estimate_is_reported_before_the_image_method_runs(windows, configs, library, monkeypatch):
    import jident_ros.identify.diagnosis as diagnosis
    published, seen_by_image = [], []
    real = diagnosis.identify_window

    def spy(*a, **kw):
        seen_by_image.append(list(published))
        return real(*a, **kw)

    monkeypatch.setattr(diagnosis, "identify_window", spy)
    d = _diagnose(windows, 0, configs, library, on_estimate=published.append)
    assert seen_by_image == [[d.inertia_kgm2]] and published == [d.inertia_kgm2]


def test_bad_arguments_name_the_field(windows, configs, library):
    with pytest.raises(ValueError, match="gap_method: expected one of auto, acceleration, gap_only, anchored, angle, "
                                         "speed, none, off, got 'fast'"):
        _diagnose(windows, 0, configs, library, gap_method="fast")
    with pytest.raises(ValueError, match="image_method"):
        _diagnose(windows, 0, configs, library, gap_method="off", image_method=False)


def test_diagnosis_and_offline_need_no_rclpy():
    code = ("import sys, jident_ros.identify.diagnosis, jident_ros.cli.offline, jident_ros.nodes.ros_io; "
            "assert 'rclpy' not in sys.modules, 'rclpy imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert r.returncode == 0, r.stderr


# --------------------------------------------------------------------------- jident diagnose


def test_diagnose_recording_finds_the_true_inertia(recording, configs, library):
    from jident_ros.cli.offline import diagnose_recording
    result = diagnose_recording(recording, library=library)
    assert result.signals_topic == "/t/drive/signals" and result.backlash_width_source == "/t/drive/backlash_width"
    assert len(result.windows) == 2 and not result.dropped
    assert [w.true_inertia_kgm2 for w in result.windows] == list(TRUE_J1)
    for w, true in zip(result.windows, TRUE_J1):
        assert abs(w.inertia_kgm2 - true) / true < 0.01, (w.inertia_kgm2, true)
        assert w.diagnosis.class_kgm2 == true and w.diagnosis.source == "gap"
    # the same numbers as diagnose_window on the simulator's windows (the detector's window is the simulator's)
    from jident_ros.sim import Case, simulate_grid
    ws = simulate_grid(configs[0], [Case(j, 0.005, 0.0375) for j in TRUE_J1])
    direct = [diagnose_window(ws.case(i), ws.entry_index, 0.005, configs[0].load.wheel_radius_m, ws.sample_period_s,
                              library=library, system=configs[0], method=configs[1], p=2.0).inertia_kgm2
              for i in range(2)]
    assert result.estimates == direct


def test_jident_diagnose_command(recording, library_file, tmp_path, capsys):
    from jident_ros.cli.main import main
    out = tmp_path / "out" / "diag.json"
    assert main(["diagnose", str(recording), "--library", str(library_file), "--json", str(out), "--quiet"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:3] == ["window", "entry_t_s", "true_J1"] and len(lines) == 4, lines
    assert lines[1].split()[:6] == ["1", "1.2240", "1.16", lines[1].split()[3], "gap", "1.16"], lines[1]
    assert lines[-1].startswith("2 window(s) from /t/drive/signals"), lines[-1]
    doc = json.loads(out.read_text())
    assert [w["true_inertia_kgm2"] for w in doc["windows"]] == list(TRUE_J1)
    for w in doc["windows"]:
        assert abs(w["error_percent"]) < 1.0 and w["values"]["estimate_source"] == "gap"
        assert w["status"] in ("nominal", "deviating") and w["refused_reason"] is None and w["level"] in ("OK", "WARN")
        assert w["values"]["verdict_class_kgm2"] == w["true_inertia_kgm2"]
    # gap only, K2 from the option
    assert main(["diagnose", str(recording), "--no-image", "--backlash-width-m", "0.005", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "K2 from --backlash-width-m" in text and "fused_class" not in text


def test_jident_diagnose_subprocess(recording, library_file, tmp_path):
    if not JIDENT.exists():
        pytest.skip(f"{JIDENT} not installed (run scripts/setup.sh)")
    out = tmp_path / "diag.json"
    r = subprocess.run([str(JIDENT), "diagnose", str(recording), "--library", str(library_file), "--p", "2",
                        "--gap-method", "auto", "--json", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    doc = json.loads(out.read_text())
    estimates = [w["inertia_estimate_kgm2"] for w in doc["windows"]]
    assert len(estimates) == 2
    for got, true in zip(estimates, TRUE_J1):
        assert abs(got - true) / true < 0.01, (got, true)
    # bad input through the installed command: one line, exit status 2, no traceback
    r = subprocess.run([str(JIDENT), "diagnose", str(tmp_path / "no-such-run")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and r.stdout == "", (r.stdout, r.stderr)
    assert r.stderr.strip().splitlines() == [f"jident: error: recording {tmp_path / 'no-such-run'}: "
                                             f"no such file or directory"], r.stderr


def _one_line_error(capsys, argv) -> str:
    from jident_ros.cli.main import main
    assert main(argv) == 2
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jident: error: ") and "Traceback" not in cap.err, cap.err
    return lines[0]


def test_recording_without_signals_is_one_line_error(tmp_path, capsys):
    from jident_ros.bag.writer import BagWriter
    with BagWriter(tmp_path / "nosig") as bag:
        bag.add_topic("/t/drive/true_inertia", "std_msgs/msg/Float64")
        bag.write("/t/drive/true_inertia", {"data": 1.16}, 1_000_000_000)
    line = _one_line_error(capsys, ["diagnose", str(tmp_path / "nosig"), "--no-image"])
    assert "no drive/signals topic" in line and "/t/drive/true_inertia" in line, line


def test_missing_or_bad_recording_is_one_line_error(tmp_path, capsys, recording):
    line = _one_line_error(capsys, ["diagnose", str(tmp_path / "missing"), "--no-image"])
    assert "missing" in line and "no such file" in line, line
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    line = _one_line_error(capsys, ["diagnose", str(tmp_path / "junk.mcap"), "--no-image"])
    assert "junk.mcap" in line and "not an MCAP file" in line, line
    line = _one_line_error(capsys, ["diagnose", str(recording), "--p", "4"])
    assert "p: must be one of method.p_values" in line and "4" in line, line
    line = _one_line_error(capsys, ["diagnose", str(recording), "--gap-method", "fast"])
    assert "--gap-method" in line and "fast" in line, line
    line = _one_line_error(capsys, ["diagnose", str(recording), "--backlash-width-m", "-1"])
    assert "--backlash-width-m" in line and "-1" in line, line
    line = _one_line_error(capsys, ["diagnose", str(recording), "--topic", "/other/drive/signals", "--no-image"])
    assert "/other/drive/signals" in line and "/t/drive/signals" in line, line
