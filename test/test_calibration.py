"""Pattern library from calibration recordings (jident_ros/cli/calibration.py, `jident build-patterns
--from-recordings`).  No ROS: the recordings are written with BagWriter from simulated cases, the way the
simulator node publishes them (drive/signals batches; drive/true_inertia, drive/backlash_width, drive/case).

Cost: one simulate_grid call (the 42 pattern runs at eta_k = 0.025 + 3 held-out runs, EXTRA_CASES), the
simulator-built library (the fixtures ``windows`` and ``library`` of conftest.py) and the recordings-built
one (each 42 windows), a few small builds.
"""
from __future__ import annotations

import numpy as np
import pytest

from jident_ros.bag.writer import BagWriter
from jident_ros.cli.calibration import (
    CalibrationError,
    LabelledWindow,
    build_library_from_recordings,
    library_from_labelled_windows,
    parse_labels,
    pattern_window_counts,
    read_calibration_windows,
)
from jident_ros.cli.main import main
from jident_ros.config import load_method_config
from jident_ros.method import normalise as nz
from jident_ros.method.patterns import LibraryMismatch, PatternLibrary, identify_window
from jident_ros.method.pipeline import SIGNALS, batch_features
from jident_ros.sim import Case
from jident_ros.stream.detector import embed_windows
from jident_ros.stream.layout import DEFAULT_CHANNELS, pack

NS = "/drive/"
F64 = "std_msgs/msg/Float64"
F64MA = "std_msgs/msg/Float64MultiArray"
CASE_LABEL = "case_index,inertia_kgm2,backlash_width_m,consistency_pa_sn,entry_time_s"
#: Held-out runs (not pattern runs): identified with both libraries.
EXTRA_CASES = [Case(1.073, 0.005, 0.0375), Case(1.189, 0.0075, 0.0375), Case(0.957, 0.0025, 0.0125)]


# ------------------------------------------------------------------ helpers
def multiarray(array, channels):
    data, dims, offset = pack(array, channels)
    return {"layout": {"dim": [{"label": lb, "size": int(n), "stride": int(s)} for lb, n, s in dims],
                       "data_offset": int(offset)}, "data": data}


def subset(ws, idx):
    return type(ws)(ws.t, {k: v[list(idx)] for k, v in ws.signals.items()}, [ws.cases[i] for i in idx],
                    ws.entry_index, ws.sample_period_s, ws.initial_slip[list(idx)])


def write_recording(path, ws, idx, *, truth=("true_inertia",), width=True, rows=None, batch=50, gap=400):
    """A bag as the simulator node publishes it: per case its announcements, then its samples in batches.

    truth: which J1 announcements to record ("true_inertia", "case"); width: record drive/backlash_width;
    rows: keep only the first ``rows`` rows of each case (e.g. steady state only, no entry).
    """
    sub = subset(ws, idx)
    stream, entry_rows = embed_windows(sub, gap, start_time_s=1.0, channels=DEFAULT_CHANNELS)
    per = gap + len(ws.t)
    with BagWriter(path) as bag:
        bag.add_topic(NS + "signals", F64MA)
        for name, typ in (("true_inertia", F64), ("backlash_width", F64), ("case", F64MA)):
            bag.add_topic(NS + name, typ, qos="transient_local")
        for i, case in enumerate(sub.cases):
            block = stream[i * per:(i + 1) * per][:rows]
            t_ns = int(round(block[0, 0] * 1e9))
            if "true_inertia" in truth:
                bag.write(NS + "true_inertia", {"data": case.inertia_kgm2}, t_ns - 3000)
            if width:
                bag.write(NS + "backlash_width", {"data": case.backlash_width_m}, t_ns - 2000)
            if "case" in truth:
                row = [[i, case.inertia_kgm2, case.backlash_width_m, case.consistency_pa_sn,
                        stream[entry_rows[i], 0]]]
                bag.write(NS + "case", multiarray(np.array(row), CASE_LABEL.split(",")), t_ns - 1000)
            for s in range(0, block.shape[0], batch):
                b = block[s:s + batch]
                bag.write(NS + "signals", multiarray(b, DEFAULT_CHANNELS), int(round(b[0, 0] * 1e9)))
    return path


def run_cli(capsys, *argv):
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc, err, *needles):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, err
    assert len(lines) == 1 and lines[0].startswith("jident: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def method():
    return load_method_config()


@pytest.fixture(scope="module")
def recordings(windows, system, tmp_path_factory):
    """Pattern runs split over recordings labelled in every supported way, plus held-out and broken ones."""
    d = tmp_path_factory.mktemp("calibration")
    nw = len(system.grid.backlash_widths_m)
    per_class = lambda fs: [f * nw + e for f in fs for e in range(nw)]  # noqa: E731
    return {
        "truth": write_recording(d / "rec_truth", windows, per_class([0, 1, 2]), truth=("true_inertia",)),
        "case": write_recording(d / "rec_case", windows, per_class([3, 4]), truth=("case",)),
        "c5": write_recording(d / "rec_c5", windows, per_class([5]), truth=()),   # J1 by --label (name)
        "c6": write_recording(d / "rec_c6", windows, per_class([6]), truth=()),   # J1 by --label (full path)
        "held_out": write_recording(d / "held_out", windows, [42, 43, 44]),
        "no_width": write_recording(d / "no_width", windows, [0], width=False),
        "no_entry": write_recording(d / "no_entry", windows, [0, 1], rows=300),
        "dir": d,
    }


@pytest.fixture(scope="module")
def rec_library(recordings, system, method):
    r = recordings
    paths = [str(r[k]) for k in ("truth", "case", "c5", "c6")]
    labels = parse_labels(["rec_c5=1.189", f"{r['c6']}=1.218"], paths)
    return build_library_from_recordings(paths, system, method, labels=labels)


def class_permutation(rec_lib, sim_lib):
    return [sim_lib.classes_kgm2.index(c) for c in rec_lib.classes_kgm2]


# ------------------------------------------------------------------ (a) equals the simulator-built library
def test_recordings_library_equals_simulator_library(rec_library, library, system):
    """Same windows -> same patterns.  What differs: the classes are sorted ascending (the simulator
    library keeps the grid order), and the metadata says where the patterns came from."""
    assert rec_library.classes_kgm2 == tuple(sorted(system.grid.inertia_classes_kgm2))
    assert rec_library.widths_m == library.widths_m and rec_library.p_values == library.p_values
    assert rec_library.signals == SIGNALS
    perm = class_permutation(rec_library, library)
    np.testing.assert_allclose(rec_library.centres, library.centres[:, :, :, perm], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(rec_library.ranges, library.ranges[:, :, perm], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(rec_library.h5, library.h5, rtol=1e-12)
    meta = rec_library.metadata
    for k in ("format", "system_hash", "method_hash", "system", "method"):
        assert meta[k] == library.metadata[k], k
    assert meta["source"] == "recordings"
    assert pattern_window_counts(rec_library).tolist() == [[1] * 7] * 6
    assert (pattern_window_counts(library) == 1).all()
    recs = {r["file"].rsplit("/", 1)[-1]: r for r in meta["recordings"]}
    assert {k: v["windows"] for k, v in recs.items()} == {"rec_truth": 18, "rec_case": 12, "rec_c5": 6, "rec_c6": 6}
    assert recs["rec_truth"]["label_sources"] == ["/drive/true_inertia"]
    assert recs["rec_case"]["label_sources"] == ["/drive/case"]
    assert recs["rec_c5"]["label_sources"] == ["label"] and recs["rec_c6"]["inertias_kgm2"] == [1.218]


def test_recordings_library_save_load_keeps_configuration_check(rec_library, system, method, tmp_path):
    path = rec_library.save(tmp_path / "rec.npz")
    lib = PatternLibrary.load(path, system, method)
    assert lib.classes_kgm2 == rec_library.classes_kgm2 and lib.metadata == rec_library.metadata
    np.testing.assert_array_equal(lib.centres, rec_library.centres)
    with pytest.raises(LibraryMismatch, match=r"method\.eq12"):
        PatternLibrary.load(path, system, method.replace(eq12="literal"))


def test_windows_are_the_simulated_ones_with_their_labels(recordings, windows, system):
    ws = read_calibration_windows(recordings["case"], system)
    nw = len(system.grid.backlash_widths_m)
    assert len(ws) == 2 * nw
    for k, w in enumerate(ws):
        i = 3 * nw + k
        assert (w.inertia_kgm2, w.backlash_width_m) == (windows.cases[i].inertia_kgm2, windows.cases[i].backlash_width_m)
        assert w.entry_index == windows.entry_index and w.label_source == "/drive/case"
        for name in SIGNALS:
            np.testing.assert_array_equal(w.data[name], windows.signals[name][i])
    # the command-line label wins over the recording's messages; --backlash-width-m over drive/backlash_width
    ws = read_calibration_windows(recordings["held_out"], system, inertia_kgm2=2.0, backlash_width_m=0.004)
    assert {w.inertia_kgm2 for w in ws} == {2.0} and {w.backlash_width_m for w in ws} == {0.004}


# ------------------------------------------------------------------ (b) same answers on a held-out recording
def test_held_out_recording_identified_as_with_the_simulator_library(recordings, rec_library, library, windows,
                                                                     system, method):
    held = read_calibration_windows(recordings["held_out"], system)
    assert [(w.inertia_kgm2, w.backlash_width_m) for w in held] == [(c.inertia_kgm2, c.backlash_width_m)
                                                                     for c in EXTRA_CASES]
    perm = class_permutation(rec_library, library)
    for k, w in enumerate(held):
        for p in (2.0, 9.0):
            a = identify_window(w.data, w.entry_index, w.backlash_width_m, rec_library, method, p)
            b = identify_window(windows.case(42 + k), windows.entry_index, EXTRA_CASES[k].backlash_width_m, library,
                                method, p)
            assert a.fused_inertia_kgm2 == b.fused_inertia_kgm2 and a.width_index == b.width_index
            for name in SIGNALS:
                assert a.answers[name].inertia_kgm2 == b.answers[name].inertia_kgm2, (k, p, name)
                np.testing.assert_allclose(a.answers[name].h, b.answers[name].h[perm], rtol=1e-9)


# ------------------------------------------------------------------ averaging
def test_windows_of_one_pattern_are_averaged(windows, system, method):
    """Two windows of J1 = 1.073 at K2 = 0.005 (eta_k 0.025 and 0.0375) and one of 1.16: the 1.073 pattern
    is the mean of the two windows' centres and (h3, k3); h5 comes from the means."""
    g = system.grid
    nw, e = len(g.backlash_widths_m), g.backlash_widths_m.index(0.005)
    idx = [g.inertia_classes_kgm2.index(1.073) * nw + e, 42, g.inertia_classes_kgm2.index(1.16) * nw + e]
    wins = [LabelledWindow(windows.case(i), windows.entry_index, windows.cases[i].inertia_kgm2, 0.005, "x") for i in idx]
    lib = library_from_labelled_windows(wins, system, method)
    assert lib.classes_kgm2 == (1.073, 1.16) and lib.widths_m == (0.005,)
    assert pattern_window_counts(lib).tolist() == [[2, 1]]
    ps = lib.p_values
    for s, name in enumerate(SIGNALS):
        cen, rps, _ = batch_features(windows.signals[name][idx], name, method, ps)
        np.testing.assert_allclose(lib.centres[:, 0, s, 0], cen[:, :2].mean(axis=1), rtol=1e-12)
        np.testing.assert_allclose(lib.centres[:, 0, s, 1], cen[:, 2], rtol=1e-12)
        mean_range = [np.mean([r.h3 for r in rps[:2]]), np.mean([r.k3 for r in rps[:2]])]
        np.testing.assert_allclose(lib.ranges[0, s, 0], mean_range, rtol=1e-12)
        ranges = [nz.RangeParams(*mean_range), rps[2]]
        for k in range(len(ps)):
            assert lib.h5[k, 0, s] == pytest.approx(nz.h5_factor(lib.centres[k, 0, s], ranges), rel=1e-12)
    wins[2].backlash_width_m = 0.01   # 1.16 only at 0.01, 1.073 only at 0.005
    with pytest.raises(CalibrationError, match=r"no window for J1 = 1\.16 kg m\^2 at K2 = 0\.005 m"):
        library_from_labelled_windows(wins, system, method)


# ------------------------------------------------------------------ CLI
def test_cli_builds_from_recordings(recordings, system, method, tmp_path, capsys):
    r = recordings
    out = tmp_path / "lib.npz"
    rc, stdout, err = run_cli(capsys, "build-patterns", "--from-recordings", str(r["c5"]), str(r["c6"]),
                              "--label", "rec_c5=1.189", "--label", f"{r['c6']}=1.218", "--out", str(out))
    assert rc == 0, err
    assert "2 J1 classes x 6 widths" in stdout and "from 12 windows of 2 recording(s)" in stdout
    assert "rec_c5: 6 window(s): J1 1.189 x 6 (J1 from label" in err
    lib = PatternLibrary.load(out, system, method)
    assert lib.classes_kgm2 == (1.189, 1.218) and lib.metadata["source"] == "recordings"
    want = build_library_from_recordings([str(r["c5"]), str(r["c6"])], system, method,
                                         labels={str(r["c5"]): 1.189, str(r["c6"]): 1.218})
    np.testing.assert_array_equal(lib.centres, want.centres)


@pytest.mark.parametrize("case", ["missing", "no_signals", "no_entry", "no_label", "one_class", "bad_label",
                                  "unknown_label", "no_width", "label_without_recordings"])
def test_cli_errors_are_one_line(case, recordings, tmp_path, capsys):
    r = recordings
    out = tmp_path / "lib.npz"
    base = ["build-patterns", "--out", str(out), "--from-recordings"]
    if case == "missing":
        argv, needles = base + [str(r["c5"]), str(tmp_path / "nope")], [str(tmp_path / "nope"), "no such file"]
    elif case == "no_signals":
        d = tmp_path / "only_truth"
        with BagWriter(d) as bag:
            bag.add_topic(NS + "true_inertia", F64)
            bag.write(NS + "true_inertia", {"data": 1.16}, 1000)
        argv, needles = base + [str(d)], [str(d), "no drive/signals topic", "/drive/true_inertia"]
    elif case == "no_entry":
        argv, needles = base + [str(r["no_entry"]), "--label", "no_entry=1.16"], \
            [str(r["no_entry"]), "no backlash entry", "K2 = 0.0025, 0.00375 m",
                                                                 "drops: clock jumps 1"]
    elif case == "no_label":
        argv, needles = base + [str(r["c5"]), str(r["truth"])], [str(r["c5"]), "no J1 label", "--label"]
    elif case == "one_class":
        argv, needles = base + [str(r["c5"]), "--label", "rec_c5=1.189"], ["at least 2", "1.189", "rec_c5"]
    elif case == "bad_label":
        argv, needles = base + [str(r["c5"]), "--label", "rec_c5=heavy"], ["rec_c5=heavy", "'heavy'", "kg m^2"]
    elif case == "unknown_label":
        argv, needles = base + [str(r["c5"]), "--label", "rec_x=1.2"], ["'rec_x'", "not one of the recordings"]
    elif case == "no_width":
        argv, needles = base + [str(r["no_width"])], [str(r["no_width"]), "no backlash width", "--backlash-width-m"]
    else:
        argv, needles = ["build-patterns", "--out", str(out), "--label", "a=1.2"], ["--from-recordings"]
    rc, stdout, err = run_cli(capsys, *argv)
    assert_one_line_error(rc, _without_progress(err), *needles)
    assert not out.exists()


def _without_progress(err):
    """stderr without the per-recording progress lines (kept: the error line)."""
    return "\n".join(ln for ln in err.splitlines() if not ln.startswith("jident build-patterns: "))


def test_parse_labels():
    recs = ["out/run_a", "/data/run_b.mcap"]
    assert parse_labels(["run_a=1.16", "run_b=1.073"], recs) == {"out/run_a": 1.16, "/data/run_b.mcap": 1.073}
    assert parse_labels(["out/run_a=1.2"], recs) == {"out/run_a": 1.2}
    for bad, msg in (("run_a", "PATH=J1"), ("run_a=-1", "> 0"), ("run_a=nan", "> 0"), ("run_c=1.1", "run_c")):
        with pytest.raises(CalibrationError, match=msg):
            parse_labels([bad], recs)
    with pytest.raises(CalibrationError, match="already labelled"):
        parse_labels(["run_a=1.1", "out/run_a=1.2"], recs)
