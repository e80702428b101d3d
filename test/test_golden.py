"""The golden outputs (issue 19): ``jident diagnose --json`` (and its printed table) on the demo's cases, raw-encoder
CSV files, JointState and drive/signals bags of the second drive, and a ``jident trend`` run are what
test/data/golden/ holds, bit for bit (timing values and paths aside: scripts/golden.py).

A change meant to change these outputs regenerates them with one command and says so in its commit:

    .venv/bin/python scripts/golden.py
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _golden_module():
    spec = importlib.util.spec_from_file_location("golden", REPO / "scripts" / "golden.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_outputs_are_the_golden_ones(tmp_path):
    golden = _golden_module()
    files = golden.generate(tmp_path)
    stored = sorted(p.name for p in golden.GOLDEN.iterdir())
    assert stored == sorted(files), "regenerate: .venv/bin/python scripts/golden.py"
    bad = golden.compare(files, golden.GOLDEN)
    assert not bad, "\n".join(bad) + "\n(a change meant to change them: .venv/bin/python scripts/golden.py)"


def test_the_comparison_sees_a_changed_digit(tmp_path):
    golden = _golden_module()
    name = "diagnose_demo.json"
    text = (golden.GOLDEN / name).read_text()
    changed = text.replace("1.16", "1.17", 1)
    assert changed != text
    assert golden.compare({name: changed}, golden.GOLDEN) and not golden.compare({name: text}, golden.GOLDEN)


def test_the_comparison_takes_rounding_and_nothing_more():
    """Another machine's BLAS moves the last digits (1e-15 … 1e-8 relative, stop 40): the same output; a number moved
    by 1e-5 relative, or a word changed, is not."""
    golden = _golden_module()
    assert golden.same_text('{"j": 1.077415111130998, "m": 80.88823102639056}',
                            '{"j": 1.0774151111309966, "m": 80.88823095569668}')
    assert not golden.same_text('{"j": 1.077415111130998}', '{"j": 1.077426111130998}')
    assert not golden.same_text('{"se": 0.0097365}', '{"se": 0.0097375}')
    assert not golden.same_text('{"level": "OK", "j": 1.0}', '{"level": "WARN", "j": 1.0}')
    assert not golden.same_text("1,2,3", "1,2")
