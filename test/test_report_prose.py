"""Generated sentences of docs/results.md say what their numbers say (issue 13 item 5): change a number, the
sentence changes."""
import numpy as np

from jident_ros.research.evaluation.report import (
    sentence_ablation,
    sentence_paper_claim,
    sentence_sensor_matched,
    sentence_variant,
    trust_limits,
    trust_sentence,
)


class _Result:
    def __init__(self, fused, p_values=(2.0, 3.0)):
        self.fused, self.p_values = np.asarray(fused, float), tuple(p_values)

    def accuracy(self):
        return {"fused": self.fused}


def _entry(share, fused, n_right=16):
    ex = [{"p": 2, "ours_class": 0, "true": 0 if i < n_right else 1} for i in range(16)]
    return {"share": share, "result": _Result(fused), "examples": ex}


def test_the_paper_claim_sentence_follows_the_accuracy():
    assert "is reproduced" in sentence_paper_claim(1.0, 1.0, 16, 16)
    assert "not every case right" in sentence_paper_claim(0.992, 1.0, 16, 16)
    s = sentence_paper_claim(0.381, 0.421, 4, 16)
    assert "is not reproduced" in s and "38.1 %–42.1 %" in s and "4 of 16" in s
    assert "is reproduced" not in sentence_paper_claim(1.0, 1.0, 15, 16)


def test_the_variant_sentence_follows_the_comparison():
    assert "worse" in sentence_variant("load_scaled", (0.15, 0.2), (0.38, 0.42))
    assert "better" in sentence_variant("load_scaled", (0.5, 0.6), (0.38, 0.42))
    assert "overlapping" in sentence_variant("load_scaled", (0.4, 0.5), (0.38, 0.42))


def test_the_ablation_sentence_names_what_recovered_and_what_got_worse():
    base = np.array([0.34, 0.14, 0.36, 0.62, 0.15])
    s = sentence_ablation(base, np.array([0.82, 0.14, 0.16, 0.36, 0.76]))
    assert s.startswith("With every η_k group at the same load a1 (34.0 % → 82.0 %)")
    assert "v2" in s.split("recover")[0] and "omega1 (36.0 % → 16.0 %)" in s and "m_el changes by less" in s
    s2 = sentence_ablation(base, base + 0.01)
    assert "recover" not in s2 and "worse" not in s2


def test_the_trust_sentence_follows_the_map():
    mismatch = {"mismatch": np.array([-0.2, 0.0, 0.2]), "accuracy": np.array([[0.3], [1.0], [0.4]])}
    vm = [_entry(0.0001, [1, 1]), _entry(0.001, [0.99, 1]), _entry(0.01, [0.9, 0.94])]
    lim = trust_limits(vm, mismatch)
    assert lim == {"share": 0.001, "width": 0.0}
    s = trust_sentence(lim, 0.63)
    assert "at most 0.1 % of the load" in s and "63.0 %" in s and "gap estimate" in s
    # one number changes, the sentence changes
    vm[2] = _entry(0.01, [0.96, 0.97])
    assert "at most 1 % of the load" in trust_sentence(trust_limits(vm, mismatch), 0.63)
    vm[1] = _entry(0.001, [1, 1], n_right=15)      # an example wrong at 0.1 %
    assert "at most 0.01 % of the load" in trust_sentence(trust_limits(vm, mismatch), 0.63)
    assert "as good as the default set (97.0 %" in trust_sentence(lim, 0.97)
    mismatch["accuracy"][2, 0] = 0.99
    assert trust_limits(vm, mismatch)["width"] == 0.0       # -20 % still fails
    mismatch["accuracy"][0, 0] = 0.99
    assert trust_limits(vm, mismatch)["width"] == 0.2


def test_the_sensor_matched_sentence_follows_the_numbers():
    s = sentence_sensor_matched((0.984, 1.0), (0.627, 0.786), (0.865, 0.921))
    assert "98.4 %–100.0 % (≥ 95 % at every p)" in s and "better than the paper-faithful mode" in s
    assert "62.7 %–78.6 %" in s and "86.5 %–92.1 %" in s and "sensors actually used" in s
    s = sentence_sensor_matched((0.93, 0.99), (0.627, 0.786), None)
    assert "below 95 % at some p" in s and "≥ 95 %" not in s and "noise-free" not in s
    assert "below 95 % at every p" in sentence_sensor_matched((0.5, 0.6), (0.627, 0.786), None)
    assert "worse" in sentence_sensor_matched((0.5, 0.6), (0.627, 0.786), None)
    assert "sensors actually used" not in sentence_sensor_matched((0.99, 1.0), (0.6, 0.7), (0.97, 1.0))


def test_the_trust_sentence_names_the_matched_variant_only_when_it_meets_the_target():
    lim = {"share": 0.003, "width": 0.0}
    s = trust_sentence(lim, 0.627, matched_accuracy=0.984)
    assert "use the variant `sensor_matched`" in s and "≥ 98.4 %" in s and "62.7 %" in s
    assert "(100 % there at every p)" in trust_sentence(lim, 0.627, matched_accuracy=1.0)
    s = trust_sentence(lim, 0.627, matched_accuracy=0.90)
    assert "use the variant" not in s and "90.0 % with the variant `sensor_matched`" in s and "far better" in s


def test_the_width_sentence_follows_each_variant():
    from jident_ros.research.evaluation.report import sentence_width_variants
    ps = (2.0, 3.0, 6.0, 9.0)
    near = np.array([0.17, 0.2, 0.24, 0.23])
    s = sentence_width_variants(near, {"width_interp": np.array([0.61, 0.9, 0.86, 0.8]),
                                       "width_simulated": np.array([0.99, 0.98, 1.0, 1.0])}, ps)
    assert "`width_interp` raises the fused accuracy from 17.0 %–24.0 % to 61.0 %–90.0 %" in s
    assert "90 % is met at p = 3 only" in s and "met at every p" in s.split("width_simulated")[1]
    s = sentence_width_variants(near, {"width_interp": np.array([0.1, 0.12, 0.1, 0.1])}, ps)
    assert "lowers" in s and "met at no p" in s


def test_the_trust_sentence_names_width_simulated_and_its_condition():
    lim = {"share": 0.003, "width": 0.0}
    s = trust_sentence(lim, 0.627, width_simulated={"accuracy": 0.979, "sensor_within": 0.079})
    assert "`width_simulated` gets ≥ 97.9 %" in s and "in only 7.9 % of the windows" in s
    assert "which the default sensors give)" in trust_sentence(lim, 0.627, width_simulated={"accuracy": 0.979,
                                                                                              "sensor_within": 0.95})
    assert "width_simulated" not in trust_sentence(lim, 0.627, width_simulated={"accuracy": 0.8, "sensor_within": 1})
    assert "width_simulated" not in trust_sentence(lim, 0.627)
