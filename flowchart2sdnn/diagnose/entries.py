"""The pieces of REPORT.json that describe one fit and one round (kept out of the loop's module).

Layer: diagnose.
"""

from __future__ import annotations

from ..strictjson import finite_or_none
from .fitting import DiagnoseSettings, Fitted, gain_spread
from .score import Score

__all__ = ["summary", "round_entry"]


def summary(f: Fitted) -> dict:
    res = f.identification.fit.train
    val = f.validation["records"]
    return {"rms": finite_or_none(f.rms), "validation_rms": finite_or_none(f.validation_rms), "aic": finite_or_none(f.aic), "bic": finite_or_none(f.bic),
            "cost": finite_or_none(f.cost), "k": f.k, "validation_floor": finite_or_none(f.validation_floor), "rms_per_output": dict(res.rms), "fit_percent": dict(res.fit_percent),
            "validation_rms_per_output": [m["rms"] for m in val],
            "validation_fit_percent": [m["fit_percent"] for m in val],
            "validation_initial_state": [m.get("initial_state") for m in val]}


def round_entry(r: int, s: Score, before: Fitted, after: Fitted | None, accepted: bool, reason: str,
                 settings: DiagnoseSettings) -> dict:
    c = s.candidate
    a = after
    return {
        "round": r, "effect": c.name, "at": c.at, "option": s.as_dict()["option"], "label": c.label,
        "accepted": accepted, "reason": reason, "start": a.start if a else None,
        "score": finite_or_none(s.score), "predicted_decrease": finite_or_none(s.score),
        "achieved_decrease": finite_or_none(before.cost - a.cost) if a else None,
        "rms_before": finite_or_none(before.rms), "rms_after": finite_or_none(a.rms) if a else None,
        "validation_rms_before": finite_or_none(before.validation_rms),
        "validation_rms_after": finite_or_none(a.validation_rms) if a else None,
        # the standard error of the validation MSE's fall, from its spread over the validation parts (refusal)
        "validation_gain_spread": finite_or_none(gain_spread(a, before)) if a else None,
        "aic_before": finite_or_none(before.aic), "aic_after": finite_or_none(a.aic) if a else None,
        "bic_before": finite_or_none(before.bic), "bic_after": finite_or_none(a.bic) if a else None,
        "before": summary(before), "after": summary(a) if a else None,
        "parameters": (a.identification.values if a else None),
    }
