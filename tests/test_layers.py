"""No module imports a layer above it: the package's layer rule, checked on every import statement (module level
and inside functions alike) by reading the source, so a lazy import cannot hide an upward dependency."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "flowchart2sdnn"

#: bottom -> top; a module may import its own package and anything of a lower rank, nothing else of ours.
RANKS = {
    "_version": 0, "errors": 0, "tables": 0, "strictjson": 0,
    "atomic": 1, "expr": 1, "executors": 1,
    "diagram": 2, "fit": 2, "data": 2,
    "analysis": 3, "network": 3,
    "compiler": 4,
    "simulate": 4.5,  # the continuous oracle and the bench: identify measures its discretization floor with it
    "identify": 5,
    "diagnose": 6,
    "batch": 7,
    "api": 8,
    "__init__": 8.5,  # the public names, over the api they come from
    "cli": 9,
    "__main__": 10,
}


def _unit(module: str) -> str:
    """flowchart2sdnn.identify.run -> identify; flowchart2sdnn (the package's __init__) -> __init__."""
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
    lazy.write_text("import numpy\nfrom .lm import LMOptions\n\ndef f():\n    from ..identify.run import identify\n")
    absolute = root / "fit" / "y.py"
    absolute.write_text("def g():\n    import flowchart2sdnn.network.runtime\n")
    assert _violations(lazy, root) == ["line 5: flowchart2sdnn.identify.run (rank 5 >= fit's 2)"]
    assert _violations(absolute, root) == ["line 2: flowchart2sdnn.network.runtime (rank 3 >= fit's 2)"]
