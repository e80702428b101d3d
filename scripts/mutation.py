#!/usr/bin/env python3
"""Mutation run over the core modules: does the test suite notice a plausible wrong change?

A small AST-based mutation runner (no new dependency: mutmut and cosmic-ray are not installed in the venv, and
the operators needed here fit in one file).  For every mutation site of a module it writes ONE one-line change
into a temporary copy of the source tree, runs the module's selected fast tests there (``pytest -x -q``, with a
timeout) and records the outcome:

* ``killed``     the tests failed (or the mutated module could not be imported);
* ``timeout``    the tests ran past ``--timeout`` (an endless loop, counted as detected);
* ``survived``   every selected test passed: a change the tests do not notice;
* ``equivalent`` survived, and listed with a written reason in ``scripts/mutation_equivalent.toml``
  (a mutation that cannot change behaviour; excluded from the score).

Score = (killed + timeout) / (mutants - equivalent), per module and overall.  The selected tests are a subset of
the suite (:data:`TESTS`), so a survivor may still be caught elsewhere: the score is a lower bound for the suite.

Operators (:class:`_Sites`):

* comparisons: ``<`` <-> ``<=``, ``>`` <-> ``>=``, ``==`` <-> ``!=``, ``is`` <-> ``is not``, ``in`` <-> ``not in``;
* arithmetic: ``+`` <-> ``-``, ``*`` <-> ``/`` (also in ``+=`` etc.);
* numbers: int n -> n + 1 (|n| <= 100), 0 <-> 1 (and 1 -> 2); float x -> 1.01 x, 2 x, x / 2 (0.0 -> 1.0);
* booleans: ``True`` <-> ``False``, ``and`` <-> ``or``, ``not x`` -> ``x``;
* returns: ``return a`` -> another simple value returned by the same function; a returned tuple with two
  neighbouring elements swapped;
* targeted (:data:`TARGETED`): the four mutations of issue 11 that survived the whole suite on main.

Not mutated: docstrings and other strings, f-string contents (error messages), annotations, and lines marked
``pragma: no cover``.  Each mutant is applied by splicing the mutated node's source text, so every other line of
the module is unchanged.

Usage (from the repository root, with the venv's python)::

    python scripts/mutation.py                       # all four modules, every mutant
    python scripts/mutation.py --module gap --max-mutants 60 --seed 1
    python scripts/mutation.py --list                # the mutants, not run
    nohup python scripts/mutation.py --json out/mutation.json > out/mutation.log 2>&1 &

``--jobs`` runs mutants in parallel in separate tree copies; keep it at 1 on a shared machine.
"""
from __future__ import annotations

import argparse
import ast
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from queue import Queue

import tomllib

REPO = Path(__file__).resolve().parents[1]

#: Module name -> (source file, selected tests: fastest and most specific first, so -x stops early).
MODULES = {
    "gap": "jident_ros/identify/gap.py",
    # gap.py's fits, split from it by fit (issue 20): the same selected tests as gap.py
    **{m: f"jident_ros/identify/{m}.py" for m in ("gap_a1", "gap_angle", "gap_cross", "gap_interval", "gap_speed",
                                                   "gap_steady", "gap_width")},
    "fusion": "jident_ros/identify/fusion.py",
    "khm": "jident_ros/method/khm.py",
    "khm_reference": "jident_ros/research/khm_reference.py",
    "detector": "jident_ros/stream/detector.py",
}
TESTS = {
    "gap": ["test/test_gap_rules.py", "test/test_gap_precision.py", "test/test_gap.py", "test/test_gap_second_drive.py"],
    **{m: ["test/test_gap_rules.py", "test/test_gap_precision.py", "test/test_gap.py", "test/test_gap_second_drive.py"]
       for m in ("gap_a1", "gap_angle", "gap_cross", "gap_interval", "gap_speed", "gap_steady", "gap_width")},
    "fusion": ["test/test_fusion_rules.py", "test/test_gap.py"],
    "khm": ["test/test_khm_rules.py", "test/test_khm.py", "test/test_method.py", "-k", "khm"],
    "khm_reference": ["test/test_khm_rules.py", "test/test_khm.py", "test/test_method.py", "-k", "khm"],
    "detector": ["test/test_detector_rules.py", "test/test_windowing.py"],
}

#: Targeted mutations (module, exact source text of the line, replacement, what it stands for, the function that
#: holds it or "" for anywhere in the module; the line must occur once there): the four one-line changes of
#: issue 11 that survived the whole suite on main.
TARGETED = [
    ("gap_speed", "j = 1.0 / kappa", "j = 1.002 / kappa", "0.2 % bias of the speed fit", "speed_fit"),
    ("gap_a1", "dof = n - 1", "dof = n - 2", "degrees of freedom of the anchored fit", "_method_anchored"),
    ("detector", "before[0] = True if self._prev_inside is None else self._prev_inside",
     "before[0] = False if self._prev_inside is None else self._prev_inside",
     "first sample of a stream taken as an entry", ""),
    ("fusion", "BETWEEN_Z = 3.0", "BETWEEN_Z = 2.0", "between-classes threshold at 2 standard errors", ""),
]

EQUIVALENT_FILE = REPO / "scripts" / "mutation_equivalent.toml"
IGNORE = shutil.ignore_patterns(".git", ".venv", ".venv-bench", "__pycache__", "build", "install", "log", "out",
                                "*.egg-info", ".pytest_cache", ".ruff_cache", "figures", "bench")


@dataclass
class Mutant:
    module: str
    file: str
    line: int
    start: tuple          # (line, col) of the replaced text, 1-based line, 0-based col
    end: tuple
    original: str         # the replaced source text
    replacement: str
    description: str
    source_line: str      # the original source line, stripped (the allowlist key)
    status: str = ""
    seconds: float = 0.0
    detail: str = ""

    @property
    def label(self) -> str:
        return f"{self.file}:{self.line}: {self.description}"


# --------------------------------------------------------------------------- finding mutation sites
_CMP_SWAP = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt, ast.Eq: ast.NotEq,
             ast.NotEq: ast.Eq, ast.Is: ast.IsNot, ast.IsNot: ast.Is, ast.In: ast.NotIn, ast.NotIn: ast.In}
_BIN_SWAP = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult}
_SYMBOL = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!=", ast.Is: "is",
           ast.IsNot: "is not", ast.In: "in", ast.NotIn: "not in", ast.Add: "+", ast.Sub: "-", ast.Mult: "*",
           ast.Div: "/", ast.And: "and", ast.Or: "or"}


def _copy(node):
    return ast.parse(ast.unparse(node), mode="eval").body if isinstance(node, ast.expr) else \
        ast.parse(ast.unparse(node)).body[0]


def _int_variants(n: int) -> list:
    if n == 0:
        return [1]
    if n == 1:
        return [0, 2]
    return [n + 1] if abs(n) <= 100 else []


def _float_variants(x: float) -> list:
    if x == 0.0:
        return [1.0]
    return [x * 1.01, x * 2.0, x / 2.0]


class _Sites(ast.NodeVisitor):
    """Collect (node, mutated node, description) for every operator site of a module."""

    def __init__(self):
        self.sites = []
        self._skip = set()
        self._function = []

    def _add(self, node, new, description):
        self.sites.append((node, new, description))

    def generic_visit(self, node):
        if id(node) in self._skip:
            return
        super().generic_visit(node)

    # strings, annotations and docstrings are not behaviour under test here
    def visit_JoinedStr(self, node):
        return

    def _skip_annotations(self, node):
        for a in [*node.args.posonlyargs, *node.args.args, *node.args.kwonlyargs, node.args.vararg,
                  node.args.kwarg]:
            if a is not None and a.annotation is not None:
                self._skip.add(id(a.annotation))
        if node.returns is not None:
            self._skip.add(id(node.returns))

    def visit_FunctionDef(self, node):
        self._skip_annotations(node)
        self._function.append(node)
        self._returns(node)
        self.generic_visit(node)
        self._function.pop()

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_AnnAssign(self, node):
        self._skip.add(id(node.annotation))
        self.generic_visit(node)

    def visit_Compare(self, node):
        for i, op in enumerate(node.ops):
            swap = _CMP_SWAP.get(type(op))
            if swap is not None:
                new = _copy(node)
                new.ops[i] = swap()
                self._add(node, new, f"'{_SYMBOL[type(op)]}' -> '{_SYMBOL[swap]}'")
        self.generic_visit(node)

    def _swap_arithmetic(self, node, suffix=""):
        """+ <-> -, * <-> / of a BinOp, or of an AugAssign (``suffix`` "=" in the description)."""
        swap = _BIN_SWAP.get(type(node.op))
        if swap is not None:
            new = _copy(node)
            new.op = swap()
            self._add(node, new, f"'{_SYMBOL[type(node.op)]}{suffix}' -> '{_SYMBOL[swap]}{suffix}'")
        self.generic_visit(node)

    def visit_BinOp(self, node):
        self._swap_arithmetic(node)

    def visit_AugAssign(self, node):
        self._swap_arithmetic(node, "=")

    def visit_BoolOp(self, node):
        swap = ast.Or if isinstance(node.op, ast.And) else ast.And
        new = _copy(node)
        new.op = swap()
        self._add(node, new, f"'{_SYMBOL[type(node.op)]}' -> '{_SYMBOL[swap]}'")
        self.generic_visit(node)

    def visit_UnaryOp(self, node):
        if isinstance(node.op, ast.Not):
            self._add(node, _copy(node.operand), "'not' removed")
        elif isinstance(node.op, ast.USub) and isinstance(node.operand, ast.Constant) \
                and type(node.operand.value) in (int, float):
            # a negative literal is one number: perturb it as such
            v = -node.operand.value
            variants = _int_variants(v) if isinstance(v, int) else _float_variants(v)
            for w in variants:
                self._add(node, ast.Constant(w), f"{v!r} -> {w!r}")
            return
        self.generic_visit(node)

    def visit_Constant(self, node):
        v = node.value
        if isinstance(v, bool):
            self._add(node, ast.Constant(not v), f"{v!r} -> {not v!r}")
        elif isinstance(v, int):
            for w in _int_variants(v):
                self._add(node, ast.Constant(w), f"{v!r} -> {w!r}")
        elif isinstance(v, float):
            for w in _float_variants(v):
                self._add(node, ast.Constant(w), f"{v!r} -> {w!r}")

    def visit_Expr(self, node):
        if isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            return   # a docstring
        self.generic_visit(node)

    def _returns(self, func):
        """Returns of this function (not of nested ones): neighbour values and swapped tuple elements."""
        rets = []
        stack = list(func.body)
        while stack:
            n = stack.pop()
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
                continue
            if isinstance(n, ast.Return) and n.value is not None:
                rets.append(n)
            stack.extend(ast.iter_child_nodes(n))
        simple = (ast.Name, ast.Constant, ast.Attribute)
        values = []
        for r in rets:
            text = ast.unparse(r.value)
            if isinstance(r.value, simple) and text not in values:
                values.append(text)
        for r in rets:
            text = ast.unparse(r.value)
            for other in values:
                if other != text:
                    self._add(r.value, ast.parse(other, mode="eval").body, f"return {text} -> return {other}")
                    break
            if isinstance(r.value, ast.Tuple) and len(r.value.elts) >= 2:
                elts = r.value.elts
                for i in range(len(elts) - 1):
                    a, b = ast.unparse(elts[i]), ast.unparse(elts[i + 1])
                    if a != b:
                        new = _copy(r.value)
                        new.elts[i], new.elts[i + 1] = new.elts[i + 1], new.elts[i]
                        self._add(r.value, new, f"return: elements {i} and {i + 1} swapped")
                        break


def _offset(lines_start, pos):
    line, col = pos
    return lines_start[line - 1] + col


def find_mutants(module: str, root: Path = REPO) -> list:
    path = MODULES[module]
    src = (root / path).read_text()
    tree = ast.parse(src)
    lines = src.splitlines(keepends=True)
    # character offsets of line starts (ast columns are utf-8 byte offsets: convert per line)
    finder = _Sites()
    finder.visit(tree)
    out = []

    def add(node, replacement, description):
        line = lines[node.lineno - 1]
        if "pragma: no cover" in line:
            return
        original = ast.get_source_segment(src, node)
        if original is None:
            return
        out.append(Mutant(module, path, node.lineno, (node.lineno, _char_col(lines, node.lineno, node.col_offset)),
                          (node.end_lineno, _char_col(lines, node.end_lineno, node.end_col_offset)),
                          original, replacement, description, line.strip()))

    for node, new, description in finder.sites:
        text = ast.unparse(new)
        if isinstance(node, ast.expr) and not isinstance(node, (ast.Constant, ast.Name)):
            text = f"({text})"
        elif isinstance(node, ast.Constant) or (isinstance(node, ast.UnaryOp) and isinstance(new, ast.Constant)):
            text = f"({text})" if text.startswith("-") else text
        add(node, text, description)
    for mod, original, replacement, description, function in TARGETED:
        if mod != module:
            continue
        span = range(len(lines))
        if function:
            defs = [f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == function]
            if len(defs) != 1:
                raise SystemExit(f"targeted mutation {description!r}: function {function!r} found {len(defs)} "
                                 f"times in {path}")
            span = range(defs[0].lineno - 1, defs[0].end_lineno)
        hits = [i for i in span if lines[i].strip() == original]
        if len(hits) != 1:
            where = f"{path}:{function}" if function else path
            raise SystemExit(f"targeted mutation {description!r}: {original!r} found {len(hits)} times in {where}")
        i = hits[0]
        col = lines[i].index(original)
        out.append(Mutant(module, path, i + 1, (i + 1, col), (i + 1, col + len(original)), original, replacement,
                          f"targeted: {description} ({original} -> {replacement})", original))
    out.sort(key=lambda m: (m.start, m.description))
    return out


def _char_col(lines, lineno, byte_col):
    return len(lines[lineno - 1].encode()[:byte_col].decode())


def apply(src: str, m: Mutant) -> str:
    lines = src.splitlines(keepends=True)
    starts = [0]
    for ln in lines:
        starts.append(starts[-1] + len(ln))
    a, b = _offset(starts, m.start), _offset(starts, m.end)
    if src[a:b] != m.original:
        raise RuntimeError(f"{m.label}: source text moved ({src[a:b]!r} != {m.original!r})")
    return src[:a] + m.replacement + src[b:]


# --------------------------------------------------------------------------- equivalent mutants
def load_equivalent(path: Path = EQUIVALENT_FILE) -> list:
    if not path.exists():
        return []
    entries = tomllib.loads(path.read_text()).get("equivalent", [])
    for e in entries:
        missing = [k for k in ("file", "line", "mutation", "reason") if not str(e.get(k, "")).strip()]
        if missing:
            raise SystemExit(f"{path}: an entry without {missing[0]!r}: {e}")
    return entries


def equivalent_reason(m: Mutant, entries: list) -> str | None:
    for e in entries:
        if e["file"] == m.file and e["line"].strip() == m.source_line and e["mutation"] == m.description:
            return e["reason"]
    return None


# --------------------------------------------------------------------------- running
def make_tree(dest: Path) -> Path:
    shutil.copytree(REPO, dest, ignore=IGNORE, dirs_exist_ok=True)
    return dest


def run_tests(tree: Path, module: str, timeout_s: float, python: str) -> tuple:
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONDONTWRITEBYTECODE="1", PYTHONHASHSEED="0")
    cmd = [python, "-B", "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--no-header", *TESTS[module]]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)   # the pytest process group this runner started
        proc.communicate()
        return "timeout", time.monotonic() - t0, f"> {timeout_s:g} s"
    dt = time.monotonic() - t0
    if proc.returncode == 0:
        return "survived", dt, ""
    failed = [ln for ln in out.splitlines() if ln.startswith(("FAILED", "ERROR"))]
    return "killed", dt, (failed[0] if failed else out.strip().splitlines()[-1] if out.strip() else "")[:200]


def run_mutant(m: Mutant, original: str, tree: Path, timeout_s: float, python: str) -> Mutant:
    """Write the mutant into the tree copy, run its tests, put the original back."""
    target = tree / m.file
    try:
        mutated = apply(original, m)
        compile(mutated, m.file, "exec")
    except SyntaxError as exc:
        m.status, m.detail = "invalid", f"does not compile: {exc}"
        return m
    target.write_text(mutated)
    try:
        m.status, m.seconds, m.detail = run_tests(tree, m.module, timeout_s, python)
    finally:
        target.write_text(original)
    return m


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--module", action="append", choices=sorted(MODULES),
                    help="module(s) to mutate (repeatable; default: all four)")
    ap.add_argument("--max-mutants", type=int, default=0,
                    help="sample at most this many mutants per module (0: all); targeted ones are always kept")
    ap.add_argument("--seed", type=int, default=1, help="seed of the sample (default 1)")
    ap.add_argument("--jobs", type=int, default=1, help="mutants run in parallel (default 1: a shared machine)")
    ap.add_argument("--timeout", type=float, default=0.0,
                    help="seconds per mutant (default: 4 x the unmutated run + 20 s)")
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs pytest")
    ap.add_argument("--list", action="store_true", help="list the mutants and exit")
    ap.add_argument("--json", type=Path, help="write every mutant's outcome to this file")
    args = ap.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))    # kill <pid>: the temporary trees are removed

    modules = args.module or list(MODULES)
    equivalent = load_equivalent()
    chosen = {}
    for mod in modules:
        ms = find_mutants(mod)
        if args.max_mutants and len(ms) > args.max_mutants:
            targeted = [m for m in ms if m.description.startswith("targeted:")]
            rest = [m for m in ms if not m.description.startswith("targeted:")]
            k = max(args.max_mutants - len(targeted), 0)
            picked = random.Random(f"{args.seed}:{mod}").sample(rest, k)
            ms = sorted(targeted + picked, key=lambda m: (m.start, m.description))
        chosen[mod] = ms
    if args.list:
        for mod, ms in chosen.items():
            for m in ms:
                print(f"{m.label}    [{m.original!r} -> {m.replacement!r}]")
            print(f"# {mod}: {len(ms)} mutants")
        return 0

    sources = {mod: (REPO / MODULES[mod]).read_text() for mod in chosen}   # as copied into the trees
    t_start = time.monotonic()
    jobs = max(1, int(args.jobs))
    with tempfile.TemporaryDirectory(prefix="jident-mutation-") as tmp:
        trees = Queue()
        for j in range(jobs):
            trees.put(make_tree(Path(tmp) / f"tree{j}"))
        # the unmutated tests must pass (and give the timeout's scale)
        base = {}
        probe = trees.get()
        for mod in chosen:
            status, dt, detail = run_tests(probe, mod, 600.0, args.python)
            if status != "survived":
                print(f"{mod}: the selected tests fail without any mutation ({status}: {detail}); fix that first")
                return 2
            base[mod] = dt
            print(f"{mod}: {len(chosen[mod])} mutants; unmutated tests pass in {dt:.1f} s "
                  f"({' '.join(TESTS[mod])})", flush=True)
        trees.put(probe)

        def one(m):
            tree = trees.get()
            try:
                timeout = args.timeout or 4.0 * base[m.module] + 20.0
                run_mutant(m, sources[m.module], tree, timeout, args.python)
            finally:
                trees.put(tree)
            reason = equivalent_reason(m, equivalent) if m.status == "survived" else None
            if reason is not None:
                m.status, m.detail = "equivalent", reason
            return m

        todo = [m for ms in chosen.values() for m in ms]
        done = 0
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            for m in pool.map(one, todo):
                done += 1
                print(f"[{done}/{len(todo)}] {m.status:10s} {m.seconds:5.1f} s  {m.label}", flush=True)
    elapsed = time.monotonic() - t_start

    print()
    print("| module | mutants | killed | timeout | survived | equivalent | invalid | score |")
    print("|---|---|---|---|---|---|---|---|")
    totals = {"n": 0, "killed": 0, "timeout": 0, "survived": 0, "equivalent": 0, "invalid": 0}
    for mod, ms in chosen.items():
        c = {s: sum(m.status == s for m in ms) for s in ("killed", "timeout", "survived", "equivalent", "invalid")}
        c["n"] = len(ms)
        for k in totals:
            totals[k] += c[k]
        print(_row(f"`{MODULES[mod]}`", c))
    print(_row("**all**", totals))
    print(f"\n{elapsed / 60:.1f} min, {len(todo)} mutants, jobs {jobs}")
    survivors = [m for ms in chosen.values() for m in ms if m.status == "survived"]
    if survivors:
        print(f"\nSurvivors ({len(survivors)}):")
        for m in survivors:
            print(f"  {m.label}    [{m.original!r} -> {m.replacement!r}]")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"elapsed_s": elapsed, "argv": sys.argv[1:],
                                         "mutants": [asdict(m) for ms in chosen.values() for m in ms]}, indent=1))
    return 0


def _row(name, c):
    scored = c["n"] - c["equivalent"] - c["invalid"]
    det = c["killed"] + c["timeout"]
    score = f"{det}/{scored} = {100.0 * det / scored:.1f} %" if scored else "–"
    return (f"| {name} | {c['n']} | {c['killed']} | {c['timeout']} | {c['survived']} | {c['equivalent']} | "
            f"{c['invalid']} | {score} |")


if __name__ == "__main__":
    sys.exit(main())
