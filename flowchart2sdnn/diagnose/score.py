"""The score test: how much would one Gauss-Newton step on the patched chart lower the cost?

At the current fit theta (cost E = 1/2 e^T e, model Jacobian J by RTRL), one undamped Gauss-Newton step
lowers the linearised cost by

    dGN(J, e) = 1/2 g^T (J^T J)^+ g = 1/2 || P_J e ||^2,        g = J^T e,

P_J the orthogonal projector onto the columns of J. A candidate is scored by the cost one GN step from the
patched chart would reach, against the cost one GN step from the current chart would reach:

    score = [E_base - dGN(J_base, e_base)] - [E_patch - dGN(J_patch, e_patch)].

Why the full step (old and new quantities together) rather than the new quantities alone: the new columns
are usually far from orthogonal to the old ones (a viscous term on one mass looks much like one on the
other when the shaft is stiff); restricted to the new quantities the predicted decrease counts again what
the old parameters already explain, and it ranks such look-alikes high. With both, the score is exactly the
decrease the new columns add *beyond* the old ones (for a neutral patch e_patch = e_base and
J_patch = [J_base, J_new], so score = 1/2 ||P_{J_new,perp} e||^2: Rao's efficient score statistic times
sigma^2 / 2), and it is zero for a candidate the chart can already imitate. Subtracting the base step makes
the score independent of how far the current fit is from converged. The same formula scores a patch that is
not neutral (a dead time, a clip inside the data range): there the patched chart starts from another cost.

(J^T J)^+ is applied through the eigen-decomposition of the Gram matrix of the column-normalised J, with
eigenvalues below ``RCOND`` times the largest dropped (the "tiny" regularisation: directions the data do not
determine are not stepped along). Columns that are exactly zero at the neutral point (the slopes of a learned
curve whose output weights are 0) drop out, which is right: to first order they cannot act yet.

Cost: every neutral candidate is patched into ONE chart (at the neutral point none of them changes the
outputs or the others' sensitivities), so one RTRL pass gives all their columns; each candidate is then a
small eigenproblem on its rows and columns of one Gram matrix. A candidate that is not neutral needs its own
pass: first the cost of each of its options by simulation, projected off the current chart's columns (what the
current quantities' own step would leave, the patched chart's sensitivities taken as the current one's), then the
full score for the ``top_options`` best by that cost.

Significance: under the hypothesis that the chart lacks nothing and the residual is white with variance
sigma^2, ``2 * score / sigma^2`` would be chi-square with ``dof`` degrees of freedom (the rank the candidate
adds, plus one for a scanned discrete choice). A fitted chart's residual is not white, and on long records that
statistic calls everything significant; the statistic and p-value reported are instead read against the
variance of the score under the residual's own noise spectrum (:mod:`.noise`: a chi-square score test for a
neutral candidate, a one-sided z test of the gain for one that changes the model). The p-value picks the places to
refit; acceptance is decided by the refits.
"""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable, Sequence

import numpy as np
from scipy.linalg import eigh
from scipy.stats import chi2

from .. import rules
from ..data.csvdata import Dataset
from ..diagram.curves import weight_names
from ..diagram.model import Diagram
from ..errors import SdnnError
from ..identify import Problem, build_problem
from .gauss_newton import (
    RCOND,
    after_current_step,
    column_norms,
    current_basis,
    decrease,
    gauss_newton_decrease,
    gram,
    solve,
)
from .noise import Layout, gain_test, score_test, step_residual
from .scored import Baseline, Candidate, Score, Screen

__all__ = ["RCOND", "Candidate", "Baseline", "Score", "Screen", "gauss_newton_decrease", "new_quantities", "screened",
           "screen"]

#: the joint pass holds when the chart with every neutral patch reproduces the residual to this fraction of its
#: largest value (rules.py)
NEUTRAL_ROUNDOFF = rules.value("neutral_roundoff")


def new_quantities(before: Diagram, after: Diagram) -> tuple[str, ...]:
    """theta names that `after` adds to `before`: new free parameters and the weights of new curves."""
    old_p = set(before.parameter_names)
    names = [p.name for p in after.parameters if p.name not in old_p and not p.fixed]
    old_b = set(before.block_names)
    for b in after.blocks:
        if b.kind == "nonlinear" and b.name not in old_b and not b.fixed:
            names += weight_names(after, b)
    return tuple(names)


# ------------------------------------------------------------------------------------------------ screen
def _significance(score: float, dof: int, base: Baseline) -> tuple[float, float]:
    stat = 2.0 * score / base.sigma2 if base.sigma2 > 0 else math.inf
    if dof <= 0 or not math.isfinite(stat):
        return stat, (1.0 if not stat > 0 else 0.0)
    return stat, float(chi2.sf(max(stat, 0.0), dof))


def _fun(problem: Problem):
    return problem.fun(problem.compiled.theta0())


def baseline_of(problem: Problem) -> tuple[Baseline, np.ndarray, np.ndarray]:
    out = _fun(problem)
    if out is None:
        raise SdnnError.at("DIAG010", "the current chart diverges on the training record; nothing to diagnose",
                           problem.diagram.file)
    e, J = out
    cost = 0.5 * float(e @ e)
    dec, rank = decrease(*gram(J, e), sign=_bound_sign(problem))
    sigma2 = 2 * cost / max(1, e.size - rank)
    layout = Layout(tuple(len(s.targets) for s in problem.segments), problem.targets.shape[1])
    return Baseline(cost, dec, rank, e.size, J.shape[1], sigma2, layout, step_residual(J, e),
                    tuple(problem.names)), e, J


def _neutral_significance(base: Baseline, Jo: np.ndarray, Jn: np.ndarray, e: np.ndarray,
                          coupling: np.ndarray | None = None) -> tuple[float, float]:
    """(statistic, p) of a neutral candidate's new columns `Jn` beyond the current ones `Jo` (both column-normalised;
    `coupling` = Jo⁺Jn when known) under the residual's noise (diagnose.noise.score_test)."""
    if coupling is None:
        coupling = np.linalg.lstsq(Jo, Jn, rcond=None)[0] if Jo.shape[1] else np.zeros((0, Jn.shape[1]))
    perp = Jn - Jo @ coupling
    # only the directions the new columns add beyond the current ones, as the score's own rank (RCOND of the unit
    # columns): what is left of a column the chart already has is round-off, and the test normalised by its own
    # tiny variance called it significant (a second learned curve at w1: score 0, p = 1e-23)
    w, V = eigh(perp.T @ perp, check_finite=False)
    keep = w > RCOND
    if not np.any(keep):
        return 0.0, 1.0
    stat, _, p = score_test(base.layout, perp @ V[:, keep], e, base.e_hat)
    return stat, p


def _scanned_significance(base: Baseline, e: np.ndarray, J: np.ndarray) -> tuple[float, float]:
    """(t, p) of a candidate that changes the model at once: its per-row gain over the current chart, each after
    its full Gauss-Newton step, under the residual's noise (diagnose.noise.gain_test)."""
    if e.shape != base.e_hat.shape:
        return math.nan, math.nan
    e_hat = step_residual(J, e)
    gain = 0.5 * (float(base.e_hat @ base.e_hat) - float(e_hat @ e_hat))
    return gain_test(base.layout, gain, e_hat, base.e_hat - e_hat)


def _bound_sign(problem: Problem) -> np.ndarray:
    """+1 for theta entries on their lower bound, -1 on their upper bound, else 0."""
    x = problem.compiled.theta0()
    spec = {p.name: p for p in problem.network.parameters}
    sign = np.zeros(x.size)
    for i, n in enumerate(problem.names):
        p = spec.get(n)
        if p is not None and p.min is not None and x[i] <= p.min:
            sign[i] = 1.0
        elif p is not None and p.max is not None and x[i] >= p.max:
            sign[i] = -1.0
    return sign


def _score_from(c: Candidate, e: np.ndarray, J: np.ndarray, base: Baseline, problem: Problem) -> Score:
    cost = 0.5 * float(e @ e)
    dec, rank, step = solve(*gram(J, e), sign=_bound_sign(problem))
    norms = column_norms(J)
    named = tuple(zip(problem.names, map(float, step / norms), strict=True))
    predicted = cost - dec
    score = base.gn_cost - predicted
    dof = max(rank - base.rank, 0) + c.effect.extra_dof
    stat, p = _significance(score, dof, base)
    if base.layout is not None and c.neutral:
        index = {n: i for i, n in enumerate(problem.names)}
        old = [index[n] for n in base.names if n in index]
        new = [i for i, n in enumerate(problem.names) if n not in set(base.names)]
        stat, p = _neutral_significance(base, J[:, old] / norms[old], J[:, new] / norms[new], e)
    elif base.layout is not None:
        stat, p = _scanned_significance(base, e, J)
    return Score(c, score, cost, predicted, dof, stat, p, step=named)


def _error(c: Candidate, text: str) -> Score:
    return Score(c, math.nan, math.nan, None, error=text)


def screened(c: Candidate) -> Diagram:
    """The chart a candidate is scored on: its own, or the effect's `screened(diagram)` where the effect scores
    a scanned choice with a quantity held (a dead time's tau at its n samples: free, the tau column made every
    n predict the same optimum, and the scan lost its ranking)."""
    hold = getattr(c.effect, "screened", None)
    return c.diagram if hold is None else hold(c.diagram)


def _build(diagram: Diagram, train: Sequence[Dataset], alignment: str, seed: int) -> Problem:
    return build_problem(diagram, train[0], alignment, seed, more=tuple(train[1:]))


def _screen_neutral(cands: Sequence[Candidate], current: Diagram, base_names: tuple[str, ...], e0: np.ndarray,
                    base: Baseline, train: Sequence[Dataset], alignment: str, seed: int) -> list[Score] | None:
    """All neutral candidates from one chart that holds them all; None when that chart cannot be built."""
    composed, groups = current, []
    for c in cands:
        before = composed
        try:
            composed = c.effect.patch(composed, c.place, c.option)
        except (SdnnError, ValueError, KeyError):
            return None
        groups.append((c, new_quantities(before, composed)))
    try:
        problem = _build(composed, train, alignment, seed)
    except SdnnError:
        return None
    out = _fun(problem)
    if out is None:
        return None
    e, J = out
    # neutral up to round-off: the composed chart sums its blocks in another order, which over 10^5 steps moves
    # the residual by ~1e-11 of its scale (two-mass drive, 30 s at N = 6); a patch that acts moves it by far more
    if e.shape != e0.shape or not np.allclose(e, e0, rtol=0.0, atol=NEUTRAL_ROUNDOFF * (1 + np.max(np.abs(e0)))):
        return None  # some patch was not neutral after all: score them one by one
    index = {n: i for i, n in enumerate(problem.names)}
    bound_sign = _bound_sign(problem)
    norms = column_norms(J)
    old = [index[n] for n in base_names]
    Jo = J[:, old] / norms[old]
    Goo, go = Jo.T @ Jo, Jo.T @ e
    w, V = eigh(Goo, check_finite=False)
    keep = w > RCOND * w[-1] if w.size and w[-1] > 0 else np.zeros(w.size, dtype=bool)
    Goo_pinv = (V[:, keep] / w[keep]) @ V[:, keep].T
    scores = []
    for c, new in groups:
        # only the blocks of the Gram matrix this candidate needs: old x old (shared), old x new, new x new
        cols = [index[n] for n in new if n in index]
        Jn = J[:, cols] / norms[cols]
        Gon = Jo.T @ Jn
        G = np.block([[Goo, Gon], [Gon.T, Jn.T @ Jn]])
        sign = np.concatenate([bound_sign[old], bound_sign[cols]])
        dec, rank, step = solve(G, np.concatenate([go, Jn.T @ e]), sign=sign)
        scaled = step / np.concatenate([norms[old], norms[cols]])  # back from the column-normalised units
        named = tuple(zip([problem.names[i] for i in old + cols], map(float, scaled), strict=True))
        predicted = base.cost - dec
        score = base.gn_cost - predicted
        dof = max(rank - base.rank, 0) + c.effect.extra_dof
        stat, p = _significance(score, dof, base)
        if base.layout is not None:
            stat, p = _neutral_significance(base, Jo, Jn, e, Goo_pinv @ Gon)
        scores.append(Score(c, score, base.cost, predicted, dof, stat, p, step=named))
    return scores


def _score_one(c: Candidate, base: Baseline, train: Sequence[Dataset], alignment: str, seed: int,
               problem: Problem | None = None) -> Score:
    if problem is None:
        try:
            problem = _build(screened(c), train, alignment, seed)
        except (SdnnError, ValueError, KeyError) as exc:
            return _error(c, _message(exc))
    out = _fun(problem)
    if out is None:
        return _error(c, _DIVERGES)
    return _score_from(c, out[0], out[1], base, problem)


def _message(exc: Exception) -> str:
    if isinstance(exc, SdnnError):
        return exc.diagnostics[0].one_line()
    return f"{type(exc).__name__}: {exc}"


_DIVERGES = "the patched chart diverges on the training record"


def scan_unit(unit: tuple) -> tuple[float | None, str | None, np.ndarray | None]:
    """One option of a candidate that changes the model, simulated: (candidate, train, alignment, seed) ->
    (cost, error, residual). Module level, so that any executor's worker runs it."""
    c, train, alignment, seed = unit
    try:
        p = _build(screened(c), train, alignment, seed)
        e = p.residual(p.compiled.theta0())
    except (SdnnError, ValueError, KeyError) as exc:
        return None, _message(exc), None
    return (None, _DIVERGES, None) if e is None else (0.5 * float(e @ e), None, e)


def score_unit(unit: tuple) -> Score:
    """One option's full score: (candidate, baseline, train, alignment, seed) -> Score (an RTRL pass)."""
    c, base, train, alignment, seed = unit
    return _score_one(c, base, train, alignment, seed)


def _map(executor, fn, units: list) -> list:
    """`fn` over `units` in order, by the executor when there is one and it can take them (an effect a user
    wrote may not pickle: then here)."""
    if executor is None or len(units) < 2:
        return list(map(fn, units))
    try:
        return list(executor.map(fn, units))
    except (pickle.PicklingError, TypeError, AttributeError):
        return list(map(fn, units))


def screen(candidates: Sequence[Candidate], problem: Problem, train: Sequence[Dataset], alignment: str = "zoh",
           seed: int = 0, top_options: int = 3,
           progress: Callable[[str, float | None], None] | None = None, executor=None) -> Screen:
    """Score every candidate against the current chart (`problem`, at its current values).

    Parameters
    ----------
    candidates : sequence of Candidate
        All patching ``problem.diagram``.
    problem : Problem
        The current chart on the training record; its theta0 is the current fit.
    train : sequence of Dataset
        The training record(s) `problem` was built from.
    top_options : int
        For an effect that is not neutral, the options (per place) with the lowest simulated cost after the
        current chart's own step that get the full score; the others keep only their simulated cost.
    executor : a :mod:`flowchart2sdnn.executors` executor, optional
        Runs the options' simulations and full scores (:func:`scan_unit`, :func:`score_unit`); the same results
        as in this process.

    Returns
    -------
    Screen
        Scores ranked best first; failures and cost-only options last.
    """
    import time

    t0 = time.perf_counter()
    train = [train] if isinstance(train, Dataset) else list(train)
    base, e0, J0 = baseline_of(problem)
    passes = {"jacobian": 1, "simulation": 0}
    neutral = [c for c in candidates if c.neutral]
    others = [c for c in candidates if not c.neutral]
    scores: list[Score] = []
    if neutral:
        if progress:
            progress(f"score test: {len(neutral)} neutral candidates in one pass", 0.0)
        joint = _screen_neutral(neutral, problem.diagram, problem.names, e0, base, train, alignment, seed)
        passes["jacobian"] += 1
        if joint is None:
            joint = [_score_one(c, base, train, alignment, seed) for c in neutral]
            passes["jacobian"] += len(neutral)
        scores += joint
    # not neutral: the cost of every option by simulation, the full score for the best few per place (both
    # independent work units, run by the executor when there is one)
    groups: dict[tuple[str, str], list[tuple]] = {}
    basis = current_basis(J0) if others else None
    if progress and others:
        progress(f"scan {len(others)} options of candidates that change the model", None)
    for c, (cost, err, e) in zip(others, _map(executor, scan_unit, [(c, train, alignment, seed) for c in others]),
                                 strict=True):
        passes["simulation"] += err is None or err == _DIVERGES
        rank_cost = None if cost is None else after_current_step(e, basis) if e.shape == e0.shape else cost
        groups.setdefault(c.key, []).append((c, cost, err, rank_cost))
    full, rest = [], []
    for items in groups.values():
        # the options of one place in the order of their cost after the current chart's own step (the patched
        # chart's sensitivities taken as the current one's): a scan's best option by its plain cost is not the
        # best once the other quantities move (a dead time's n), and the full score of every option cost an RTRL
        # pass each, 90 a round on the two-mass drive
        ok = sorted((x for x in items if x[1] is not None), key=lambda x: x[3])
        full += [c for c, *_ in ok[:top_options]]
        rest += [Score(c, math.nan, cost, None) for c, cost, *_ in ok[top_options:]]
        rest += [_error(c, err or "failed") for c, cost, err, _ in items if cost is None]
    scores += _map(executor, score_unit, [(c, base, train, alignment, seed) for c in full]) + rest
    passes["jacobian"] += len(full)
    ranked = sorted(scores, key=lambda s: (not s.scored, -(s.score if s.scored else 0.0)))
    return Screen(base, tuple(ranked), time.perf_counter() - t0, passes)
