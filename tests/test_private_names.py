"""No private name crosses a module: `from .x import _name` and `x._name` (x a module of ours) are read from the
source of every module in flowchart2sdnn, at module level and inside functions alike. A name another module
needs is public (no underscore, in its module's __all__) or lives where it is used. Tests may use private
names; dunders (`__version__`) and private modules (`_version`) are not private names in this sense."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "flowchart2sdnn"

#: (module, name) -> why the private name may cross; none today
EXCEPTIONS: dict[tuple[str, str], str] = {}


def _module_name(path: Path, package: Path) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" and len(parts) > 1 else parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _crossings(path: Path, package: Path = PACKAGE) -> list[str]:
    """`line: module.name` of every private name of another module of ours that `path` imports or reads."""
    root = package.name
    modules = {_module_name(f, package) for f in package.rglob("*.py")}
    me = _module_name(path, package)
    here = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    aliases: dict[str, str] = {}  # local name -> module of ours it is bound to
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == root:
                    aliases[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom):
            base = here[: len(here) - (node.level - 1)] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            if target.split(".")[0] != root:
                continue
            for a in node.names:
                if f"{target}.{a.name}" in modules:  # `from . import x`: a module, not a name
                    aliases[a.asname or a.name] = f"{target}.{a.name}"
                elif _private(a.name) and target != me:
                    out.append((node.lineno, f"{target}.{a.name}"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            owner = aliases.get(ast.unparse(node.value), ast.unparse(node.value))
            if owner in modules and owner != me:
                out.append((node.lineno, f"{owner}.{node.attr}"))
    return [f"line {line}: {name}" for line, name in sorted(out)
            if tuple(name.rsplit(".", 1)) not in EXCEPTIONS]


FILES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_private_name_crosses_a_module(path):
    bad = _crossings(path)
    assert not bad, (f"{path.relative_to(PACKAGE)} uses private names of other modules (make them public or "
                     "move them): " + "; ".join(bad))


def test_the_checker_sees_private_names_imported_or_read(tmp_path):
    """The test above could pass by seeing nothing: a lazy `from .x import _f`, an attribute `ok._g` of a module
    bound by `from . import`, and one of an absolute import must show; a module's own private names, a dunder
    and a private name of another package (numpy) must not."""
    package = tmp_path / "flowchart2sdnn"
    (package / "fit").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "_version.py").write_text("__version__ = '0'\n")
    (package / "fit" / "__init__.py").write_text("")
    (package / "fit" / "kernel.py").write_text("def _f():\n    pass\n\ndef _g():\n    pass\n")
    user = package / "fit" / "user.py"
    user.write_text("import numpy as np\nimport flowchart2sdnn.fit.kernel\nfrom .. import _version\n"
                    "from .._version import __version__\nfrom . import kernel as ok\n\n"
                    "def _own():\n    return np._NoValue, _own\n\n"
                    "def h():\n    from .kernel import _f\n    return ok._g, flowchart2sdnn.fit.kernel._g, _f\n")
    assert _crossings(user, package) == ["line 11: flowchart2sdnn.fit.kernel._f",
                                         "line 12: flowchart2sdnn.fit.kernel._g",
                                         "line 12: flowchart2sdnn.fit.kernel._g"]
