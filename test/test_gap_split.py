"""gap.py split by fit (issue 20): a test that patches a constant or function on a gap module patches the module that
reads it.

``from module import NAME`` binds a copy: after a function moved out of gap.py (to gap_a1.py, gap_angle.py, ...), a
``monkeypatch.setattr(gap, "NAME", ...)`` still succeeds where gap.py re-exports NAME, but no longer reaches the moved
function, and a test of a rule turned off passes without turning it off.  So every patch of a name on one of the
jident_ros.identify gap modules (``monkeypatch.setattr(module, "NAME", ...)`` or ``module.NAME = ...`` in test/*.py)
names a name that module reads (its own source by name, or another module of jident_ros.identify as module.NAME); a
name patched on gap that a module split from it reads too is patched there as well in the same file; and a constant of
gap.py or of a module split from it is read by name only in the module that defines it (another reader looks it up as
module.NAME, where one patch reaches every reader: gap_cross.CROSS_CHECK_Z).
"""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

TEST_DIR = Path(__file__).resolve().parent
IDENTIFY = TEST_DIR.parents[0] / "jident_ros" / "identify"
PACKAGE = "jident_ros.identify"
#: The modules split from gap.py (their functions were gap.py's and read its constants until the split).
SPLIT_FROM_GAP = ("gap_a1", "gap_angle", "gap_cross", "gap_interval", "gap_speed", "gap_steady", "gap_types",
                  "gap_width")


def _loads(tree: ast.AST) -> set:
    """The names a tree loads (ast.Name in a Load context: its code reads them)."""
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}


@lru_cache(maxsize=None)
def _trees() -> dict:
    """{module name: AST} of jident_ros/identify/*.py."""
    return {p.stem: ast.parse(p.read_text()) for p in sorted(IDENTIFY.glob("*.py"))}


@lru_cache(maxsize=None)
def _reads(module: str) -> frozenset:
    """The names read in a module of jident_ros.identify: those its code loads by name, and those any module of the
    package loads as ``module.NAME`` (``from jident_ros.identify import module``)."""
    out = set(_loads(_trees()[module]))
    for tree in _trees().values():
        aliases = {a for a, m in _aliases(tree).items() if m == {module}}
        out |= {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Load)
                and isinstance(n.value, ast.Name) and n.value.id in aliases}
    return frozenset(out)


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
    assert unreached({("gap", "FREE_REL_SE_FLOOR"), ("gap_angle", "FREE_REL_SE_FLOOR"), ("gap_a1", "FREE_REL_SE_FLOOR")}) == []
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


def test_a_constant_of_gap_or_its_fits_read_in_two_modules_is_looked_up_in_its_home():
    """``from module import NAME`` copies NAME: a constant of gap.py or of a module split from it that two modules of
    jident_ros.identify read, one of them by a from-import, would need a patch in each (CROSS_CHECK_Z, read by
    gap._cross_checked and gap_angle._anchored_angle, is looked up as gap_cross.CROSS_CHECK_Z by both).  Re-exports
    (gap.py imports the names the tests import from it) are not reads."""
    family = ("gap",) + SPLIT_FROM_GAP
    trees = _trees()
    home = {c: m for m in family for c in _defined(trees[m]) if c.isupper()}
    readers, by_copy = {}, set()
    for module, tree in trees.items():
        read = _loads(tree)
        for c in read & {c for c, m in home.items() if m == module}:
            readers.setdefault(c, set()).add(module)
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith(PACKAGE) \
                    and n.module.rsplit(".", 1)[-1] in family:
                for a in n.names:
                    if a.name in home and (a.asname or a.name) in read:
                        readers.setdefault(a.name, set()).add(module)
                        by_copy.add((a.name, module))
    for c, m in home.items():
        if c in _reads(m) - _loads(trees[m]):          # looked up as module.NAME somewhere
            readers.setdefault(c, set()).add(f"{m}.{c}")
    bad = [f"{c}: read in {sorted(readers[c])}, by a from-import in {mod}.py" for c, mod in sorted(by_copy)
           if len(readers[c]) > 1]
    assert not bad, "; ".join(bad)
    assert readers["CROSS_CHECK_Z"] == {"gap_cross.CROSS_CHECK_Z"}


def _defined(tree: ast.Module) -> set:
    """The names a module defines at its top level (assignments, functions, classes), not those it imports."""
    out = set()
    for node in tree.body:
        if isinstance(node, ast.Assign):
            out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out.add(node.target.id)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
    return out
