"""Fleets: identify one chart on many data files (`sdnn batch`) and watch the parameters drift (`sdnn report`).

Modules: :mod:`.run` (run_batch, identify_file), :mod:`.results` (the resumable results table),
:mod:`.drift` (drift per drive; its plots and tables are drawn by :mod:`flowchart2sdnn.report.drift`); the commands live in :mod:`flowchart2sdnn.cli.batch` and
:mod:`flowchart2sdnn.cli.report`. Importing this package is cheap:
the names below load their module on first use, so `sdnn --help` does not pay for numba.
"""

from __future__ import annotations

import importlib

__all__ = ["BatchSettings", "BatchSummary", "run_batch", "identify_file", "read_results", "columns_for",
           "load_fleet", "drift_table"]

_WHERE = {"BatchSettings": "run", "BatchSummary": "run", "run_batch": "run", "identify_file": "run",
          "read_results": "results", "columns_for": "results",
          "load_fleet": "drift", "drift_table": "drift"}


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
