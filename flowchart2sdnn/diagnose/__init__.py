"""`sdnn diagnose`: trace the residual to a missing effect, add it to the chart, refit, report before and after.

Pipeline: residual tests (:mod:`.residual`) -> the effects library (:mod:`.effects`, :mod:`.usereffects`) ->
the score test of every candidate (:mod:`.score`) -> brief refits and acceptance (:mod:`.loop`) -> the typed
:class:`~.result.Diagnosis` and REPORT.json (:mod:`.document`); the text, page and figures live in
:mod:`flowchart2sdnn.report`, the click command in :mod:`flowchart2sdnn.cli.diagnose`.
"""

from __future__ import annotations

import importlib

# Importing this package is cheap: a name loads its module on first use, so `sdnn --help` (which imports
# cli.diagnose to register the command) does not pay for numba and scipy.
_WHERE = {
    **dict.fromkeys(("BUILTIN_EFFECTS", "Backlash", "Cogging", "Damping", "DeadTime", "DeadZone", "Effect",
                     "Friction", "InputOffset", "LinearTerm", "Saturation", "Scales", "SensorLimit",
                     "SensorOffset", "Spring"), "effects"),
    "Place": "graph",
    **dict.fromkeys(("DiagnoseSettings", "Fitted", "diagnose"), "loop"),
    "Diagnosis": "result",
    "read_report": "document",
    **dict.fromkeys(("Candidate", "Score", "Screen", "gauss_newton_decrease", "screen"), "score"),
    **dict.fromkeys(("YamlEffect", "load_effects_file"), "usereffects"),
}


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)


__all__ = [
    "BUILTIN_EFFECTS",
    "Backlash",
    "Candidate",
    "Cogging",
    "Damping",
    "DeadTime",
    "DeadZone",
    "DiagnoseSettings",
    "Diagnosis",
    "Effect",
    "Fitted",
    "Friction",
    "InputOffset",
    "LinearTerm",
    "Place",
    "Saturation",
    "Scales",
    "Score",
    "SensorLimit",
    "SensorOffset",
    "Screen",
    "Spring",
    "YamlEffect",
    "diagnose",
    "gauss_newton_decrease",
    "load_effects_file",
    "read_report",
    "screen",
]
