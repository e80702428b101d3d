"""gap.py split by fit (issue 20): a test that patches a constant or function on a gap module patches the module that
reads it.

``from module import NAME`` binds a copy: after a function moved out of gap.py (to gap_a1.py, gap_angle.py, ...), a
``monkeypatch.setattr(gap, "NAME", ...)`` still succeeds where gap.py re-exports NAME, but no longer reaches the moved
function, and a test of a rule turned off passes without turning it off.  So every patch of a name on one of the
jident_ros.identify gap modules (``monkeypatch.setattr(module, "NAME", ...)`` or ``module.NAME = ...`` in test/*.py)
names a name that module's own source reads; and a name patched on gap that a module split from it reads too is
patched there as well in the same file.
"""
from __future__ import annotations

import ast
from pathlib import Path

TEST_DIR = Path(__file__).resolve().parent
IDENTIFY = TEST_DIR.parents[0] / "jident_ros" / "identify"
PACKAGE = "jident_ros.identify"
#: The modules split from gap.py (their functions were gap.py's and read its constants until the split).
SPLIT_FROM_GAP = ("gap_a1", "gap_angle", "gap_cross", "gap_interval", "gap_speed", "gap_steady", "gap_types",
                  "gap_width")


def _reads(module: str) -> set:
    """The names a module of jident_ros.identify loads (ast.Name in a Load context: its code reads them)."""
    tree = ast.parse((IDENTIFY / f"{module}.py").read_text())
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}


def _aliases(tree: ast.AST) -> dict:
    """{alias: module} of the jident_ros.identify gap modules a test file imports (anywhere in it)."""
    out = {}
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module == PACKAGE:
            for a in n.names:
                if a.name.startswith("gap"):
                    out.setdefault(a.asname or a.name, set()).add(a.name)
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name.startswith(f"{PACKAGE}.gap") and a.asname:
                    out.setdefault(a.asname, set()).add(a.name.rsplit(".", 1)[1])
    return out


def patches(source: str) -> set:
    """{(module, NAME)} patched in a test file's source: monkeypatch.setattr(module, "NAME", ...),
    monkeypatch.setattr("jident_ros.identify.module.NAME", ...) and module.NAME = ... on a gap module."""
    tree = ast.parse(source)
    aliases = _aliases(tree)
    ambiguous = {k: v for k, v in aliases.items() if len(v) > 1}
    assert not ambiguous, f"one alias for several gap modules: {ambiguous}"
    mod = {k: next(iter(v)) for k, v in aliases.items()}
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "setattr" and n.args:
            first = n.args[0]
            if isinstance(first, ast.Name) and first.id in mod and len(n.args) > 1 \
                    and isinstance(n.args[1], ast.Constant) and isinstance(n.args[1].value, str):
                out.add((mod[first.id], n.args[1].value))
            elif isinstance(first, ast.Constant) and isinstance(first.value, str) \
                    and first.value.startswith(f"{PACKAGE}.gap"):
                module, name = first.value[len(PACKAGE) + 1:].rsplit(".", 1)
                out.add((module, name))
        elif isinstance(n, (ast.Assign, ast.AugAssign)):
            for t in (n.targets if isinstance(n, ast.Assign) else [n.target]):
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id in mod:
                    out.add((mod[t.value.id], t.attr))
    return out


def unreached(patched: set) -> list:
    """The patches of ``patched`` ({(module, NAME)}, one file's) that do not reach the code reading NAME."""
    bad = []
    for module, name in sorted(patched):
        if name not in _reads(module):
            bad.append(f"{module}.{name}: {module}.py does not read it (patch the module that does)")
        elif module == "gap":
            for other in SPLIT_FROM_GAP:
                if name in _reads(other) and (other, name) not in patched:
                    bad.append(f"gap.{name}: {other}.py reads it too, and it is not patched there")
    return bad


def test_every_patch_of_a_gap_module_reaches_the_code_that_reads_it():
    found, bad = 0, []
    for path in sorted(TEST_DIR.glob("test_*.py")):
        patched = patches(path.read_text())
        found += len(patched)
        bad += [f"{path.name}: {x}" for x in unreached(patched)]
    assert found >= 15                                  # the checker sees the suite's patches (23 at the split)
    assert not bad, "; ".join(bad)


def test_the_check_fails_a_patch_left_on_gap_after_its_reader_moved():
    # plausible wrong tests after the split: the trim's persistence (gap_a1 reads it) patched on gap, a re-exported
    # rule switch assigned on gap, gap's own lag bound (read there) and gap_free's floor read by gap.py and gap_angle.py
    src = ("from jident_ros.identify import gap, gap_a1\n"
           "from jident_ros.identify import gap as G\n"
           "def test_x(monkeypatch):\n"
           "    monkeypatch.setattr(gap, 'TRIM_PERSIST', 0)\n"
           "    monkeypatch.setattr(gap_a1, '_free_level', None)\n"
           "    monkeypatch.setattr('jident_ros.identify.gap.LAG_Z', 1.0)\n"
           "    monkeypatch.setattr(gap, 'FREE_REL_SE_FLOOR', 1.0)\n")
    found = patches(src.replace("gap as G", "gap_angle as G") + "    G.A1_ROWS_FROM_ANGLE = False\n")
    assert found == {("gap", "TRIM_PERSIST"), ("gap_a1", "_free_level"), ("gap", "LAG_Z"), ("gap", "FREE_REL_SE_FLOOR"),
                     ("gap_angle", "A1_ROWS_FROM_ANGLE")}
    bad = unreached(found)
    assert any(x.startswith("gap.TRIM_PERSIST") for x in bad)
    assert any(x.startswith("gap.FREE_REL_SE_FLOOR: gap_angle.py") for x in bad)
    assert not any(x.startswith(("gap.LAG_Z", "gap_a1._free_level", "gap_angle.A1_ROWS")) for x in bad), bad
    assert unreached({("gap", "FREE_REL_SE_FLOOR"), ("gap_angle", "FREE_REL_SE_FLOOR")}) == []
    assert unreached({("gap", "A1_ROWS_FROM_ANGLE")}) != []


def test_no_module_split_from_gap_imports_it():
    """gap.py imports its fits; a fit importing gap.py back would be a cycle (and the split modules never import rclpy
    or the research code either)."""
    for module in SPLIT_FROM_GAP:
        tree = ast.parse((IDENTIFY / f"{module}.py").read_text())
        for n in ast.walk(tree):
            names = [n.module or ""] if isinstance(n, ast.ImportFrom) else \
                [a.name for a in n.names] if isinstance(n, ast.Import) else []
            for name in names:
                assert name != f"{PACKAGE}.gap" and not name.startswith(("rclpy", "jident_ros.research")), (module, name)
                if isinstance(n, ast.ImportFrom) and name == PACKAGE:
                    assert "gap" not in [a.name for a in n.names], module
