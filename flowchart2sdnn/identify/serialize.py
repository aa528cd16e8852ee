"""Identification -> RESULT.json: the writing half of the result format (:mod:`.document` reads it back and
re-exports these names).

Kept apart from :mod:`.document` because :class:`~flowchart2sdnn.identify.result.Identification` writes
itself (``.to_json()``) while the reader builds Identifications: one module doing both made result and
document import each other. This one needs the result's types only to name them.

Layer: identify.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import TYPE_CHECKING

from ..notices import Notice
from ..strictjson import strict_json

if TYPE_CHECKING:  # names for annotations only: importing result here would close the cycle again
    from .result import Identification, Metrics, RecordInfo
    from .settings import IdentifySettings

__all__ = ["to_document", "dumps", "RESULT_FORMAT", "RESULT_VERSION", "NON_FINITE"]

RESULT_FORMAT = "sdnn-result"
RESULT_VERSION = 1
#: The document's own warning when it had to store NaN/inf as null (not part of the typed result).
NON_FINITE = "non-finite values stored as null: "


def _metrics(m: Metrics) -> dict:
    out = {"rows": m.rows, "cost": m.cost, "rms": dict(m.rms), "fit_percent": dict(m.fit_percent)}
    if m.records is not None:
        out["records"] = [_metrics(r) for r in m.records]
    if m.note is not None:
        out["note"] = m.note
    return out


def _record(r: RecordInfo | None) -> dict | None:
    return None if r is None else {"file": r.file, "sha256": r.sha256, "rows": r.rows,
                                   "max_step_deviation": r.max_step_deviation}


def _settings(s: IdentifySettings) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(s).items()}


def to_document(ident: Identification) -> dict:
    """The RESULT.json body of an identification (NaN/inf stored as null, with a warning saying where)."""
    doc = {
        "format": RESULT_FORMAT,
        "version": RESULT_VERSION,
        "status": ident.status,
        "message": ident.message,
        "interrupted": bool(ident.interrupted),
        "converged": ident.converged,
        "parameters": {n: {"value": e.value, "init": e.init, "stderr": e.stderr,
                           "ci95": None if e.ci95 is None else list(e.ci95), "unit": e.unit, "fixed": e.fixed,
                           "ci95_noise": None if e.ci95_noise is None else list(e.ci95_noise)}
                       for n, e in ident.parameters.items()},
        "nonlinear": {b: {"a": list(c.a), "v": list(c.v), **({"b": list(c.b)} if c.b is not None else {}),
                          **({"c": c.c} if c.c is not None else {}), "fixed": c.fixed}
                      for b, c in ident.curves.items()},
        "fit": {"train": _metrics(ident.fit.train),
                "validation": None if ident.fit.validation is None else _metrics(ident.fit.validation)},
        "warnings": list(ident.warnings),
        "notices": [n.to_dict() for n in ident.notices],  # the warnings as records: code, numbers, advice
        "settings": _settings(ident.settings),
        "seed": ident.settings.seed,
        "chart": {"name": ident.source.name, "file": ident.source.file, "sha256": ident.source.sha256},
        "data": {"train": _record(ident.data.train), "train_records": [_record(r) for r in ident.data.train_records],
                 "validation": _record(ident.data.validation)},
        "versions": dict(ident.versions),
    }
    if (o := ident.optimizer) is not None:
        doc["optimizer"] = {"iterations": o.iterations, "cost_history": list(o.cost_history), "nfev": o.nfev,
                            "njev": o.njev, "rejected": {"cost": o.rejected_cost, "diverged": o.rejected_diverged,
                                                         "chatter": o.rejected_chatter}}
    if (m := ident.multistart) is not None:
        ms = {"n": m.n, "best_index": m.best_index, "costs": list(m.costs), "near_best": list(m.near_best),
              "local_minima": list(m.local_minima), "diverged": list(m.diverged),
              "starts": [list(s) for s in m.starts], "message": m.message}
        if m.names is not None:
            ms["names"] = list(m.names)
        if m.cost is not None:
            ms["cost"] = m.cost
        doc["multistart"] = ms
    if (u := ident.uncertainty) is not None:
        doc["uncertainty"] = {"names": list(u.names), "correlation": [list(r) for r in u.correlation],
                              "condition_number": u.condition_number,
                              "unidentifiable": [list(g) for g in u.unidentifiable], "sigma2": u.sigma2,
                              "residual_lag1": u.residual_lag1, "interval_inflation": u.interval_inflation,
                              "note": u.note}
    if (t := ident.online) is not None:
        doc["online"] = {"window": t.window, "average": t.average, "every": t.every, "steps": t.steps,
                         "mean_cost": t.mean_cost, "final": dict(t.final), "trajectory_time": list(t.trajectory_time),
                         "trajectories": {n: list(v) for n, v in t.trajectories.items()},
                         "cost_time": list(t.cost_time), "cost": list(t.cost)}
    bad: list[str] = []
    doc = strict_json(doc, "", bad)
    if bad:
        said = Notice("JSON001", f"{NON_FINITE}{', '.join(bad[:5])}" + (f" (+{len(bad) - 5} more)" if len(bad) > 5 else ""),
                      {"places": bad}, "read those values from the identified chart or the run's log")
        doc["warnings"].append(said.message)
        doc["notices"].append(said.to_dict())
    doc.update(ident.extra)
    return doc


def dumps(doc: dict) -> str:
    """A document as RESULT.json text (strict JSON; what `sdnn identify -o` writes)."""
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"
