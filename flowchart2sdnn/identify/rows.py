"""An identification's tables as rows (one dict per row), which ``parameters_table()`` and ``fit_table()`` give as
DataFrames when pandas is installed (:func:`flowchart2sdnn.tables.frame`).

Layer: identify.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names for annotations only: result imports this module
    from .result import Identification

__all__ = ["parameter_rows", "fit_rows", "PARAMETER_COLUMNS", "FIT_COLUMNS"]

PARAMETER_COLUMNS = ("parameter", "value", "unit", "stderr", "stderr_percent", "ci95_low", "ci95_high", "init",
                     "fixed")
FIT_COLUMNS = ("record", "output", "rms", "fit_percent", "cost", "rows")


def _percent(value: float, stderr: float | None) -> float | None:
    return None if stderr is None or not value else 100.0 * stderr / abs(value)


def parameter_rows(ident: Identification) -> list[dict]:
    """One row per chart parameter: value, unit, standard error (also in % of the value), 95 % interval, init."""
    return [{"parameter": n, "value": e.value, "unit": e.unit, "stderr": e.stderr,
             "stderr_percent": _percent(e.value, e.stderr), "ci95_low": e.ci95[0] if e.ci95 else None,
             "ci95_high": e.ci95[1] if e.ci95 else None, "init": e.init, "fixed": e.fixed}
            for n, e in ident.parameters.items()]


def fit_rows(ident: Identification) -> list[dict]:
    """One row per record (train, validation) and output: RMS, fit %, cost E, rows scored."""
    out = []
    for which, m in (("train", ident.fit.train), ("validation", ident.fit.validation)):
        if m is not None:
            out += [{"record": which, "output": o, "rms": m.rms[o], "fit_percent": m.fit_percent.get(o),
                     "cost": m.cost, "rows": m.rows} for o in m.rms]
    return out
