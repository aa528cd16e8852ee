"""Diagnosis -> REPORT.json: the writing half of the report format (:mod:`.document` reads it back and
re-exports these names).

Kept apart from :mod:`.document` because :class:`~flowchart2sdnn.diagnose.result.Diagnosis` writes itself
(``.report``, ``.to_json()``) while the reader builds Diagnoses: one module doing both would make result and
document import each other. This one needs the result's types only to name them.

Layer: diagnose.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, fields
from typing import TYPE_CHECKING

from ..identify import to_document as identification_document
from ..strictjson import strict_json

if TYPE_CHECKING:  # names for annotations only: importing result here would close the cycle again
    from .result import CandidateRow, Diagnosis, Round

__all__ = ["to_document", "dumps", "REPORT_FORMAT", "REPORT_VERSION"]

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
        doc["data_notices"] = [n.to_dict() for n in d.data_notices]  # the notes as records, codes beside them
    if d.command is not None:
        doc["command"] = _plain(d.command)
    doc.update(d.extra)
    return doc


def dumps(doc: dict) -> str:
    """A document as REPORT.json text (strict JSON: NaN and infinities as null; what `--report` writes)."""
    return json.dumps(strict_json(doc), indent=1, allow_nan=False) + "\n"
