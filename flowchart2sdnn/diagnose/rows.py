"""A diagnosis's tables as rows (one dict per row), which ``candidates_table()`` and ``rounds_table()`` give as
DataFrames when pandas is installed (:func:`flowchart2sdnn.tables.frame`).

Layer: diagnose.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # names for annotations only: result imports this module
    from .result import Diagnosis

__all__ = ["candidate_rows", "round_rows", "CANDIDATE_COLUMNS", "ROUND_COLUMNS"]

CANDIDATE_COLUMNS = ("round", "rank", "effect", "at", "label", "score", "p_value", "refitted", "achieved_decrease",
                     "validation_rms_after", "start", "error")
ROUND_COLUMNS = ("round", "effect", "at", "label", "accepted", "reason", "rms_before", "rms_after",
                 "validation_rms_before", "validation_rms_after", "bic_before", "bic_after")


def candidate_rows(d: Diagnosis) -> list[dict]:
    """Every scored candidate of every round, ranked per round, with its refit where it had one."""
    return [{"round": c.round, "rank": c.rank, "effect": c.effect, "at": c.at, "label": c.label, "score": c.score,
             "p_value": c.p_value, "refitted": c.refit is not None,
             "achieved_decrease": c.refit.achieved_decrease if c.refit else None,
             "validation_rms_after": c.refit.validation_rms_after if c.refit else None,
             "start": c.refit.start if c.refit else None, "error": c.error} for c in d.candidates]


def round_rows(d: Diagnosis) -> list[dict]:
    """Each round's decision: the effect, accepted or why not, train and validation RMS and BIC before/after."""
    return [{k: getattr(r, k) for k in ROUND_COLUMNS} for r in d.rounds]
