"""No module imports a layer above it: the package's layer rule, checked on every import statement (module level
and inside functions alike) by reading the source, so a lazy import cannot hide an upward dependency. Inside a
package no two modules import each other, however far round (a lazy import cannot hide a cycle either), and
only report/ draws: computation never imports report/ or matplotlib."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "flowchart2sdnn"

#: bottom -> top; a module may import its own package and anything of a lower rank, nothing else of ours.
RANKS = {
    "_version": 0, "errors": 0, "notices": 0, "tables": 0, "strictjson": 0,
    "rules": 0,  # the rule book: every threshold's one default (imports nothing)
    "threads": 0,  # one BLAS thread around the library's computations (imports nothing of ours)
    "views": 0,  # the registry report/ fills for results that draw on request (Identification.compare(plot=))
    "atomic": 1, "expr": 1, "executors": 1,
    "diagram": 2, "fit": 2, "data": 2,
    "analysis": 3, "network": 3,
    "compiler": 4,
    "simulate": 4.5,  # the continuous oracle and the bench: identify measures its discretization floor with it
    "identify": 5,
    "diagnose": 6,
    "batch": 7,
    "report": 7.5,  # text, pages and figures of every command, from the typed results of everything below
    "api": 8,
    "__init__": 8.5,  # the public names, over the api they come from
    "cli": 9,
    "__main__": 10,
}


def _unit(module: str) -> str:
    """flowchart2sdnn.identify.offline.run -> identify; flowchart2sdnn (the package's __init__) -> __init__."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _module_name(path: Path, package: Path = PACKAGE) -> str:
    rel = path.relative_to(package.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1] if len(parts) > 1 else parts
    return ".".join(parts)


def _imports(path: Path, root: Path = PACKAGE) -> list[tuple[int, str]]:
    """(line, absolute module) of every import of ours in the file."""
    name = _module_name(path, root)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    if path.name == "__init__.py" and name == "flowchart2sdnn.__init__":
        package = ["flowchart2sdnn"]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "flowchart2sdnn"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "flowchart2sdnn":
                continue
            if target == "flowchart2sdnn":  # `from . import identify`: the names are modules or attributes
                out += [(node.lineno, f"flowchart2sdnn.{a.name}" if a.name in RANKS else "flowchart2sdnn")
                        for a in node.names]
            else:
                out.append((node.lineno, target))
    return out


FILES = sorted(PACKAGE.rglob("*.py"))


def test_every_package_has_a_rank():
    units = {_unit(_module_name(f)) if f.name != "__init__.py" or f.parent != PACKAGE else "__init__" for f in FILES}
    assert units <= set(RANKS), f"give these a rank in RANKS: {sorted(units - set(RANKS))}"


def _violations(path: Path, root: Path = PACKAGE) -> list[str]:
    me = "__init__" if path == root / "__init__.py" else _unit(_module_name(path, root))
    bad = []
    for line, target in _imports(path, root):
        them = _unit(target)
        if them != me and RANKS[them] >= RANKS[me]:
            bad.append(f"line {line}: {target} (rank {RANKS[them]} >= {me}'s {RANKS[me]})")
    return bad


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_upward_import(path):
    bad = _violations(path)
    assert not bad, f"{path.relative_to(PACKAGE)} imports upward: " + "; ".join(bad)


def test_the_checker_sees_upward_imports_hidden_in_functions(tmp_path):
    """The test above could pass by seeing nothing: it must flag a lazy relative import and an absolute one."""
    root = tmp_path / "flowchart2sdnn"
    (root / "fit").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    lazy = root / "fit" / "x.py"
    lazy.write_text("import numpy\nfrom .lm import LMOptions\n\ndef f():\n    from ..identify.offline.run import identify\n")
    absolute = root / "fit" / "y.py"
    absolute.write_text("def g():\n    import flowchart2sdnn.network.runtime\n")
    assert _violations(lazy, root) == ["line 5: flowchart2sdnn.identify.offline.run (rank 5 >= fit's 2)"]
    assert _violations(absolute, root) == ["line 2: flowchart2sdnn.network.runtime (rank 3 >= fit's 2)"]


# ------------------------------------------------------------------------------------ cycles inside a package
def _runtime_imports(path: Path, root: Path = PACKAGE) -> list[tuple[int, str]]:
    """(line, module) of every import of ours that runs: an import under `if TYPE_CHECKING:` only names types.
    `from . import x` names the module x when x is one (not the package)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                   and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
    name = _module_name(path, root)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "flowchart2sdnn"]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - (node.level - 1)] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            if target.split(".")[0] == "flowchart2sdnn":
                out += [(node.lineno, f"{target}.{a.name}") for a in node.names]
    return out


def _package_graph(files, root: Path = PACKAGE) -> dict[str, dict[str, int]]:
    """module -> {module of the same package it imports: line}, over the subpackages' modules."""
    modules = {_module_name(f, root) for f in files}
    graph: dict[str, dict[str, int]] = {}
    for f in files:
        me = _module_name(f, root)
        if len(me.split(".")) < 2:
            continue
        for line, target in _runtime_imports(f, root):
            parts = target.split(".")
            while parts and ".".join(parts) not in modules:  # `from .x import name` -> module x
                parts = parts[:-1]
            them = ".".join(parts)
            if them and them != me and them.split(".")[:2] == me.split(".")[:2]:
                graph.setdefault(me, {})[them] = line
    return graph


def _cycles(files, root: Path = PACKAGE) -> list[str]:
    import networkx as nx

    graph = _package_graph(files, root)
    g = nx.DiGraph([(a, b) for a, targets in graph.items() for b in targets])
    return [" -> ".join(f"{m} (line {graph[m][c[(i + 1) % len(c)]]})" for i, m in enumerate(c)) + f" -> {c[0]}"
            for c in sorted(sorted(c) for c in nx.simple_cycles(g))]


def test_no_import_cycle_inside_a_package():
    cycles = _cycles(FILES)
    assert not cycles, "modules that import each other (break the cycle, do not hide it in a function):\n" + \
        "\n".join(cycles)


def test_the_cycle_checker_sees_a_lazy_cycle_and_not_a_typing_one(tmp_path):
    """The test above could pass by seeing nothing: a cycle closed by a lazy `from . import` must show, a
    cycle closed only under TYPE_CHECKING must not."""
    root = tmp_path / "flowchart2sdnn"
    (root / "fit").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "fit" / "__init__.py").write_text("")
    (root / "fit" / "a.py").write_text("from .b import g\n")
    (root / "fit" / "b.py").write_text("def g():\n    from . import a\n")
    (root / "fit" / "c.py").write_text("from .d import h\n")
    (root / "fit" / "d.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .c import X\n")
    files = sorted(root.rglob("*.py"))
    assert _cycles(files, root) == ["flowchart2sdnn.fit.a (line 1) -> flowchart2sdnn.fit.b (line 2) -> "
                                    "flowchart2sdnn.fit.a"]


# ----------------------------------------------------------------------------------------- only report/ draws
#: the packages that compute: none of them may import report/ or draw
COMPUTATION = {unit for unit, rank in RANKS.items() if rank < RANKS["report"]}


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_only_report_draws(path):
    unit = "__init__" if path == PACKAGE / "__init__.py" else _unit(_module_name(path))
    if unit not in COMPUTATION:
        return
    tree = ast.parse(path.read_text(encoding="utf-8"))
    drawing = [node.lineno for node in ast.walk(tree)
               if (isinstance(node, ast.Import) and any(a.name.split(".")[0] == "matplotlib" for a in node.names))
               or (isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "matplotlib")]
    viewing = [line for line, target in _imports(path) if _unit(target) == "report"]
    assert not drawing, f"{path.relative_to(PACKAGE)} imports matplotlib at line(s) {drawing}: draw in report/"
    assert not viewing, f"{path.relative_to(PACKAGE)} imports report/ at line(s) {viewing}"


def test_computation_is_everything_below_the_views():
    assert {"fit", "network", "identify", "diagnose", "batch", "simulate", "analysis"} <= COMPUTATION
    assert not {"report", "api", "cli", "__init__"} & COMPUTATION


# ------------------------------------------------------------------------------------------ modules stay small
#: the package's modules over LONGEST lines, each with the reason it stays whole
LONG_MODULES = {
    "identify/shooting/segmented.py": "one class, Segmented: a stage's residual and sparse Jacobian fill the index "
                                      "plan built once per stage; its methods apart would pass that plan between "
                                      "modules",
    "identify/online/kernel.py": "numba: the quasi-online per-sample loop and trial mode, inlined into one compiled "
                                 "function (its window numerics are already apart, online/window.py)",
    "identify/online/window.py": "numba: the window's sums, damped step and iteration, inlined into the kernel's loop",
    "identify/online/run.py": "the quasi-online run's options, state and result around the one call of the kernel; "
                              "the record checks and the chunked driver share OnlineRun's arrays",
    "network/kernels.py": "numba: simulation and RTRL kernels compiled together over the flat arrays, sharing the "
                          "inlined per-neuron helpers (the row operations are already apart, network/rowops.py)",
}
LONGEST = 400


def test_modules_stay_small():
    lengths = {f.relative_to(PACKAGE).as_posix(): len(f.read_text(encoding="utf-8").splitlines()) for f in FILES}
    long = {name for name, n in lengths.items() if n > LONGEST}
    over = sorted((n, lengths[n]) for n in long - set(LONG_MODULES))
    assert not over, f"split by concern (or name the reason in LONG_MODULES): {over}"
    assert set(LONG_MODULES) <= long, f"no longer long, drop from LONG_MODULES: {sorted(set(LONG_MODULES) - long)}"


@pytest.mark.parametrize("path", [f for f in FILES if _unit(_module_name(f)) != "identify"],
                         ids=lambda p: str(p.relative_to(PACKAGE)))
def test_identify_is_imported_through_its_face(path):
    """diagnose, batch, report, the api and the command line take identify's names from flowchart2sdnn.identify
    (its __init__), never from the modules inside: those may move without their users noticing."""
    inner = [f"line {line}: {target}" for line, target in _imports(path)
             if target.startswith("flowchart2sdnn.identify.")]
    assert not inner, f"{path.relative_to(PACKAGE)} imports identify's modules (import from the face): {inner}"
