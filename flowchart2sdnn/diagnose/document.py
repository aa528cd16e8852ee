"""REPORT.json: the one place the diagnose report format is written (through :mod:`.serialize`) and read.

:func:`to_document` turns a :class:`~flowchart2sdnn.diagnose.result.Diagnosis` into the document (keys as they
have always been: users' scripts read them; written by :mod:`.serialize`, re-exported here),
:func:`from_document` reads one back (``to_document`` of it gives the body back), :func:`dumps` writes it as
strict JSON, :func:`read_report` reads a file. The final fit's ``final`` is a RESULT.json body
(:mod:`flowchart2sdnn.identify.document`).

Layer: diagnose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path

from ..atomic import read_json
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify import from_document as identification_from
from ..notices import Notice
from .fitting import DiagnoseSettings
from .result import (
    AcceptedEffect,
    CandidateRow,
    Control,
    Diagnosis,
    FirstFit,
    FitSummary,
    Refit,
    ResidualCheck,
    Round,
)
from .serialize import REPORT_FORMAT, REPORT_VERSION, dumps, to_document

__all__ = ["to_document", "from_document", "dumps", "read_report", "load_report", "REPORT_FORMAT",
           "REPORT_VERSION", "fit_summary", "read_round", "read_candidate", "read_accepted"]


# ------------------------------------------------------------------------------------------------ reading
_KNOWN = {"format", "version", "stop", "last_round", "n_accepted", "first_fit", "interrupted", "candidates",
          "rounds", "accepted", "before", "after", "whiteness", "final", "settings", "timing", "data_notes",
          "data_notices", "command"}


def _tuple(x):
    return None if x is None else tuple(x)


def fit_summary(d: Mapping) -> FitSummary:
    """A :class:`FitSummary` from its REPORT.json mapping (``before``, ``after``, a round's)."""
    return FitSummary(
        rms=d["rms"], validation_rms=d["validation_rms"], aic=d["aic"], bic=d["bic"], cost=d["cost"], k=d["k"],
        validation_floor=d.get("validation_floor"), rms_per_output=dict(d["rms_per_output"]),
        fit_percent=dict(d["fit_percent"]),
        validation_rms_per_output=tuple(d.get("validation_rms_per_output") or ()),
        validation_fit_percent=tuple(d.get("validation_fit_percent") or ()),
        validation_initial_state=tuple(d.get("validation_initial_state") or ()))


def read_candidate(d: Mapping) -> CandidateRow:
    """A :class:`CandidateRow` from its REPORT.json mapping (the refit's criterion is the ``*_after`` key that is
    not the validation RMS)."""
    refit = None
    if d.get("refitted"):
        crit = next((k[:-6] for k in d if k.endswith("_after") and k != "validation_rms_after"), "bic")
        refit = Refit(d.get("achieved_cost"), d.get("achieved_decrease"), d.get("start"),
                      d.get("validation_rms_after"), crit, d.get(crit + "_after"))
    return CandidateRow(round=d["round"], rank=d["rank"], effect=d["effect"], at=d["at"], option=d.get("option"),
                        label=d.get("label") or "", score=d.get("score"), predicted_cost=d.get("predicted_cost"),
                        cost_patched=d.get("cost_patched"), dof=d.get("dof"), statistic=d.get("statistic"),
                        p_value=d.get("p_value"), error=d.get("error"), refit=refit)


def read_round(d: Mapping) -> Round:
    """A :class:`Round` from its REPORT.json mapping."""
    plain = {f.name: d.get(f.name) for f in fields(Round)
             if f.name not in ("before", "after", "control", "score_rows", "score_rows_added", "second_look",
                               "one_step")}
    c = d.get("control")
    return Round(**plain, before=fit_summary(d["before"]),
                 after=None if d.get("after") is None else fit_summary(d["after"]),
                 control=None if c is None else Control(c.get("start"), c.get("rms"), c.get("validation_rms"),
                                                         bool(c.get("used_as_baseline")), bool(c.get("final"))),
                 score_rows=_tuple(d.get("score_rows")), score_rows_added=tuple(d.get("score_rows_added") or ()),
                 second_look=tuple(d.get("second_look") or ()),
                 one_step=tuple(dict(x) for x in d.get("one_step") or ()))


def read_accepted(d: Mapping) -> AcceptedEffect:
    return AcceptedEffect(d["effect"], d["at"], d.get("option"), d.get("label") or "")


def _settings(s: Mapping) -> DiagnoseSettings:
    known = {f.name for f in fields(DiagnoseSettings)} - {"split"}
    return DiagnoseSettings(**{k: v for k, v in s.items() if k in known})


def from_document(doc: Mapping, chart: Diagram | None = None) -> Diagnosis:
    """A :class:`Diagnosis` from a REPORT.json body; `chart` is the augmented chart when it was read too (the
    file ``sdnn diagnose -o`` wrote)."""
    first = doc["first_fit"]
    white = doc.get("whiteness") or {}
    return Diagnosis(
        stop=doc["stop"], last_round=doc.get("last_round", doc["stop"]),
        first_fit=FirstFit(first.get("converged"), first["status"], first["message"],
                           tuple(first.get("still_moving") or ())),
        interrupted=bool(doc.get("interrupted")),
        candidates=tuple(read_candidate(c) for c in doc["candidates"]),
        rounds=tuple(read_round(r) for r in doc["rounds"]),
        accepted=tuple(read_accepted(a) for a in doc["accepted"]),
        before=fit_summary(doc["before"]), after=fit_summary(doc["after"]),
        whiteness=(ResidualCheck(white.get("before") or {}), ResidualCheck(white.get("after") or {})),
        identification=identification_from(doc["final"], chart),
        settings=_settings(doc["settings"]), split=doc["settings"].get("split"),
        effects=tuple(doc["settings"].get("effects") or ()), timing=dict(doc.get("timing") or {}),
        data_notes=tuple(doc.get("data_notes") or ()), command=doc.get("command"),
        data_notices=tuple(Notice.from_dict(n) for n in doc.get("data_notices") or ()),
        extra={k: v for k, v in doc.items() if k not in _KNOWN}, diagram=chart)


def load_report(path: str | Path) -> dict:
    """Read a REPORT.json written by `sdnn diagnose --report`; SdnnError naming the file when it is not one."""
    name = str(path)
    data = read_json(path, "DIAG031", "DIAG032")
    if not isinstance(data, dict) or data.get("format") != REPORT_FORMAT:
        raise SdnnError.at("DIAG033", f"not an sdnn diagnose report (expected \"format\": \"{REPORT_FORMAT}\")",
                           name)
    missing = [k for k in ("stop", "first_fit", "candidates", "rounds", "accepted", "before", "after", "final",
                           "settings") if k not in data]
    if missing:
        raise SdnnError.at("DIAG033", f"the report lacks {', '.join(repr(k) for k in missing)}", name)
    return data


def read_report(path: str | Path, chart: Diagram | str | Path | None = None) -> Diagnosis:
    """Read a REPORT.json as a :class:`Diagnosis`; `chart` (a Diagram or the file ``sdnn diagnose -o`` wrote)
    becomes its ``diagram`` and the final identification's chart."""
    from ..diagram.validate import load_diagram

    diagram = chart if chart is None or isinstance(chart, Diagram) else load_diagram(chart)
    data = load_report(path)
    try:
        return from_document(data, diagram)
    except (KeyError, TypeError, ValueError) as exc:
        raise SdnnError.at("DIAG033", f"not a readable diagnose report ({type(exc).__name__}: {exc})",
                           str(path)) from None
