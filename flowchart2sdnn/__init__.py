"""flowchart2sdnn: grey-box identification of mechatronic systems.

A continuous signal flow chart (YAML) is linted, compiled into a structured General Dynamic Neural Network
whose weights are physical parameters, and identified from measured data with Levenberg-Marquardt + RTRL.

The public API (see the README's "Python API"):

* :func:`load_chart`, :func:`compile_chart`: a chart file -> :class:`Diagram` -> compiled network
* :func:`read_csv`, :func:`dataset_from_frame`: measured records (:class:`Dataset`)
* :func:`identify` -> :class:`Identification` (``.parameters``, ``.chart``, ``.simulate()``, ``.to_json()``)
* :func:`diagnose` -> :class:`Diagnosis`; :func:`read_result` reads a RESULT.json back, :func:`read_report` a
  REPORT.json

Names are imported on first use, so ``import flowchart2sdnn`` (and the command line) stays fast.
"""

from __future__ import annotations

import importlib

from . import diagnose as _diagnose_package  # noqa: F401
from . import identify as _identify_package  # noqa: F401
from . import report as _report_package  # noqa: F401  (registers the drawing results delegate to; cheap)
from ._version import __version__

# The subpackages identify/ and diagnose/ are imported above (cheap: their modules load on first use); their
# names are then taken back so that `identify` and `diagnose` here are the functions of api.py (loaded on first
# use by __getattr__, with their own docstrings and signatures for help()). Reach identify's names through its
# face, `from flowchart2sdnn.identify import Problem` (flowchart2sdnn/identify/__init__.py).
del globals()["identify"], globals()["diagnose"]

__all__ = [
    "__version__",
    "load_chart",
    "compile_chart",
    "read_csv",
    "dataset_from_frame",
    "identify",
    "diagnose",
    "read_result",
    "read_report",
    "Diagram",
    "Dataset",
    "Compilation",
    "IdentifySettings",
    "Identification",
    "Estimate",
    "Curve",
    "Metrics",
    "DiagnoseSettings",
    "Diagnosis",
    "SdnnError",
    "Notice",
]

_HOME = {
    "load_chart": "api", "compile_chart": "api", "read_csv": "api", "dataset_from_frame": "api",
    "read_result": "api", "read_report": "api", "identify": "api", "diagnose": "api",
    "Diagram": "diagram.model", "Dataset": "data.csvdata", "Compilation": "compiler",
    "IdentifySettings": "identify.settings", "Identification": "identify.result", "Estimate": "identify.result",
    "Curve": "identify.result", "Metrics": "identify.result",
    "DiagnoseSettings": "diagnose.loop", "Diagnosis": "diagnose.result", "SdnnError": "errors",
    "Notice": "notices",
}


def __getattr__(name: str):
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'flowchart2sdnn' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{home}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))

