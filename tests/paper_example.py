"""The scripts of examples/ as modules, for the tests that score runs with them."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def example(stem: str):
    """examples/STEM.py, imported once (registered in sys.modules first: its dataclasses look themselves up)."""
    name = f"{stem}_example"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, REPO / "examples" / f"{stem}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def paper_example():
    """examples/paper_experiment.py as a module."""
    return example("paper_experiment")
