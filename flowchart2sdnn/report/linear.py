"""The identified chart linearised where the drive moves, and what the pages read from it: the Bode figure's
model and the number of lags a residual test must span.

Layer: report.
"""

from __future__ import annotations

import numpy as np

from ..analysis.linearize import linearize
from ..analysis.response import MIN_LAGS, lags_for
from ..errors import SdnnError
from ..identify import record_theta

__all__ = ["linear_model", "residual_lags"]


def linear_model(outcome):
    """(the chart linearised at the RMS of its states over the free run of the first training record, or
    None; why not, or "")."""
    diagram, problem = outcome.diagram, outcome.problem
    if not diagram.input_names or not diagram.output_names:
        return None, "the chart has no input or no output"
    states = {b.name for b in diagram.blocks if b.kind == "integrator"}
    with np.errstate(all="ignore"):
        signals = dict(problem.compiled.signals(record_theta(outcome, 0), problem.inputs, problem.init))
    at = {name: float(f"{np.sqrt(np.mean(np.square(v))):.3g}") for name, v in signals.items()
          if name in states and np.all(np.isfinite(v))}
    try:
        model = linearize(diagram, at)
    except (SdnnError, ValueError) as exc:
        return None, str(exc)
    return (model, "") if model.A.size else (None, "the chart has no state")


def residual_lags(outcome, n: int, lags: int | None = None, model=None) -> tuple[int, str]:
    """(lags, why) of the residual analysis of a record of `n` rows: `lags` when given (``--lags``), else
    spanning the slowest dynamics of the linearised chart (`model`, linearised here when not given)."""
    if lags is not None:
        return lags, "set with --lags"
    if model is None and outcome.online is None:
        model, _ = linear_model(outcome)
    if model is None:
        return MIN_LAGS, "no linearised model to size them by"
    lags, why = lags_for(model.damp(), outcome.diagram.sample_time, n)
    return lags, f"spanning {why}"
