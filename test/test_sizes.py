"""Sizes of the runtime code (issue 19): no function longer than 80 lines or taking more than 8 parameters
(``self``/``cls`` not counted), no file longer than 600 lines, research code (jident_ros/research/) aside.
What is over today is named below with its reason; a new function or file over the limits fails."""
from __future__ import annotations

import ast
from pathlib import Path

from test_patches import defined

PKG = Path(__file__).resolve().parents[1] / "jident_ros"
MAX_FUNCTION_LINES, MAX_PARAMETERS, MAX_FILE_LINES = 80, 8, 600

#: "path:function" or "path" -> why it is over the limit (and whose lane it is in this session's split).
EXCEPTIONS = {
    # dataclass-like constructors: one keyword per documented option, all with defaults
    "bag/drive_replay.py:__init__": "9 options of the replay (callables for the caller's errors); ros helper's file",
    "bag/rotating_recorder.py:__init__": "12 options = the diagnostic node's recorder parameters; ros helper's file",
    "stream/dynamics.py:__init__": "the detector's tuning constants as keywords; detector helper's file",
    "stream/flank.py:__init__": "the detector's tuning constants as keywords; detector helper's file",
    "stream/flank_free.py:single_mass_run": "detector helper's file (issue 20)",
    "stream/flank_delta.py:estimate_width": "detector helper's file (issue 20)",
    # the estimator (issue 20): gap.py split by fit (gap_a1, gap_angle, gap_speed, ...); its choice still one function
    "identify/gap.py:estimate_inertia": "the public entry: _estimate_inertia's arguments, passed through",
    "identify/gap.py:_estimate_inertia": "11 parameters: estimate_inertia's, passed on (one function per fit since the "
                                          "split: gap_a1's, gap_angle's and gap_speed's _method_*)",
    "identify/gap_a1.py:_joint_fit": "the a1 + m_el errors-in-variables fit in one piece (its algebra reads as one)",
    "stream/flank.py:_track": "the flank state machine's one transition function (issue 20 added the spike and "
                              "same-flank states); the file's split left it whole, the state machine flank.py keeps",
    "identify/verdict.py:input_refusal": "9: the window's five header fields + config, policy, nominal, width_unknown; "
                                         "estimator helper's file",
    # numerics kernels
    "method/khm.py:khm_fit_batch": "9: the histograms (3) + the KHM options of MethodConfig (n_clusters, p, max_iter, "
                                   "tol) + the two numerics switches, all keywords with defaults",
    "method/patterns.py:identify_window": "9: the window (3), library, method, p + the research variants "
                                          "(signals, width_mode, system) as keywords with defaults",
    "sim/simulate.py:_rk4_window": "10: the integrator's state arrays; speed helper's file (single-case fast path)",
    "sim/simulate.py:_rk4_window_one": "98 lines, 10 parameters: _rk4_window's arguments; the one-case RK4 on 10 "
                                       "unpacked floats (not packing them is the speed, issue 23)",
    "sim/simulate.py:rhs": "12 parameters: the 10 state floats + 2 supply values of _rk4_window_one's kernel, "
                           "passed unpacked for speed (issue 23)",
    # command-line tools: argument tables and scripted runs
    "cli/demo.py:_listen": "the demo's DDS listener (a dev tool, not beside a drive)",
    "cli/demo.py:run": "the demo's script (a dev tool, not beside a drive)",
    "cli/scenario.py:write_scenario_recording": "the test-run writer of `jident simulate --scenario`; trend helper's",
    "sim/scenarios.py:wear_scenario": "11: the wear scenario's options (`jident simulate --scenario wear` flags)",
}


def _runtime_files():
    return [p for p in sorted(PKG.rglob("*.py")) if "research" not in p.relative_to(PKG).parts]


def _measure(rel: str, text: str) -> dict:
    """{"rel" or "rel:function": what is over} of one file's source."""
    out = {}
    n = len(text.splitlines())
    if n > MAX_FILE_LINES:
        out[rel] = f"{n} lines"
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs] + [x for x in (a.vararg, a.kwarg) if x]
            if a.args and a.args[0].arg in ("self", "cls"):
                params = params[1:]
            lines = node.end_lineno - node.lineno + 1
            if lines > MAX_FUNCTION_LINES or len(params) > MAX_PARAMETERS:
                out[f"{rel}:{node.name}"] = f"{lines} lines, {len(params)} parameters"
    return out


def _over_the_limits() -> dict:
    out = {}
    for path in _runtime_files():
        out.update(_measure(str(path.relative_to(PKG)), path.read_text()))
    return out


def test_runtime_functions_and_files_within_the_limits():
    over = _over_the_limits()
    new = {k: v for k, v in over.items() if k not in EXCEPTIONS}
    assert not new, "over the limits (80 lines, 8 parameters, 600 lines per file): " + "; ".join(
        f"{k} ({v})" for k, v in sorted(new.items()))


def test_the_limits_are_measured():
    # plausible wrong changes: an off-by-one at a limit, self counted, a limit that never trips
    body = "    x = 1\n" * 79
    assert _measure("a.py", f"def f():\n{body}") == {}                                    # 80 lines
    assert "a.py:f" in _measure("a.py", f"def f():\n{body}    x = 2\n")                   # 81 lines
    assert _measure("a.py", "class C:\n    def m(self, a, b, c, d, e, f, g, h):\n        pass\n") == {}
    assert "a.py:m" in _measure("a.py", "def m(a, b, c, d, e, f, g, h, *, i=0):\n    pass\n")
    assert "a.py" in _measure("a.py", "x = 1\n" * 601) and "a.py" not in _measure("a.py", "x = 1\n" * 600)
    assert all(not k.startswith("research") for k in _over_the_limits())


def test_every_exception_is_still_over_the_limits():
    """A debt paid is struck off the list: an exception that is within the limits again (stop 41: free_angle_fit, its
    scan and fits moved into classes) would let the next change grow it back past them unnoticed."""
    over = _over_the_limits()
    stale = sorted(k for k in EXCEPTIONS if k not in over)
    assert not stale, "within the limits again, strike off EXCEPTIONS: " + ", ".join(stale)


# ---------------------------------------------------------------- the flank detector's modules (stream/flank*.py)
STREAM = PKG / "stream"


def _flank_modules() -> dict:
    """{module name: its AST} of jident_ros/stream/flank.py and the modules split off it (flank_*.py)."""
    return {p.stem: ast.parse(p.read_text()) for p in sorted(STREAM.glob("flank*.py"))}


def _family_imports(tree: ast.Module, modules) -> list:
    """(module, name) of every ``from jident_ros.stream.<flank module> import name`` in a tree."""
    return [(node.module.rsplit(".", 1)[1], a.name) for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("jident_ros.stream.")
            and node.module.rsplit(".", 1)[1] in modules for a in node.names]


def test_each_flank_constant_has_one_home_that_every_reader_looks_up():
    """stream/flank.py was split (its models and rules into flank_*.py; since stop 43 flank.py no longer finds their names):
    a constant patched where it is not read changes nothing, silently.  So each UPPER_CASE constant is defined in one
    flank module only, no flank module imports another's constant by name (a reader elsewhere looks it up as
    ``module.NAME``, where a patch reaches it), and none imports flank.py (no cycle)."""
    modules = _flank_modules()
    homes = {}
    for name, tree in modules.items():
        for const in (n for n in defined(tree) if n.isupper()):
            homes.setdefault(const, []).append(name)
    assert not {c: m for c, m in homes.items() if len(m) > 1}, "constants defined twice"
    by_name = [(name, mod, n) for name, tree in modules.items() for mod, n in _family_imports(tree, modules)]
    assert not [x for x in by_name if x[2].isupper()], "a flank constant imported by name (read it as module.NAME)"
    assert not [x for x in by_name if x[1] == "flank"], "a flank_* module imports flank.py (a cycle)"
    assert "REBOUND_MAX_SHARE" in homes and "FlankDetector" in defined(modules["flank"])
