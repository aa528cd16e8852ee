"""examples/paper_experiment.py as a module, for the tests that score runs with it."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_NAME = "paper_experiment_example"


def paper_example():
    """The script, imported once (registered in sys.modules first: its dataclasses look themselves up)."""
    if _NAME not in sys.modules:
        spec = importlib.util.spec_from_file_location(_NAME, REPO / "examples" / "paper_experiment.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[_NAME] = module
        spec.loader.exec_module(module)
    return sys.modules[_NAME]
