"""Robustness evaluation (method/robustness.py, report_robustness.py) on tiny sweeps."""
import numpy as np
import pytest

from jident_ros.config import load_method_config, load_system_config
from jident_ros.method.patterns import PatternLibrary
from jident_ros.research.evaluation.robustness import (
    CHANNEL_SETS,
    PRIMARY,
    Sweep,
    check_targets,
    evaluate_windows,
    run_robustness,
    width_on_windows,
)
from jident_ros.sim import Case, add_measurement_noise, quantise_encoders, simulate_grid

CFG = load_system_config()
METHOD = load_method_config().replace(p_values=(2.0,))
CLASSES = tuple(CFG.grid.inertia_classes_kgm2)


@pytest.fixture(scope="module")
def library():
    return PatternLibrary.build(CFG, METHOD)


@pytest.fixture(scope="module")
def windows():
    # two on-class cases (one a pattern run) and one J1 far off the classes (1.00: between 0.957 and 1.073)
    cases = [Case(1.131, 0.005, 0.0375), Case(0.957, 0.0075, 0.025), Case(1.00, 0.009, 0.0125)]
    return simulate_grid(CFG, cases)


def test_sweep_shapes_and_noise_free_numbers(windows, library):
    sw = evaluate_windows(CFG, windows, "noise-free", "grid", library=library, method=METHOD)
    n = len(windows.cases)
    assert set(sw.gap) == set(CHANNEL_SETS)
    for key, g in sw.gap.items():
        for name in ("estimate", "lo", "hi", "rel_error", "covered", "n_gap", "gap_end"):
            assert g[name].shape == (n,), (key, name)
        assert not g["failed"], key
        assert np.all(np.abs(g["rel_error"]) < 0.005), key          # the noise-free target
        assert np.all(g["n_gap"] >= 9), key
    assert np.all(np.abs(sw.width["rel_error"]) < 0.05)
    assert sw.image["evaluated"].all() and sw.image["fused_class"].shape == (n,)
    assert np.all(np.isin(sw.image["width_used"], library.widths_m))
    # fused verdict: right class for the on-class cases, 'between classes' for J1 = 1.00
    assert list(sw.verdict["class"][:2]) == [CLASSES.index(1.131), CLASSES.index(0.957)]
    assert list(sw.verdict["between"]) == [False, False, True]
    acc = sw.accuracy(CLASSES)
    assert acc["n"] == 2 and acc["fused"] == 1.0 and acc["gap"] == 1.0 and acc["between"] == 0.0
    off = sw.offclass_outcomes(CLASSES, np.array([False, False, True]))
    assert off["n"] == 1 and off["between"] == 1.0 and off["nearest"] == 0.0
    s = sw.gap_summary()
    assert s["failed"] == 0 and s["max"] < 0.005 and s["coverage"] == 1.0


def test_noise_is_seeded_and_hurts(windows):
    clean = evaluate_windows(CFG, windows, "noise-free", "grid")
    a = evaluate_windows(CFG, add_measurement_noise(windows, 20.0, 5), "20 dB", "grid", snr_db=20.0, seed=5)
    b = evaluate_windows(CFG, add_measurement_noise(windows, 20.0, 5), "20 dB", "grid", snr_db=20.0, seed=5)
    assert a.image is None and a.verdict is None                    # no library: gap estimator only
    np.testing.assert_array_equal(a.gap[PRIMARY]["estimate"], b.gap[PRIMARY]["estimate"])
    e_clean = np.abs(clean.gap[PRIMARY]["rel_error"])
    e_noisy = np.abs(a.gap[PRIMARY]["rel_error"])
    assert e_noisy.mean() > 5 * e_clean.mean()
    # noise-free, the contact-torque fit gives the width; at 20 dB on a1 and m_el it is too uncertain and the
    # bracket of the (un-noised) angles answers, as it would with the clean angles alone
    assert np.all(clean.width["method"] == "contact") and np.nanmax(np.abs(clean.width["rel_error"])) < 1e-3
    bracket = a.width["method"] == "bracket"
    assert bracket.mean() > 0.5
    angles_only = width_on_windows(CFG, windows, clean.gap[PRIMARY]["gap_end"])      # no J1: bracket only
    assert np.all(angles_only["method"] == "bracket")
    np.testing.assert_allclose(a.width["estimate"][bracket], angles_only["estimate"][bracket])


def test_coarse_encoder_moves_the_width_estimate(windows):
    ref = evaluate_windows(CFG, windows, "exact", "grid", keys=(PRIMARY,))
    q = evaluate_windows(CFG, quantise_encoders(windows, 2 ** 8), "256", "quantisation", keys=(PRIMARY,),
                         counts_per_rev=256)
    assert set(q.gap) == {PRIMARY} and q.counts_per_rev == 256
    assert not np.allclose(q.width["estimate"], ref.width["estimate"])


def _fake_sweep(rel_errors, verdict_classes, true_j1=1.16, covered=True):
    n = len(rel_errors)
    est = true_j1 * (1 + np.asarray(rel_errors, float))
    gap = {"estimate": est, "lo": est - 0.01, "hi": est + 0.01, "rel_error": np.asarray(rel_errors, float),
           "covered": np.full(n, covered), "n_gap": np.full(n, 10), "gap_end": np.full(n, 58), "failed": {}}
    sw = Sweep("fake", "grid", [Case(true_j1, 0.005, 0.025)] * n, None, None, 5e-4)
    sw.gap = {PRIMARY: gap}
    sw.width = {"estimate": np.full(n, 0.005), "rel_error": np.zeros(n)}
    cls = np.array([-1 if c is None else CLASSES.index(c) for c in verdict_classes])
    sw.verdict = {"class": cls, "between": cls < 0, "inertia": est, "source": np.array(["gap"] * n)}
    return sw


def test_summaries_count_what_they_claim():
    sw = _fake_sweep([0.001, -0.03, 0.05], [1.16, 1.131, None])
    acc = sw.accuracy(CLASSES)
    assert acc["n"] == 3 and acc["fused"] == pytest.approx(1 / 3) and acc["between"] == pytest.approx(1 / 3)
    assert acc["gap"] == pytest.approx(1 / 3)        # -3 % -> 1.1252 (1.131), +5 % -> 1.218
    s = sw.gap_summary()
    assert s["max"] == pytest.approx(0.05) and s["median"] == pytest.approx(0.03)


def test_targets_fail_when_the_numbers_miss():
    from jident_ros.research.evaluation.robustness import RobustnessResult
    good = _fake_sweep([0.001, 0.002], [1.16, 1.16])
    bad = _fake_sweep([0.001, 0.006], [1.16, 1.131])
    for sweep, expect in ((good, True), (bad, False)):
        res = RobustnessResult(CLASSES, tuple(CFG.grid.backlash_widths_m), 0.025, [sweep], [], [], [], [], [],
                               tuple(CFG.grid.backlash_widths_m), 0.0)
        t = {x["name"]: x for x in check_targets(res, None)}
        assert t["gap |J1 error|, noise-free"]["met"] is expect
        assert t["fused class accuracy, noise-free grid"]["met"] is expect


def test_run_robustness_tiny_and_report(library, tmp_path):
    log = []
    res = run_robustness(CFG, METHOD, library=library, log=log.append, snr_db=(30.0,), extra_seeds=(3,),
                         offgrid_j1=(("1.00", 1.00),), offgrid_widths=(0.006,), encoder_counts=(4096,),
                         sample_periods=(1e-3,), image_stride=8,
                         grid_cases=[Case(1.16, 0.005, 0.0125), Case(1.218, 0.0025, 0.05)])
    assert [s.label for s in res.grid][0] == "noise-free" and res.grid[1].snr_db == 30.0
    assert len(res.grid_extra) == 1 and res.grid_extra[0].image is None
    assert res.grid_extra[0].verdict["class"].shape == (2,)          # the verdict's gap part
    assert (res.grid[1].seed, res.grid_extra[0].seed) == (1300, 3300) and res.offgrid_j1[1].seed not in (1300, 3300)
    assert len(res.offgrid_j1) == 2 and len(res.offgrid_j1[0].cases) == 24
    assert len(res.offgrid_width) == 2 and len(res.offgrid_width[0].cases) == 28
    assert [q.counts_per_rev for q in res.quantisation] == [4096]
    assert len(res.sample_period) == 2 and res.sample_period[0].sample_period_s == 1e-3
    assert res.sample_period[0].image is None
    assert res.offgrid_j1[0].image["evaluated"].sum() == 3          # every 8th of 24 windows
    assert res.grid[0].gap_summary()["max"] < 0.005
    assert res.grid[0].accuracy(CLASSES)["fused"] == 1.0
    # J1 = 1.00 is 4.5 % from the nearest class: flagged between classes when noise-free
    assert res.offgrid_j1[0].offclass_outcomes(CLASSES)["between"] == 1.0
    names = [t["name"] for t in res.targets]
    assert "gap |J1 error|, noise-free" in names and "fused class accuracy, 30 dB grid" in names
    assert any("robustness evaluation" in m for m in log)

    from jident_ros.research.evaluation.report_robustness import render_robustness, write_robustness_figures
    figs = write_robustness_figures(res, tmp_path / "figures")
    assert len(figs) == 4
    for path in figs.values():
        assert (tmp_path / path).stat().st_size > 10_000
    md = render_robustness(res, figs)
    assert md.startswith("### Robustness")
    for heading in ("#### Targets", "#### (a)", "#### (b)", "#### (c)", "#### (d)", "#### (e)", "#### Findings"):
        assert heading in md
    # every table row has as many cells as its header
    for block in md.split("\n\n"):
        rows = [r for r in block.splitlines() if r.startswith("|")]
        if rows:
            width = rows[0].replace("\\|", "").count("|")
            assert all(r.replace("\\|", "").count("|") == width for r in rows), rows[0]
