"""Batched features and identification (issue 23: the robustness sweeps' image method in one batch) equal the
per-window path bit for bit: pipeline.windows_features vs window_features, patterns.identify_windows vs
identify_window."""
from __future__ import annotations

import numpy as np
import pytest

from jident_ros.config import load_method_config, load_system_config
from jident_ros.method.patterns import PatternLibrary, identify_window, identify_windows, pattern_run_cases
from jident_ros.method.pipeline import window_features, windows_features
from jident_ros.sim import Case, add_measurement_noise, simulate_grid

SYSTEM = load_system_config()
METHOD = load_method_config().replace(p_values=(2.0, 3.0))
#: off the pattern runs (eta_k 0.0375 / 0.0125), on and between classes, every width edge
CASES = [Case(1.16, 0.005, 0.0375), Case(0.957, 0.0025, 0.0125), Case(1.218, 0.01, 0.05),
         Case(1.10, 0.0075, 0.0375), Case(1.073, 0.00875, 0.0125)]


@pytest.fixture(scope="module")
def data():
    ws = simulate_grid(SYSTEM, pattern_run_cases(SYSTEM) + CASES)
    library = PatternLibrary.build(SYSTEM, METHOD, windows=ws)
    n = len(ws.cases) - len(CASES)
    clean = [ws.case(i) for i in range(n, len(ws.cases))]
    noisy = add_measurement_noise(ws, 25.0, 7)
    return library, clean + [noisy.case(i) for i in range(n, len(ws.cases))], ws.entry_index


@pytest.mark.parametrize("variant", ["paper", "load_scaled"])
def test_windows_features_equal_window_features(data, variant):
    _, windows, entry = data
    method = METHOD.replace(variant=variant)
    refs = [float(np.mean(w["m_el"][:entry])) for w in windows]
    many, rngs = windows_features(windows, method, method.p_values, references=refs, entry_index=entry, chunk=3)
    assert many.shape == (2, len(windows), 5, method.n_clusters)
    for i, w in enumerate(windows):
        one, r = window_features(w, method, method.p_values, reference=refs[i], entry_index=entry)
        np.testing.assert_array_equal(many[:, i], one)
        assert rngs[i] == r


@pytest.mark.parametrize("p", [2.0, 3.0])
def test_identify_windows_equals_identify_window(data, p):
    library, windows, entry = data
    widths = [c.backlash_width_m for c in CASES] * 2
    batch = identify_windows(windows, entry, widths, library, METHOD, p)
    assert len(batch) == len(windows)
    for w, width, b in zip(windows, widths, batch):
        a = identify_window(w, entry, width, library, METHOD, p)
        assert (a.fused_class_index, a.width_index, a.p) == (b.fused_class_index, b.width_index, b.p)
        assert a.fused_margin == b.fused_margin or (np.isnan(a.fused_margin) and np.isnan(b.fused_margin))
        assert list(a.answers) == list(b.answers)
        for name in a.answers:
            np.testing.assert_array_equal(a.answers[name].h, b.answers[name].h)
            assert a.answers[name].class_index == b.answers[name].class_index
    # not trivially equal: the noisy windows are not all answered like the clean ones
    assert len({b.answers["a1"].h.tobytes() for b in batch}) == len(batch)


def test_identify_windows_refuses_a_missing_p(data):
    library, windows, entry = data
    with pytest.raises(Exception, match="p"):
        identify_windows(windows[:1], entry, [0.005], library, METHOD, 9.0)
