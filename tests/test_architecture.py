"""The package's import graph: dependencies point one way, down the pipeline, and nothing imports in a circle.

Every ``import`` in ``src/planeray`` is read with :mod:`ast` (module level *and* inside
functions, where cycles used to hide), resolved to a planeray module, and checked:

* no import cycle between modules;
* no *upward* import between the package's top-level units: a unit may import only
  units listed before it in :data:`LAYERS` (capture -> storage -> models -> scenes ->
  devices -> demultiplexing -> analysis -> figures -> experiments -> front ends).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "planeray"

#: Top-level units, lowest first.  A unit may import only units before it.
LAYERS = [
    "errors",
    "_extras",
    "_validate",
    "_progress",
    "goodness",
    "timing",
    "medium",
    "optical_data",
    "optical_data_skin",
    "linesweep",
    "_bandsum",
    "transport",
    "stack",
    "camera",
    "io",
    "resumable",
    "calibration",
    "mc",
    "kernels",
    "render",
    "scenes",
    "projector",
    "devices",
    "acquire",
    "rig",
    "demux",
    "design",
    "synthesis",
    "profiles",
    "classify",
    "materials",
    "baselines",
    "skin",
    "pulse",
    "live",
    "study",
    "figures",
    "experiments",
    "viewer",
    "_console",
    "demo",
    "cli",
    "__main__",  # python -m planeray: the command line
    "_jit",  # compiles the kernels of every engine (make kernels): above them all, imported by none
]


#: The front ends may use the front door (``import planeray as pr``), as a user would.
FRONT_ENDS = {"demo", "cli"}


def _modules() -> dict[str, Path]:
    mods = {}
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The planeray module that ``import name`` runs (the longest existing prefix)."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in MODULES:
            return cand
        parts.pop()
    return None


def _imports(module: str, path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    package = module if is_pkg else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "planeray":
                    found.add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            if prefix.split(".")[0] != "planeray":
                continue
            subs = {f"{prefix}.{a.name}" for a in node.names} & MODULES.keys()
            found |= subs  # ``from . import x`` may name a submodule
            if len(subs) < len(node.names):
                found.add(prefix)
    return {m for m in (_resolve(n) for n in found) if m is not None and m != module}


@pytest.fixture(scope="module")
def graph():
    """planeray's import graph (parsed when a test needs it, not at collection by every pytest worker)."""
    return {m: _imports(m, p) for m, p in MODULES.items()}


def _unit(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in MODULES} - {None}
    assert units <= set(LAYERS), f"add {sorted(units - set(LAYERS))} to LAYERS"


def test_no_upward_import(graph):
    rank = {u: i for i, u in enumerate(LAYERS)}
    bad = []
    for mod, deps in graph.items():
        u = _unit(mod)
        if u is None:  # planeray/__init__.py: the front door may import anything
            continue
        for dep in deps:
            d = _unit(dep)
            if d is None:
                if u not in FRONT_ENDS:
                    bad.append(f"{mod} -> {dep} (the top-level package)")
            elif d != u and rank[d] > rank[u]:
                bad.append(f"{mod} -> {dep} ({u} is below {d})")
    assert not bad, "upward imports:\n" + "\n".join(sorted(bad))


def test_no_import_cycle(graph):
    # Tarjan's strongly connected components over the module graph.
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


@pytest.mark.parametrize(
    ("module", "dep"),
    [("planeray.demo", "planeray.cli"), ("planeray.kernels", "planeray.mc.engine")],
)
def test_the_checker_sees_imports_inside_functions(module, dep, tmp_path):
    # A test that cannot fail is a defect: the parser must find a function-level import.
    src = tmp_path / "m.py"
    src.write_text(f"def f():\n    from {dep} import x\n")
    assert _resolve(dep) in _imports(module, src)


#: Units that analyse captures: they may not import the scenes (the ground truth a simulation knows and a
#: capture never has). What they compare against is passed in (``device.scene``, ``Scene.effect_masks``)
#: or the comparison lives above them (``experiments``).
GROUND_TRUTH_FREE = {"demux", "synthesis", "profiles", "classify", "materials", "baselines"}


def test_analysis_does_not_reach_for_the_scenes_ground_truth(graph):
    bad = sorted(
        f"{mod} -> {dep}"
        for mod, deps in graph.items()
        if _unit(mod) in GROUND_TRUTH_FREE
        for dep in deps
        if _unit(dep) == "scenes"
    )
    assert not bad, "analysis importing the scenes (pass the ground truth in):\n" + "\n".join(bad)


#: Longest function body (lines, its docstring and its signature's option declarations aside) in ``cli/``:
#: a command parses its options, calls one library function and prints; the work lives in the library.
MAX_CLI_BODY_LINES = 60


def _body_lines(fn: ast.FunctionDef) -> int:
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant):
        body = body[1:]  # the docstring
    return body[-1].end_lineno - body[0].lineno + 1 if body else 0


def test_the_command_line_is_thin():
    long = sorted(
        (n, f"{path.relative_to(SRC)}:{fn.lineno} {fn.name}")
        for path in sorted((SRC / "cli").glob("*.py"))
        for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef) and (n := _body_lines(fn)) > MAX_CLI_BODY_LINES
    )
    assert not long, "command-line functions doing a library's work (move it to the library):\n" + "\n".join(
        f"{n} lines: {where}" for n, where in long
    )
