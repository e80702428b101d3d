"""A test that turns a rule off must reach the code that reads the rule.

``monkeypatch.setattr(module, "NAME", ...)`` (or ``module.NAME = ...``) replaces the attribute of one module object.
It reaches the code that looks NAME up in that module: the module's own functions (reading NAME as a global) and other
modules reading ``module.NAME``.  It does not reach a module that did ``from module import NAME`` (a copy bound at
import), nor code that moved to another module and reads NAME there -- after stream/flank.py and identify/gap.py were
split into modules (stop 42), a patch left on the old module would still succeed (flank.py found its old names for
reading until stop 43; gap.py re-exports some) and change nothing, and the test of a rule turned off would pass
without turning it off.  Two checks over every test file:

* every patched (module, NAME) of jident_ros is read through that module: NAME is loaded by the module's own code, or
  some module of jident_ros reads it as ``module.NAME``;
* a constant (an UPPER_CASE rule or threshold) a test patches is imported by name at import time (``from module
  import NAME``) by no module of jident_ros that reads it: one patch on its home reaches every reader.  (A function a
  test replaces by a fake is that test's double; where else it is imported does not matter to it.)
"""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

TESTS = Path(__file__).resolve().parent
PKG = TESTS.parent / "jident_ros"


def defined(tree: ast.Module) -> set:
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


def _name(path: Path) -> str:
    return ".".join(("jident_ros",) + path.relative_to(PKG).with_suffix("").parts)


@lru_cache(maxsize=None)
def _trees() -> dict:
    """{dotted module name: AST} of every module of jident_ros (not __init__'s package names)."""
    return {_name(p): ast.parse(p.read_text()) for p in sorted(PKG.rglob("*.py")) if p.name != "__init__.py"}


def aliases(tree: ast.AST) -> dict:
    """{local name: dotted module} of the jident_ros modules a tree imports as modules (any scope):
    ``from jident_ros.x import mod [as a]`` and ``import jident_ros.x.mod as a``."""
    modules, out = _trees(), {}
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("jident_ros"):
            for a in n.names:
                if f"{n.module}.{a.name}" in modules:
                    out[a.asname or a.name] = f"{n.module}.{a.name}"
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.asname and a.name in modules:
                    out[a.asname] = a.name
    return out


def patches(tree: ast.AST) -> list:
    """(line, dotted module, NAME) of every setattr(alias, "NAME", ...), setattr("jident_ros....module.NAME", ...) and
    alias.NAME = ... on a jident_ros module in a test file."""
    mods, modules, out = aliases(tree), _trees(), []
    for n in ast.walk(tree):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "setattr" and n.args:
            first = n.args[0]
            if isinstance(first, ast.Name) and first.id in mods and len(n.args) > 1 \
                    and isinstance(n.args[1], ast.Constant) and isinstance(n.args[1].value, str):
                out.append((n.lineno, mods[first.id], n.args[1].value))
            elif isinstance(first, ast.Constant) and isinstance(first.value, str) and first.value.startswith("jident_ros."):
                module, name = first.value.rsplit(".", 1)
                if module in modules:
                    out.append((n.lineno, module, name))
        elif isinstance(n, (ast.Assign, ast.AugAssign)):
            for t in (n.targets if isinstance(n, ast.Assign) else [n.target]):
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id in mods:
                    out.append((n.lineno, mods[t.value.id], t.attr))
    return out


@lru_cache(maxsize=None)
def _reads() -> dict:
    """{dotted module: the names read through it}: those its own code loads by name, and those any jident_ros module
    loads as ``module.NAME``."""
    out = {m: {n.id for n in ast.walk(t) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
           for m, t in _trees().items()}
    for m, tree in _trees().items():
        # a name looked up at run time (globals()[...], getattr): a string constant naming it (not __all__'s: a
        # re-export listed there is not a read)
        exported = {id(c) for a in tree.body if isinstance(a, ast.Assign)
                    and any(isinstance(t, ast.Name) and t.id == "__all__" for t in a.targets) for c in ast.walk(a)}
        out[m] |= {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
                   and n.value.isidentifier() and id(n) not in exported}
        mods = aliases(tree)
        for n in ast.walk(tree):
            if isinstance(n, ast.Attribute) and isinstance(n.ctx, ast.Load) and isinstance(n.value, ast.Name) \
                    and n.value.id in mods:
                out[mods[n.value.id]].add(n.attr)
        # a from-import inside a function runs at call time: it takes the patched attribute, a read through it
        top = {id(n) for n in tree.body}
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and n.module in out and id(n) not in top:
                out[n.module] |= {a.name for a in n.names}
    return out


def copies(trees: dict, reads: dict) -> dict:
    """{(dotted module, NAME): [modules that do ``from module import NAME`` at import time and read NAME]} over
    ``trees`` ({dotted module: AST}; ``reads``: {module: names it reads}); a from-import inside a function runs at
    call time and takes a patched attribute."""
    out = {}
    for reader, tree in trees.items():
        for n in tree.body:
            if isinstance(n, ast.ImportFrom) and n.module in trees:
                for a in n.names:
                    if (a.asname or a.name) in reads[reader]:
                        out.setdefault((n.module, a.name), []).append(reader)
    return out


@lru_cache(maxsize=None)
def _imported_by_name() -> dict:
    return copies(_trees(), _reads())


def _all_patches() -> list:
    return [(p.name, line, mod, name) for p in sorted(TESTS.glob("*.py"))
            for line, mod, name in patches(ast.parse(p.read_text()))]


def test_every_patch_is_read_through_the_module_it_patches():
    found = _all_patches()
    bad = [f"{f}:{line}: {mod}.{name}" for f, line, mod, name in found if name not in _reads()[mod]]
    assert len(found) > 90 and not bad, "patched where no code reads it: " + ", ".join(bad)


def test_no_module_holds_a_copy_of_a_name_a_test_patches():
    bad = sorted({f"{mod}.{name}: imported by name in {', '.join(_imported_by_name()[(mod, name)])}"
                  for _, _, mod, name in _all_patches() if name.isupper() and (mod, name) in _imported_by_name()})
    assert not bad, "a patch on the home does not reach these copies: " + "; ".join(bad)


def test_the_checks_see_a_patch_left_behind_and_a_copy(tmp_path):
    """Plausible wrong changes: a patch left on flank.py for a rule that moved to flank_scan (flank.py does not read
    it), and a module importing a patched constant by name."""
    tree = ast.parse("from jident_ros.stream import flank, flank_scan\n"
                     "def test(monkeypatch):\n"
                     "    monkeypatch.setattr(flank, 'REBOUND_AFTER_ENTRY', False)\n"
                     "    monkeypatch.setattr(flank_scan, 'REBOUND_AFTER_ENTRY', False)\n")
    got = patches(tree)
    assert [(m, n) for _, m, n in got] == [("jident_ros.stream.flank", "REBOUND_AFTER_ENTRY"),
                                           ("jident_ros.stream.flank_scan", "REBOUND_AFTER_ENTRY")]
    assert "REBOUND_AFTER_ENTRY" not in _reads()["jident_ros.stream.flank"]
    assert "REBOUND_AFTER_ENTRY" in _reads()["jident_ros.stream.flank_scan"]
    # a copy: a module that imports a rule by name at import time keeps the value a patch of its home changes
    trees = {"jident_ros.a": ast.parse("RULE = True\n"),
             "jident_ros.b": ast.parse("from jident_ros.a import RULE\ndef f():\n    return RULE\n"),
             "jident_ros.c": ast.parse("def g():\n    from jident_ros.a import RULE\n    return RULE\n")}
    reads = {"jident_ros.a": set(), "jident_ros.b": {"RULE"}, "jident_ros.c": {"RULE"}}
    assert copies(trees, reads) == {("jident_ros.a", "RULE"): ["jident_ros.b"]}
