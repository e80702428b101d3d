"""gap.py split by fit (issue 20, stop 42): no module split from gap imports it back, and a constant of gap.py or of
a module split from it is read by name only in the module that defines it (another reader looks it up as
module.NAME, where one patch reaches every reader: gap_cross.CROSS_CHECK_Z).  That every test's patch reaches the
code that reads the name, for every module of the package, is test_patches.py's check.
"""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

from test_patches import defined

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
    home = {c: m for m in family for c in defined(trees[m]) if c.isupper()}
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
