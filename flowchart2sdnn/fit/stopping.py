"""The stopping rules of Levenberg-Marquardt (:mod:`.lm`), each a named predicate that returns its one
:class:`Stop` (status and the detail the message carries) where it ends the fit, else None.

The loop asks them in a fixed order, and the order is part of the result: before a step, :func:`cost_goal`,
then (on the normal equations) :func:`min_grad`, :func:`max_iter`, :func:`mu_max`, :func:`negligible_gain`;
during a step's trials, :func:`rounding` (trust radius), :func:`small_step` on a refused trial at rounding
level, :func:`mu_max` after a refusal and :func:`max_mu_tries`; after an accepted step, :func:`small_step`,
:func:`min_rel_cost_change`, :func:`stall`, :func:`crawl`. ``opt`` is the fit's :class:`~.lm.LMOptions`;
their defaults are rules of :mod:`flowchart2sdnn.rules`. A new rule is a predicate here, its option in
``LMOptions``, and its place in the loop's order (CONTRIBUTING.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import rules
from .effective import effective_samples
from .transforms import Bounds

__all__ = ["Stop", "STATUS_MESSAGES", "CONVERGED_STATUSES", "CRAWL_DETAIL", "COST_ROUNDING", "gauss_newton_gain",
           "cost_goal", "min_grad", "max_iter", "mu_max", "negligible_gain", "rounding", "max_mu_tries",
           "small_step", "min_rel_cost_change", "stall", "crawl"]

#: Status code -> message (scipy style).  ``LMResult.message`` starts with one of these.
STATUS_MESSAGES: dict[str, str] = {
    "diverged_at_start": "the model diverged (no finite output) at the start values; choose other start values",
    "min_grad": "the gradient norm fell below `min_grad`",
    "cost_goal": "the cost reached `cost_goal`",
    "max_iter": "the iteration limit `max_iter` was reached",
    "mu_max": "mu exceeded `mu_max`: no damped step lowers the cost (a local minimum, or rejected steps)",
    "max_mu_tries": "`max_mu_tries` increases of mu in a row did not find a step that lowers the cost",
    "small_step": "the relative step fell below `min_rel_step`",
    "small_cost_change": "the cost stopped falling: its relative decrease fell below `min_rel_cost_change` in one "
                         "iteration, or below `stall_decrease` over the last `stall_iterations`, or, at the noise floor "
                         "(`crawl_cost`), below `crawl_decrease` over the last `crawl_iterations` (or, with the "
                         "trust radius, the model's best decrease is below the cost's rounding)",
    "negligible_gain": "what is left to gain is negligible (in units of -2 log-likelihood at the residual's own "
                       "variance)",
    "callback_stop": "stopped by the callback",
    "interrupted": "interrupted (KeyboardInterrupt); the best point so far is returned",
}


#: Statuses that mean "a (local) minimum was reached" rather than "stopped early".
CONVERGED_STATUSES = frozenset({"min_grad", "cost_goal", "mu_max", "small_step", "small_cost_change",
                                "negligible_gain"})


@dataclass(frozen=True)
class Stop:
    """A stopping rule fired: ``status`` (a key of STATUS_MESSAGES) and the numbers it saw (``detail``)."""

    status: str
    detail: str = ""


# ------------------------------------------------------------------------------ before a step
def cost_goal(cost: float, opt) -> Stop | None:
    """The cost reached ``cost_goal``."""
    return Stop("cost_goal") if cost <= opt.cost_goal else None


def min_grad(g: np.ndarray, opt) -> Stop | None:
    """The gradient ``g = J_uᵀe`` is shorter than ``min_grad``."""
    gnorm = float(np.linalg.norm(g))
    return Stop("min_grad", f"|grad| = {gnorm:.3g}") if gnorm < opt.min_grad else None


def max_iter(iteration: int, opt) -> Stop | None:
    """``max_iter`` steps were accepted."""
    return Stop("max_iter") if iteration >= opt.max_iter else None


def mu_max(mu: float, opt) -> Stop | None:
    """The damping grew past ``mu_max`` (not with the trust radius, whose mu is found per step)."""
    return Stop("mu_max") if mu > opt.mu_max and opt.damping != "trust" else None


def negligible_gain(point, A: np.ndarray, g: np.ndarray, costs: tuple[float, ...], box: Bounds | None,
                    opt) -> Stop | None:
    """What is left to gain, or the recent pace, is negligible in units of -2 log-likelihood
    (``negligible_gain``, ``negligible_pace``; :class:`~.lm.LMOptions`)."""
    if not ((opt.negligible_gain > 0 or opt.negligible_pace > 0) and len(costs) > 1):
        return None
    said = _negligible(point, A, g, costs, box, opt)
    return Stop("negligible_gain", said) if said is not None else None


# ------------------------------------------------------------------------------ during a step's trials
def rounding(tries: int, mu: float, predicted: float, cost: float) -> Stop | None:
    """Trust radius only: the Gauss-Newton step fits the radius (mu 0), or a trial follows a refusal, and the
    model's decrease is below what the cost can show (COST_ROUNDING of it): converged. Simulating it, then ever
    shorter steps, only draws rounding (the bench's L = 100 run refused 14 such trials after converging)."""
    if (tries > 0 or mu == 0.0) and predicted <= COST_ROUNDING * cost:
        return Stop("small_cost_change", "the model's best decrease is below the cost's rounding")
    return None


def max_mu_tries() -> Stop:
    """``max_mu_tries`` trials in a row were refused."""
    return Stop("max_mu_tries")


# ------------------------------------------------------------------------------ after a step (or a refused one)
def small_step(tiny: bool) -> Stop | None:
    """The step was below ``min_rel_step`` of the parameters' size."""
    return Stop("small_step") if tiny else None


def min_rel_cost_change(before: float, after: float, opt) -> Stop | None:
    """The accepted step lowered the cost by less than ``min_rel_cost_change`` of itself."""
    rel_decrease = (before - after) / before if before > 0 else 0.0
    if 0 < opt.min_rel_cost_change and rel_decrease < opt.min_rel_cost_change:
        return Stop("small_cost_change", f"relative decrease {rel_decrease:.3g}")
    return None


def stall(costs: tuple[float, ...], cost: float, opt) -> Stop | None:
    """The last ``stall_iterations`` steps together lowered the cost by less than ``stall_decrease`` of it
    (``costs``: the start's and each accepted step's before this one; ``cost``: this one's)."""
    if 0 < opt.stall_decrease and len(costs) > opt.stall_iterations:
        gained = (costs[-opt.stall_iterations] - cost) / cost
        if gained < opt.stall_decrease:
            return Stop("small_cost_change",
                        f"{gained:.3g} of the cost over the last {opt.stall_iterations} iterations")
    return None


def crawl(costs: tuple[float, ...], opt) -> Stop | None:
    """At the noise floor (``crawl_cost``) the last ``crawl_iterations`` steps gained less than
    ``crawl_decrease`` of the cost (``costs`` up to this step's)."""
    crawled = _crawl_gain(costs, opt)
    if crawled is None:
        return None
    return Stop("small_cost_change",
                f"{CRAWL_DETAIL}: {crawled:.3g} of the cost over the last {opt.crawl_iterations} iterations")


# ------------------------------------------------------------------------------ the rules' arithmetic

def gauss_newton_gain(A: np.ndarray, g: np.ndarray, x: np.ndarray | None = None, box: Bounds | None = None,
                      sigma2: float = 1.0) -> float:
    """1/2 gᵀA⁺g, the cost E's fall the undamped Gauss-Newton step predicts, with quantities that the step
    pushes against a box bound closer than one standard error (sqrt(sigma2 (A⁺)_ii)) held at it."""
    d = np.sqrt(np.clip(np.diag(A), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    As, gs = A / np.outer(d, d), g / d
    free = np.ones(g.size, dtype=bool)
    for _ in range(3):
        idx = np.flatnonzero(free)
        if idx.size == 0:
            return 0.0
        w, V = np.linalg.eigh(As[np.ix_(idx, idx)])
        keep = w > max(float(w.max()), 0.0) * 1e-12
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        ys = inv @ gs[idx]
        if box is None or x is None:
            break
        step, se = ys / d[idx], np.sqrt(np.clip(sigma2 * np.diag(inv), 0.0, None)) / d[idx]
        xi, lo, hi = x[idx], box.lower[idx], box.upper[idx]
        held = ((xi + step < lo) & (xi - lo < se)) | ((xi + step > hi) & (hi - xi < se))
        if not held.any():
            break
        free[idx[held]] = False
    return 0.5 * float(gs[idx] @ ys)


def _negligible(point, A, g, costs, box, opt) -> str | None:
    """The negligible-gain rule of :class:`LMOptions`: the detail of the status where it ends the fit."""
    m = point.e.size
    if not point.cost > 0 or m == 0:
        return None
    if opt.residual_stride > 0:  # a correlated residual holds fewer independent samples than it has entries
        m = effective_samples(point.e, opt.residual_stride)
    unit = point.cost / m  # one unit of -2 log-likelihood in E, at the residual's own variance
    k = opt.pace_iterations
    gained = (costs[-2] - costs[-1]) / unit
    paced = (costs[-1 - k] - costs[-1]) / unit if opt.negligible_pace > 0 and len(costs) > k else math.inf
    if gained >= opt.negligible_gain and paced >= opt.negligible_pace:
        return None
    left = gauss_newton_gain(A, g, point.x, box, 2.0 * unit) / unit
    if gained < opt.negligible_gain and left < opt.negligible_gain:
        return f"{left:.3g} units left by Gauss-Newton, {gained:.3g} gained by the last step"
    if paced < opt.negligible_pace and left < opt.pace_left:
        return f"{paced:.3g} units gained by the last {k} iterations, {left:.3g} left by Gauss-Newton"
    return None


#: The crawl rule's words in LMResult.message (identify warns on them).
CRAWL_DETAIL = "a crawl at the noise floor"


def _crawl_gain(costs: tuple[float, ...], opt) -> float | None:
    """The crawl rule of :class:`LMOptions` on the costs so far (start, then one per accepted step): the window's
    gain as a fraction of the cost where the rule ends the fit, else None."""
    if not (0 < opt.crawl_decrease and len(costs) > opt.crawl_iterations and costs[-1] <= opt.crawl_cost):
        return None
    gained = (costs[-1 - opt.crawl_iterations] - costs[-1]) / costs[-1]
    return gained if gained < opt.crawl_decrease else None


#: The trust radius's fit ends as converged when the Gauss-Newton step's predicted decrease is below this fraction
#: of the cost: a change the cost cannot show (on the two-mass bench, 50 000 residuals, trials at the minimum
#: changed the cost by up to 1.6e-13 of itself whatever the model predicted, 1e-17 or 1e-12 of it).
COST_ROUNDING = rules.value("cost_rounding")
