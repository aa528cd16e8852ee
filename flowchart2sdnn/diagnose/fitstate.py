"""What a fit says about itself: whether it is unpredictable (chaotic from a moved start), still moving (a
parameter not converged), or far above the noise; the training problem and the signal scales at it; and the
residual analysis of a fit. Re-exported by :mod:`.fitting`.

Layer: diagnose (below it: identify and everything under it).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import rules
from ..data.csvdata import Dataset
from ..errors import SdnnError
from ..fit.effective import effective_samples
from ..identify import (
    NOISE_MARGIN,
    SUSPECT_PEAK,
    Problem,
    build_problem,
    choose_shooting,
    noise_cost,
)
from .effects import Scales
from .residual import signal_correlation, whiteness

if TYPE_CHECKING:
    from .fitting import DiagnoseSettings, Fitted

__all__ = ["unpredictable", "still_moving", "far_above_noise", "current_problem", "effect_scales",
           "residual_analysis"]


def unpredictable(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> bool:
    """Whether the single-shooting fit `fitted` may have stopped where a growing horizon (:func:`~.fitting.fit_growing`)
    goes further: its chart amplifies a moved start more than stable charts do (identify.shooting.auto's probe over
    the training records, peak above SUSPECT_PEAK) and its training residual is off the noise floor (RMS above
    NOISE_MARGIN x the noise read off the records' second differences): identify's rule for its second look
    (identify.shooting.auto.second_look), applied to a brief refit.

    Why: a neutral effect (zero amplitude) starts on the chart's own trajectory, yet the effect it adds may make
    the drive chaotic (motor cogging, two-mass bench, 30 s records at 0.01 rad/s: the brief refits of cogging
    p = 6 at w1 grew a moved start 53- to 3e6-fold and ended at 26-97x the noise, validation RMS 0.086 -> 0.097
    on seed 1; with the growing horizon 0.0129, the amplitude within 0.1 %). The gate keeps stable charts as they
    were: there the growing horizon would only add time, and when it was last measured for every neutral
    candidate, on EMPS a learned friction curve bent on the first 0.5 s won over the physical terms
    (docs/diagnose.md).
    """
    problem = _training_problem(fitted, train, settings)
    if problem is None or not _above_noise(fitted, problem, NOISE_MARGIN):
        return False
    return choose_shooting(problem, problem.compiled.theta0()).peak > SUSPECT_PEAK


#: a Gauss-Newton step is trusted where its simulated cost fall is at least this share of its linearised one, and
#: shortened by TRUST_SHRINK until it is (the trust-region rules of the trainer, fit.steps; diagnose.choice's too)
_TRUST, _SHRINK = rules.value("trust_poor_gain"), rules.value("trust_shrink")


def still_moving(fitted: Fitted) -> list[str]:
    """The quantities an unfinished fit would still move by more than their standard error: the Gauss-Newton
    step from where it stopped, against sqrt(sigma² (JᵀJ)⁻¹_ii) with sigma² the residual's variance per effective
    sample (fit.effective). Empty when the fit is at its minimum in that sense, whatever stopped it.

    The step counts only as far as it is trusted: simulated, its cost must fall by at least 1/4 of the fall
    its linearisation predicts, else it is shortened (x1/4) as a trust region is. A fit that stopped in a curved
    valley, where the whole step is predicted to gain much and gains little (a one-mass chart whose learned curve
    makes up for a sensor offset it lacks: 1000 iterations, the cost 1657 -> 1639, four curve weights "moving" by
    the whole step), moves by no more than the trusted part says; and once the part still worth trying gains less
    than one unit of -2 log-likelihood, nothing is moving."""
    ident = fitted.identification
    problem, x = ident.problem, ident.x
    if problem is None or x is None or not problem.names:
        return []
    x = np.asarray(x, dtype=float)
    out = problem.fun(x)
    if out is None:
        return list(problem.names)
    e, J = out
    J = np.asarray(J.toarray() if hasattr(J, "toarray") else J, dtype=float)
    step, *_ = np.linalg.lstsq(J, e, rcond=None)
    m_eff = effective_samples(e, len(problem.compiled.output_names))
    cost = 0.5 * float(e @ e)
    sigma2 = 2 * cost / m_eff
    cov = sigma2 * np.linalg.pinv(J.T @ J, rcond=1e-12)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    t = _trusted_length(problem, x, step, cost, 0.5 * float(np.sum((J @ step) ** 2)), cost / m_eff)
    return [n for n, d, s in zip(problem.names, t * step, se, strict=True) if abs(d) > s]


def _trusted_length(problem: Problem, x: np.ndarray, step: np.ndarray, cost: float, predicted: float,
                    unit: float) -> float:
    """The longest t (1, then x_SHRINK) at which t x `step`, held inside the bounds and simulated, lowers `cost`
    by at least _TRUST of its linearised fall (2t - t²) x `predicted`; 0 once that fall is below one `unit` of
    -2 log-likelihood (in cost) untrusted."""
    lower, upper = problem.bounds()
    t = 1.0
    while predicted > 0 and unit > 0:
        fall = (2 * t - t * t) * predicted
        if fall < unit:
            return 0.0
        e = problem.residual(np.clip(x + t * step, lower, upper))
        if e is not None and cost - 0.5 * float(e @ e) >= _TRUST * fall:
            return t
        t *= _SHRINK
    return 1.0


def far_above_noise(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings, ratio: float) -> bool:
    """Whether the training residual RMS of `fitted` exceeds `ratio` x the noise read off the records' second
    differences (:func:`~flowchart2sdnn.identify.assess.noise.noise_level`); False where that cannot be told."""
    problem = _training_problem(fitted, train, settings)
    return problem is not None and _above_noise(fitted, problem, ratio)


def _training_problem(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> Problem | None:
    """The problem of `fitted`'s chart on the training records, None for a fit without a finite cost or a chart
    that no longer builds."""
    if not math.isfinite(fitted.cost) or getattr(fitted.identification, "problem", None) is None:
        return None
    try:
        return current_problem(fitted, train, settings)
    except (SdnnError, ValueError, KeyError):
        return None


def _above_noise(fitted: Fitted, problem: Problem, ratio: float) -> bool:
    m = sum(s.targets.size for s in problem.segments)
    return fitted.cost / max(1, m) > noise_cost(problem, ratio)


def current_problem(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> Problem:
    return build_problem(fitted.diagram, train[0], settings.alignment, settings.seed, more=tuple(train[1:]))


def _signals(problem: Problem, x: np.ndarray) -> dict[str, np.ndarray]:
    """Every neuron's output over all training records, concatenated like the residual."""
    parts = [problem.compiled.signals(x, s.inputs, s.init) for s in problem.segments]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _inputs(problem: Problem) -> np.ndarray:
    return np.vstack([s.inputs for s in problem.segments])


def effect_scales(problem: Problem) -> Scales:
    x = problem.compiled.theta0()
    sig = _signals(problem, x)
    rms = {k: float(np.sqrt(np.mean(v**2))) for k, v in sig.items() if np.all(np.isfinite(v))}
    # a signal's range: where a state limit (overflow) is scanned
    lo = {k: float(np.min(v)) for k, v in sig.items() if k in rms}
    hi = {k: float(np.max(v)) for k, v in sig.items() if k in rms}
    u_all = _inputs(problem)
    for i, name in enumerate(problem.compiled.input_names):
        u = u_all[:, i]
        rms[name] = float(np.sqrt(np.mean(u**2)))
        lo[name], hi[name] = float(np.min(u)), float(np.max(u))
    return Scales(rms, lo, hi)


def residual_analysis(fitted: Fitted, train: list[Dataset], settings: DiagnoseSettings) -> dict:
    """Whiteness, independence from the inputs and the internal signals most correlated with the residual."""
    problem = current_problem(fitted, train, settings)
    x = problem.compiled.theta0()
    e = problem.residual(x)
    if e is None:
        return {"error": "the fitted chart diverges on the training record"}
    e = e.reshape(-1, problem.compiled.n_outputs)
    u = _inputs(problem)
    out = whiteness(e, u, problem.compiled.output_names, problem.compiled.input_names)
    sig = _signals(problem, x)
    inputs = {n: u[:, i] for i, n in enumerate(problem.compiled.input_names)}
    out["signals"] = signal_correlation(e, {**inputs, **sig}, problem.compiled.output_names)
    return out
