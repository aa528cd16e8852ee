"""REPORT.json: the only writer and reader of the diagnose report format.

:func:`to_document` turns a :class:`~flowchart2sdnn.diagnose.result.Diagnosis` into the document (keys as they
have always been: users' scripts read them), :func:`from_document` reads one back (``to_document`` of it gives
the body back), :func:`dumps` writes it as strict JSON, :func:`read_report` reads a file. The final fit's
``final`` is a RESULT.json body (:mod:`flowchart2sdnn.identify.document`).

Layer: diagnose.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, fields
from pathlib import Path

from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify.document import from_document as identification_from
from ..identify.document import to_document as identification_document
from ..strictjson import strict_json
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

__all__ = ["to_document", "from_document", "dumps", "read_report", "load_report", "REPORT_FORMAT",
           "REPORT_VERSION", "fit_summary", "read_round", "read_candidate", "read_accepted"]

REPORT_FORMAT = "sdnn-diagnose"
REPORT_VERSION = 1


def _plain(x):
    """Tuples as lists and mappings as dicts, all the way down: what the document holds."""
    if isinstance(x, Mapping):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _flat(part) -> dict:
    """A part whose fields are named as its keys, as the document's mapping."""
    return {f.name: _plain(getattr(part, f.name)) for f in fields(part)}


# ------------------------------------------------------------------------------------------------ writing
def _candidate(c: CandidateRow) -> dict:
    out = {f.name: _plain(getattr(c, f.name)) for f in fields(c) if f.name != "refit"}
    if (r := c.refit) is not None:
        out.update({"refitted": True, "achieved_cost": r.achieved_cost, "achieved_decrease": r.achieved_decrease,
                    "start": r.start, "validation_rms_after": r.validation_rms_after,
                    r.criterion + "_after": r.criterion_after})
    return out


def _round(r: Round) -> dict:
    out = {f.name: _plain(getattr(r, f.name)) for f in fields(r)}
    out["before"] = _flat(r.before)
    out["after"] = None if r.after is None else _flat(r.after)
    out["control"] = None if r.control is None else _flat(r.control)
    return out


def to_document(d: Diagnosis) -> dict:
    """The REPORT.json body of a diagnosis (numbers as computed: :func:`dumps` stores NaN/inf as null)."""
    settings = {**asdict(d.settings), "split": d.split, "effects": list(d.effects)}
    doc = {
        "format": REPORT_FORMAT,
        "version": REPORT_VERSION,
        "stop": d.stop,
        "last_round": d.last_round,
        "n_accepted": d.n_accepted,
        "first_fit": _flat(d.first_fit),
        "interrupted": d.interrupted,
        "candidates": [_candidate(c) for c in d.candidates],
        "rounds": [_round(r) for r in d.rounds],
        "accepted": [_flat(a) for a in d.accepted],
        "before": _flat(d.before),
        "after": _flat(d.after),
        "whiteness": {"before": _plain(d.whiteness[0].analysis), "after": _plain(d.whiteness[1].analysis)},
        "final": identification_document(d.identification),
        "settings": settings,
        "timing": _plain(d.timing),
    }
    if d.data_notes:
        doc["data_notes"] = list(d.data_notes)
    if d.command is not None:
        doc["command"] = _plain(d.command)
    doc.update(d.extra)
    return doc


def dumps(doc: dict) -> str:
    """A document as REPORT.json text (strict JSON: NaN and infinities as null; what `--report` writes)."""
    return json.dumps(strict_json(doc), indent=1, allow_nan=False) + "\n"


# ------------------------------------------------------------------------------------------------ reading
_KNOWN = {"format", "version", "stop", "last_round", "n_accepted", "first_fit", "interrupted", "candidates",
          "rounds", "accepted", "before", "after", "whiteness", "final", "settings", "timing", "data_notes",
          "command"}


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
             if f.name not in ("before", "after", "control", "score_rows", "score_rows_added", "second_look")}
    c = d.get("control")
    return Round(**plain, before=fit_summary(d["before"]),
                 after=None if d.get("after") is None else fit_summary(d["after"]),
                 control=None if c is None else Control(c.get("start"), c.get("rms"), c.get("validation_rms"),
                                                         bool(c.get("used_as_baseline")), bool(c.get("final"))),
                 score_rows=_tuple(d.get("score_rows")), score_rows_added=tuple(d.get("score_rows_added") or ()),
                 second_look=tuple(d.get("second_look") or ()))


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
        extra={k: v for k, v in doc.items() if k not in _KNOWN}, diagram=chart)


def load_report(path: str | Path) -> dict:
    """Read a REPORT.json written by `sdnn diagnose --report`; SdnnError naming the file when it is not one."""
    name = str(path)
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SdnnError.at("DIAG031", "no such file", name) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SdnnError.at("DIAG031", f"cannot read: {exc}", name) from None
    except json.JSONDecodeError as exc:
        raise SdnnError.at("DIAG032", f"not JSON: {exc.msg}", name, exc.lineno, exc.colno) from None
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
