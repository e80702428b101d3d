"""The package's layers (DEVELOPERS.md, issue 11, 19): no import cycles, an acyclic layer table, the runtime (nodes,
``jident diagnose``/``trend``/``salvage``/``build-patterns``) imports no research code (jident_ros/research/),
nothing but ``cli`` and research imports the nodes or cli, the core never imports rclpy, and imports stand at
the top of a module except where an optional dependency (rclpy and the ROS message packages, matplotlib) must
stay optional.

The import graph is read from the source with ``ast`` (nothing is imported), so a violation is named
with its file and line.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "jident_ros"

#: Top-level packages whose modules may be imported lazily inside a function (optional dependencies).
OPTIONAL = {"rclpy", "rcl_interfaces", "std_msgs", "sensor_msgs", "diagnostic_msgs", "rosgraph_msgs",
            "builtin_interfaces", "lifecycle_msgs", "diagnostic_updater", "launch", "launch_ros",
            "ament_index_python", "matplotlib", "tqdm",
            "zstandard", "lz4",  # compression codecs of the optional mcap extra
            "motulator"}  # the vector drive's simulator (optional extra 'zoo')
#: Modules that import (some of) the package lazily, and why (issue 23: a command starts at once).
LAZY = {
    "jident_ros.cli.main": "the dispatcher: each subcommand imports only what it runs",
    "jident_ros.config": "the method config's class (method.pipeline imports scipy.fft): `jident simulate` "
                         "reads the system config only",
    "jident_ros.identify.trend_maths": "scipy.optimize (brentq) once per CUSUM threshold design: ~14 MiB of a "
                                       "node's memory that the nodes need only then (issue 25)",
}
#: Of those, the ROS client library and messages: never imported below nodes and cli.
ROS = OPTIONAL - {"ament_index_python", "matplotlib", "tqdm",
            "zstandard", "lz4", "motulator"}  # the last two: compression codecs of the optional mcap extra
#: Layers (first package part below jident_ros). A module may import its own layer and those listed.
ALLOWED = {
    "sim": set(),
    "stream": {"sim"},
    "method": {"sim", "stream", "resources"},
    "identify": {"sim", "stream", "method", "config", "resources"},
    "evaluation": {"sim", "stream", "method", "identify", "config", "resources", "second_drive", "vector_drive",
                   "cli"},   # cli: evaluation/zoo.py diagnoses through jident diagnose's own function
    "bag": {"sim", "stream"},
    "second_drive": set(),
    "research": set(),          # jident_ros/research/__init__.py
    "khm_reference": set(),
    "vector_drive": {"second_drive"},   # its writers
    "nodes": {"sim", "stream", "method", "identify", "bag", "config", "resources", "parameters"},
    "cli": {"sim", "stream", "method", "identify", "bag", "nodes", "config", "resources", "parameters"},
    # the `jident` command's dispatcher: every subcommand, the research ones (evaluate) too
    "entry": {"sim", "stream", "method", "identify", "evaluation", "bag", "nodes", "config", "resources",
              "parameters", "second_drive", "cli"},
    "config": {"sim", "method", "resources"},
    "parameters": set(),
    "resources": set(),
    "__init__": set(),
}


#: Modules that are a layer of their own: the `jident` entry point (dispatches every subcommand).
ENTRY = {"jident_ros.cli.main", "jident_ros.cli.__main__"}


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path):
    """(imported module, line, inside a function) for every import of ``path``; an import guarded by
    ``try: ... except ImportError`` counts as a top-level one (the optional dependency is handled)."""
    tree = ast.parse(path.read_text())
    mod = module_name(path)
    is_pkg = path.name == "__init__.py"
    out = []

    def visit(node, in_func):
        for child in ast.iter_child_nodes(node):
            nested = in_func or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Try) and any(h.type is not None and "ImportError" in ast.dump(h.type)
                                                  for h in child.handlers):
                nested = False   # guarded: an optional dependency may be missing
            if isinstance(child, ast.Import):
                out.extend((a.name, child.lineno, in_func) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = mod.split(".")
                    if not is_pkg:
                        base = base[:-1]
                    base = base[:len(base) - (child.level - 1)]
                    target = ".".join(base + ([child.module] if child.module else []))
                else:
                    target = child.module
                names = [f"{target}.{a.name}" for a in child.names]
                # "from jident_ros.x import y" imports module x.y when y is a submodule
                for n in names:
                    sub = PKG.parent / (n.replace(".", "/") + ".py")
                    subpkg = PKG.parent / n.replace(".", "/") / "__init__.py"
                    out.append((n if sub.exists() or subpkg.exists() else target, child.lineno, in_func))
            visit(child, nested)

    visit(tree, False)
    return out


def _modules():
    return {module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _layer(mod: str) -> str:
    """The first package part below jident_ros; below jident_ros.research, the part below that (research's own
    packages are layers of their own: evaluation, second_drive, vector_drive, khm_reference)."""
    if mod in ENTRY:
        return "entry"
    parts = mod.split(".")
    if len(parts) > 2 and parts[1] == "research":
        return parts[2]
    return parts[1] if len(parts) > 1 else "__init__"


def test_no_import_cycles():
    mods = _modules()
    graph = {m: sorted({i for i, _, _ in _imports(p) if i in mods and i != m}) for m, p in mods.items()}
    seen, stack, cycles = {}, [], []

    def dfs(m):
        seen[m] = 1
        stack.append(m)
        for n in graph[m]:
            if seen.get(n) == 1:
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in seen:
                dfs(n)
        stack.pop()
        seen[m] = 2

    for m in graph:
        if m not in seen:
            dfs(m)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_layers():
    bad = []
    for m, p in _modules().items():
        own = _layer(m)
        for imp, line, _ in _imports(p):
            if not imp.startswith("jident_ros.") and imp != "jident_ros":
                continue
            other = _layer(imp)
            if other in (own, "__init__", "parameters") or other in ALLOWED.get(own, set()):
                continue
            bad.append(f"{p.relative_to(PKG.parent)}:{line} ({own}) imports {imp} ({other})")
    assert not bad, "\n".join(bad)


def test_core_never_imports_rclpy():
    bad = [f"{p.relative_to(PKG.parent)}:{line} imports {imp}"
           for m, p in _modules().items() if _layer(m) not in ("nodes", "cli")
           for imp, line, _ in _imports(p) if imp.split(".")[0] in ROS]
    assert not bad, "\n".join(bad)


def test_imports_at_the_top_unless_optional():
    bad = [f"{p.relative_to(PKG.parent)}:{line} imports {imp} inside a function"
           for m, p in _modules().items() for imp, line, inside in _imports(p)
           if inside and imp.split(".")[0] not in OPTIONAL and m not in LAZY]
    assert not bad, f"{len(bad)} imports inside functions:\n" + "\n".join(bad)


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layer_table_names_real_packages(layer):
    # a typo in ALLOWED would silently allow nothing or everything
    assert layer in ("__init__", "entry") or any((base / layer).is_dir() or (base / f"{layer}.py").exists()
                                      for base in (PKG, PKG / "research")), layer


def test_layer_table_is_acyclic():
    # no pair of layers may import each other, directly or through others: the table is an order, no exceptions
    seen, stack, cycles = {}, [], []

    def dfs(layer):
        seen[layer] = 1
        stack.append(layer)
        for other in sorted(ALLOWED.get(layer, ())):
            if seen.get(other) == 1:
                cycles.append(" -> ".join(stack[stack.index(other):] + [other]))
            elif other not in seen:
                dfs(other)
        stack.pop()
        seen[layer] = 2

    for layer in sorted(ALLOWED):
        if layer not in seen:
            dfs(layer)
    assert not cycles, "layers that import each other: " + "; ".join(cycles)


#: What runs beside a drive: the nodes and `jident diagnose` / `trend` / `salvage` / `build-patterns`.
#: (cli.main, the one `jident` entry point, also runs `jident evaluate`: its research imports are its own.)
RUNTIME_ROOTS = ("jident_ros.nodes", "jident_ros.cli.offline", "jident_ros.cli.trend", "jident_ros.cli.salvage",
                 "jident_ros.cli.calibration")
#: Research: the evaluation, the validation drive models, the reference implementations.
RESEARCH = "jident_ros.research"


def runtime_closure() -> dict:
    """{module: the module that imported it first} of every jident_ros module the runtime roots import,
    directly or not, at the top or inside a function."""
    mods = _modules()
    seen = {m: None for m in mods if m == RUNTIME_ROOTS[0] or m.startswith(RUNTIME_ROOTS[0] + ".")
            or m in RUNTIME_ROOTS[1:]}
    todo = list(seen)
    while todo:
        m = todo.pop()
        for imp, _, _ in _imports(mods[m]):
            while imp not in mods and "." in imp:      # "from package import name": the package
                imp = imp.rsplit(".", 1)[0]
            if imp in mods and imp not in seen:
                seen[imp] = m
                todo.append(imp)
    return seen


def test_the_runtime_imports_no_research_code():
    closure = runtime_closure()
    assert set(RUNTIME_ROOTS[1:]) <= set(closure) and "jident_ros.nodes.diagnostic" in closure
    bad = []
    for m in closure:
        if m == RESEARCH or m.startswith(RESEARCH + "."):
            chain, cur = [m], closure[m]
            while cur is not None:
                chain.append(cur)
                cur = closure[cur]
            bad.append(" <- ".join(chain))
    assert not bad, "the runtime imports research code:\n" + "\n".join(bad)


def test_the_runtime_check_sees_a_research_import(monkeypatch):
    # the check itself: a runtime module that imported the evaluation would be caught
    real = _imports

    def with_research(path):
        out = real(path)
        if path.name == "offline.py" and path.parent.name == "cli":
            out.append(("jident_ros.research.evaluation.verdicts", 1, True))
        return out
    monkeypatch.setitem(globals(), "_imports", with_research)
    assert "jident_ros.research.evaluation.verdicts" in runtime_closure()
