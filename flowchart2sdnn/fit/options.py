"""The settings of Levenberg-Marquardt (:class:`LMOptions`, validated at construction) and its outcome
(:class:`LMResult`). Both are reached as ``flowchart2sdnn.fit.lm.LMOptions`` and ``.LMResult`` too, where they
were first defined. The defaults are rules of :mod:`flowchart2sdnn.rules`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import rules
from .damping import TRAINLM_MU0
from .stopping import CONVERGED_STATUSES

__all__ = ["LMOptions", "LMResult"]


@dataclass(frozen=True)
class LMOptions:
    """Settings of :func:`levenberg_marquardt` (names and defaults follow MATLAB's ``trainlm``).

    ``mu_min`` keeps mu from underflowing after a long run of accepted steps, so that a later rejection
    can raise it back to a useful size within ``max_mu_tries`` tries.

    ``tau`` > 0 scales the first damping to the problem: ``mu = max(mu0, tau * max diag(JᵀJ))`` at the start
    (Madsen, Nielsen & Tingleff, *Methods for non-linear least squares problems*, 2004, section 3.2).
    trainlm's fixed ``mu0`` makes the first steps of a long record (diag(JᵀJ) of 1e6 and more) undamped
    Gauss-Newton steps that jump across narrow cost valleys; 0 keeps trainlm's behaviour.

    ``scale = "jac"`` damps each quantity in proportion to its own curvature, ``(JᵀJ + mu D²) du = Jᵀe`` with
    D the largest column norms of J_u seen so far (Moré 1978, MINPACK's ``lmder``, scipy's ``x_scale='jac'``):
    the step no longer depends on the units of the quantities (a stiffness of 500 N·m/rad next to an inertia
    of 0.4 kg·m²); ``mu`` is then relative (``tau * max diag`` becomes ``tau``). "none" is trainlm's ``mu I``.
    ``scale_groups`` (one integer per quantity, optional) makes quantities of one group share one D, the
    largest of their column norms: a learned curve's weights are numbers of one kind whose columns come and
    go with saturation, and damped apart they crawl (the bundled engine example: 1000 iterations unconverged
    with a D per weight, converged with one D for all of them).

    ``stall_decrease`` > 0 ends a fit as converged ("small_cost_change") once the cost has fallen by less than that fraction of itself
    over the last ``stall_iterations`` accepted iterations: one iteration's gain says little (a large mu makes
    it small), ten in a row that together gain nothing that matters do.

    ``crawl_decrease`` > 0 ends a fit as converged ("small_cost_change") once the cost, at or below
    ``crawl_cost``, has fallen by less than that fraction of itself over the last ``crawl_iterations`` accepted
    iterations. It is the stall rule over a longer window, for a fit that is already at the noise floor and creeps
    along a direction the data barely determine (a learned curve's slope traded against a viscous term: the
    three-mass learned chart's draw 9 gained 0.3-0.7 E/N per 100 iterations for more than 1000 iterations,
    above the stall rule's 0.1, with its cost within 1 % of the noise's).

    ``negligible_gain`` > 0 ends a fit as converged ("negligible_gain") wherever it is, at the noise floor or
    far above it, once the undamped Gauss-Newton step predicts a fall of -2 log-likelihood below that many units
    at the residual's own variance (m dE / E for m residuals: the Newton decrement, the step's length in the
    metric of the parameters' covariance, so it is blind to units and scaling) and the last accepted step
    gained less than that too. Quantities the step pushes against a bound they are within one standard error
    of (box bounds) are held there for the prediction. ``negligible_pace`` > 0 ends it the same way once the last
    ``pace_iterations`` accepted iterations together gained less than that many units while Gauss-Newton's
    unconstrained step predicts less than ``pace_left`` (3.84, what a test at the 5 % level can see): a descent
    held by bounds, the stability guard or a trust radius, near a minimum that step cannot reach. ``residual_stride`` > 0 (the residual laid out as rows of
    that many outputs) counts the residual's independent samples (:mod:`.effective`: its length over its
    autocorrelation time) instead of its entries: a residual that is mostly a missing effect or coloured noise
    weighs a fall of the cost by what it holds.

    ``damping = "nielsen"`` moves mu by the gain ratio rho of each accepted step (actual over predicted decrease):
    ``mu *= max(1/3, 1 - (2 rho - 1)^3)``, and by 2, 4, 8, ... on refusals in a row (:mod:`.damping`);
    "trainlm" is ``mu_dec`` / ``mu_inc``. ``damping = "trust"`` sets each step's length instead (Moré 1978, as
    MINPACK and scipy's trf): mu is the smallest damping whose scaled step fits a trust radius (0 where the
    Gauss-Newton step fits), the radius starts at the start's scaled size and becomes a quarter of the step after
    a refusal or a poor gain ratio (< 0.25), twice the step after a good one (> 0.75); ``mu_history`` then holds
    the radius. Where mu is small beside JᵀJ, raising it barely shortens the step, so Nielsen's x2, x4, ... take
    several refused trials to act; the radius acts at once. A trust-radius fit also ends as converged
    ("small_cost_change") when the Gauss-Newton step fits the radius, or a trial follows a refusal, and predicts a
    decrease below ``stopping.COST_ROUNDING`` of the cost, which the cost cannot show. ``trial_jacobian = True``
    simulates the first trial of an iteration with its Jacobian (``fun``) instead of ``residual`` alone:
    accepted, it needs no second simulation; later trials of the iteration (after a refusal) stay residual-only.
    With the trust radius every trial is simulated with its Jacobian (after a refusal the step is a quarter of the
    refused one, mostly accepted) except one more than ``LONG_STEP`` times longer (scaled) than the last accepted
    step (mostly refused). Either way the iterates are the same; only the count of simulations differs.
    ``bound_width`` > 0 makes each one-sided bound's transform bend within that fraction of the start's distance
    from the bound (:meth:`.transforms.Bounds.with_width`); 0 keeps the unit transform.

    ``bounds = "box"`` handles the bounds without a transform: steps in the physical (column-scaled) coordinates,
    each component held within 0.995 of its room to the bound it moves towards and the others re-solved around
    it (:mod:`.boxstep`), every iterate strictly feasible, as bounded trust-region methods do. It needs plain
    steps (``geodesic = 0``) and the unit transform's width (``bound_width = 0``). "transform" is the change of
    variables of :mod:`.transforms`.
    """

    max_iter: int = rules.value("lm_max_iter")
    mu0: float = TRAINLM_MU0
    mu_inc: float = rules.value("lm_mu_inc")
    mu_dec: float = rules.value("lm_mu_dec")
    mu_max: float = rules.value("lm_mu_max")
    min_grad: float = rules.value("lm_min_grad")
    cost_goal: float = rules.value("lm_cost_goal")
    min_rel_step: float = rules.value("lm_min_rel_step")
    min_rel_cost_change: float = rules.value("lm_min_rel_cost_change")
    stall_decrease: float = rules.value("lm_stall_decrease")
    stall_iterations: int = rules.value("lm_stall_iterations")
    crawl_decrease: float = rules.value("lm_crawl_decrease")
    crawl_iterations: int = rules.value("crawl_iterations")
    crawl_cost: float = rules.value("lm_crawl_cost")
    negligible_gain: float = rules.value("lm_negligible_gain")
    negligible_pace: float = rules.value("lm_negligible_pace")
    pace_iterations: int = rules.value("pace_iterations")
    pace_left: float = rules.value("pace_left")
    residual_stride: int = rules.value("lm_residual_stride")
    max_mu_tries: int = rules.value("lm_max_mu_tries")
    mu_min: float = rules.value("lm_mu_min")
    tau: float = rules.value("lm_tau")
    scale: str = "none"
    scale_groups: tuple[int, ...] = ()
    geodesic: float = rules.value("lm_geodesic")
    damping: str = "trainlm"
    trial_jacobian: bool = False
    bound_width: float = rules.value("lm_bound_width")
    bounds: str = "transform"

    def __post_init__(self) -> None:
        def need(cond: bool, text: str) -> None:
            if not cond:
                raise ValueError(text)

        for name in (
            "mu0",
            "mu_inc",
            "mu_dec",
            "mu_max",
            "min_grad",
            "cost_goal",
            "min_rel_step",
            "min_rel_cost_change",
            "stall_decrease",
            "crawl_decrease",
            "negligible_gain",
            "negligible_pace",
            "pace_left",
            "mu_min",
            "tau",
        ):
            need(math.isfinite(getattr(self, name)), f"`{name}` must be finite, got {getattr(self, name)}")
        need(
            isinstance(self.max_iter, int) and self.max_iter >= 0,
            f"`max_iter` must be an int >= 0, got {self.max_iter!r}",
        )
        need(
            isinstance(self.max_mu_tries, int) and self.max_mu_tries >= 1,
            f"`max_mu_tries` must be an int >= 1, got {self.max_mu_tries!r}",
        )
        need(0 < self.mu_min <= self.mu0 <= self.mu_max, "need 0 < `mu_min` <= `mu0` <= `mu_max`")
        need(self.mu_inc > 1, f"`mu_inc` must be > 1, got {self.mu_inc}")
        need(0 < self.mu_dec < 1, f"`mu_dec` must be in (0, 1), got {self.mu_dec}")
        need(isinstance(self.stall_iterations, int) and self.stall_iterations >= 1,
             f"`stall_iterations` must be an int >= 1, got {self.stall_iterations!r}")
        need(isinstance(self.crawl_iterations, int) and self.crawl_iterations >= 1,
             f"`crawl_iterations` must be an int >= 1, got {self.crawl_iterations!r}")
        need(not math.isnan(self.crawl_cost), "`crawl_cost` must be a number or inf, got nan")
        need(isinstance(self.pace_iterations, int) and self.pace_iterations >= 1,
             f"`pace_iterations` must be an int >= 1, got {self.pace_iterations!r}")
        need(isinstance(self.residual_stride, int) and self.residual_stride >= 0,
             f"`residual_stride` must be an int >= 0, got {self.residual_stride!r}")
        need(self.damping in ("trainlm", "nielsen", "trust"),
             f"`damping` must be 'trainlm', 'nielsen' or 'trust', got {self.damping!r}")
        need(self.scale in ("none", "jac"), f"`scale` must be 'none' or 'jac', got {self.scale!r}")
        need(all(isinstance(g, int) for g in self.scale_groups), "`scale_groups` must be integers, one per quantity")
        need(math.isfinite(self.bound_width) and self.bound_width >= 0,
             f"`bound_width` must be a finite number >= 0, got {self.bound_width}")
        need(math.isfinite(self.geodesic) and 0 <= self.geodesic < 2, f"`geodesic` must be in [0, 2), got {self.geodesic}")
        need(self.bounds in ("transform", "box"), f"`bounds` must be 'transform' or 'box', got {self.bounds!r}")
        need(self.bounds == "transform" or (self.geodesic == 0 and self.bound_width == 0),
             "`bounds='box'` takes plain steps in the physical coordinates: it needs `geodesic` = 0 and "
             f"`bound_width` = 0, got {self.geodesic} and {self.bound_width}")
        for name in ("min_grad", "cost_goal", "min_rel_step", "min_rel_cost_change", "stall_decrease", "crawl_decrease",
                     "tau"):
            need(getattr(self, name) >= 0, f"`{name}` must be >= 0, got {getattr(self, name)}")


@dataclass(frozen=True, eq=False)
class LMResult:
    """Outcome of :func:`levenberg_marquardt`; arrays are read-only.

    Attributes
    ----------
    x : ndarray (P,)            final (best) values, external coordinates
    cost : float                E = 1/2 e^T e at ``x`` (inf only for "diverged_at_start")
    status, message : str       a key of ``STATUS_MESSAGES`` and a sentence with details
    iterations : int            accepted steps
    cost_history, mu_history : tuple of float, length iterations + 1 (start value, then after each step; for
                                ``damping="trust"`` the trust radius)
    jac : ndarray (M, P)        last model Jacobian d yhat / d x at ``x`` (external coordinates; a CSR
                                matrix when ``fun`` returns sparse Jacobians)
    residual : ndarray (M,)     e = y - yhat at ``x``
    nfev, njev : int            residual and Jacobian evaluations
    interrupted : bool          True after a KeyboardInterrupt
    names : tuple of str        quantity names
    mu : float                  damping when the run stopped (may exceed ``mu_max``); a quasi-online
                                caller can start the next window from it
    rejected_cost, rejected_diverged, rejected_guard : int   trial steps rejected, by reason
    last_guard_reason : str or None                          the guard's last refusal
    stages : tuple of dict      earlier stages of a staged fit whose last stage this is (multiple shooting,
                                identify.shooting.multiple), each a summary; () for a plain fit
    """

    x: np.ndarray
    cost: float
    status: str
    message: str
    iterations: int
    cost_history: tuple[float, ...]
    mu_history: tuple[float, ...]
    jac: np.ndarray
    residual: np.ndarray
    nfev: int
    njev: int
    interrupted: bool = False
    names: tuple[str, ...] = ()
    mu: float = math.nan
    rejected_cost: int = 0
    rejected_diverged: int = 0
    rejected_guard: int = 0
    last_guard_reason: str | None = None
    stages: tuple = ()

    @property
    def converged(self) -> bool:
        """True when a stopping rule of ``CONVERGED_STATUSES`` ended the run."""
        return self.status in CONVERGED_STATUSES
