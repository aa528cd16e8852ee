"""Identification: fit a chart to measured data (offline LM, multiple shooting, quasi-online), and judge the fit.

This file is the package's face: diagnose, batch, the api and the command line import the names below from
``flowchart2sdnn.identify``, never from the modules inside. Names load on first use (``import flowchart2sdnn``
stays fast).

Inside, by concern:

* :mod:`.settings` (how identify fits) -> :mod:`.offline` (identify: problem, workers, curve starts, initial
  states) -> :mod:`.result` (the typed answer) -> :mod:`.serialize` / :mod:`.document` (RESULT.json written
  and read back); :mod:`.compare` scores a result on a record, :mod:`.rows` tabulates it;
* :mod:`.shooting`: multiple shooting and ``--shooting auto``;
* :mod:`.online`: the quasi-online sliding-window LM;
* :mod:`.assess`: the discretization floor and its bias, the evidence of a fit, the records' noise, the lag-0
  check.

The text, pages and figures live in :mod:`flowchart2sdnn.report`.

Layer 5: imports the compiler, network, fit, data, chart and executors below it; never diagnose, batch, report
or cli. Modules inside import each other's modules, never this face.
"""

from __future__ import annotations

import importlib

#: public name -> the module (below this package) it lives in
_HOME = {
    # the offline fit
    "identify": "offline.run", "with_floor_bias": "offline.run", "lm_options": "offline.optimize",
    "Problem": "offline.problem", "build_problem": "offline.problem", "data_init": "offline.problem",
    "metrics": "offline.problem", "required_columns": "offline.problem", "columns_of": "offline.arrays",
    "estimate_initial_state": "offline.initstate", "FitTask": "offline.workers",
    # settings, the typed answer and its documents
    "IdentifySettings": "settings", "IDENTIFY_GEODESIC": "settings", "REFIT_TAU": "settings",
    "Identification": "result", "Estimate": "result", "Curve": "result", "Metrics": "result", "Fit": "result",
    "Uncertainty": "result",
    "to_document": "document", "from_document": "document", "dumps": "document", "read_result": "document",
    "read_model": "document", "fix_from_result": "document", "apply_result_file": "document",
    "fit_rows": "rows", "parameter_rows": "rows",
    "Comparison": "compare", "compare_records": "compare", "compare_fit": "compare", "record_theta": "compare",
    "signal_units": "compare",
    # multiple shooting
    "choose_shooting": "shooting.auto", "SUSPECT_PEAK": "shooting.auto",
    # quasi-online
    "OnlineOptions": "online.run", "quasi_online": "online.run",
    # assessment of a fit
    "NOISE_MARGIN": "assess.noise", "noise_cost": "assess.noise", "noise_level": "assess.noise",
    "measure_floor": "assess.floor", "pooled_floor": "assess.floor", "lag_zero_warnings": "assess.lagzero",
}

__all__ = list(_HOME)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


def __getattr__(name: str):
    """A public name, imported from its module on first use (sys.modules keeps the module)."""
    if name not in _HOME:
        raise AttributeError(f"module 'flowchart2sdnn.identify' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
