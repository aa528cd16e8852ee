"""The bundled examples (examples/*.py) and benchmarks loaded as modules, for the real-data tests that check them."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_example(name: str):
    """examples/<name>.py as a module (the examples are scripts, not a package)."""
    return _load(ROOT / "examples" / f"{name}.py", f"{name}_example")


def load_benchmark(name: str):
    """benchmarks/<name>.py as a module (the real-data tests that check a benchmark's measurements)."""
    return _load(ROOT / "benchmarks" / f"{name}.py", name)


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
