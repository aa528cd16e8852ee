"""The discretization's bias on each parameter, by a parametric-bootstrap refit (identify, on by default).

A fit bends the parameters to absorb the network's own step error (identify.assess.floor): at the optimum theta^ of
the data the network matches the machine, not the chart at theta^. To see by how much, the continuous oracle
runs the *fitted* chart (theta^) on the training input, from the same initial states; that noise-free record is
what a plant with exactly theta^ would have given. The network fits it from theta^ (a few LM iterations: the
start is next to its optimum) -> theta~. beta = theta~ - theta^ is the shift the discretization adds at this
point, and theta^ - beta the estimate with it removed (first order: beta changes little between the truth and
theta^). The interval from the Jacobian reflects the noise only; beta is what it cannot see, so identify widens
it by |beta| on both sides (ci95; the noise's alone stays as ci95_noise). With 0.01 rad/s noise on the Coulomb
benches (auto N, seeds 1-10) that took the parameters whose interval covers the truth 8 in 10 times from 13 of 21
to 21 of 21, at x1.24-1.33 the fit's time (benchmarks/bench_floor_acceptance.py).

Layer: identify (below it: simulate's oracle through identify.assess.floor, fit, network, data).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from ... import rules
from ...data.csvdata import Dataset
from ...diagram.model import Diagram
from ...fit.lm import LMOptions
from ...network.alignment import fitted_rows
from ...notices import Notice
from ..offline.problem import Problem
from ..offline.workers import run_start
from .floor import oracle_runs, oracle_steps

__all__ = ["BIAS_ITER", "BETA_SETTLED", "BIAS_WARN", "estimate_floor_bias", "floor_bias_warnings"]

#: LM iterations of the bootstrap refit. It starts at theta^, a distance beta (a fraction of a standard error to
#: a few) from its optimum, on noise-free data, and converges in a few steps: 6-13 on the Coulomb benches (20 s,
#: auto), 17 at N = 1; stopped after 3, three-mass d1's beta was 0.41 standard errors against 0.98 converged.
BIAS_ITER = rules.value("bias_iter")
#: A refit still unconverged after 2 x BIAS_ITER iterations counts as settled when beta moved by less than this
#: fraction over the second half (the engine example: its learned friction curve's weights crawl on for hundreds of
#: iterations, J1's beta moves 1.5 % from 20 to 40 iterations and 0.01 % from 50 to 300).
BETA_SETTLED = rules.value("beta_settled")
#: Warn when |beta| exceeds this many standard errors: from there a 95 % interval (about +-2 standard errors)
#: centred on theta^ misses the truth visibly more often than 1 in 20.
BIAS_WARN = rules.value("bias_warn")


def _oracle_problem(problem: Problem, chart: Diagram, records: Sequence[Dataset],
                    oracle: Sequence[np.ndarray] | None = None) -> Problem:
    """`problem` with every record's targets replaced by the continuous oracle's run of `chart` (same rows;
    `oracle`: those runs when already computed, floor.oracle_runs)."""
    if oracle is None:
        oracle = oracle_runs(chart, records, problem.alignment, problem.compiled)
    targets = [np.ascontiguousarray(y[fitted_rows(d.n_rows, problem.alignment)])
               for d, y in zip(records, oracle, strict=True)]
    segs = problem.segments
    if len(targets) != len(segs) or any(t.shape != s.targets.shape for t, s in zip(targets, segs, strict=False)):
        raise ValueError("the oracle's rows do not match the fitted rows")
    return replace(problem, targets=targets[0], extra=tuple(replace(s, targets=t)
                                                            for s, t in zip(segs[1:], targets[1:], strict=True)))


def _physical(problem: Problem, x: np.ndarray, names) -> dict[str, float]:
    """The physical parameters `names` at the problem's point `x` (per-record values at their mean)."""
    values, _ = problem.compiled.values(problem.mean_x(x))
    return {n: float(values[n]) for n in names}


def estimate_floor_bias(problem: Problem, chart: Diagram, xs: np.ndarray, records: Sequence[Dataset],
                        lower: np.ndarray, upper: np.ndarray, options: LMOptions,
                        estimates: Mapping[str, tuple[float, float | None, tuple[float, float] | None]],
                        oracle: Sequence[np.ndarray] | None = None) -> dict:
    """RESULT.json's `discretization.bias`: beta per identified parameter, the corrected values and intervals.

    Parameters
    ----------
    problem : the fitted Problem; chart : the identified chart (the values `xs` stands for, N resolved)
    xs : ndarray (P,)  the fit's point (per-record values included); records : the training records, in order
    lower, upper, options : the fit's bounds and LM options (the refit runs BIAS_ITER iterations of them)
    estimates : {name: (value, stderr or None, (lo, hi) or None)} of the identified physical parameters
    oracle : the oracle's runs on `records` when already computed (floor.oracle_runs), else computed here

    Returns
    -------
    dict: ``beta`` {name: beta}, ``corrected`` {name: {"value", "ci95"}} (the interval shifted by -beta),
    ``widened`` {name: ci95 widened by |beta| on both sides}, ``ratio`` {name: |beta| / stderr}, ``refit``
    (iterations, status, cost, ``beta_change``: where the first BIAS_ITER iterations did not converge, the largest
    relative change of beta over as many more, else None; method; no wall time: the same inputs give
    byte-identical files); or ``{"beta": None, "skipped": why}``.
    """
    if problem.record_params:  # the identified chart holds their mean: the oracle would run every record at it
        return {"beta": None, "skipped": "per-record parameters (" + ", ".join(problem.record_params) + "): the "
                "identified chart holds their mean, and the oracle would run every record at it"}
    try:
        oracle = _oracle_problem(problem, chart, records, oracle)
    except (ValueError, KeyError) as exc:  # the oracle's refusals (e.g. a blow-up) are ValueErrors
        return {"beta": None, "skipped": f"the continuous oracle cannot run this chart: {exc}"}
    if not all(np.all(np.isfinite(s.targets)) for s in oracle.segments):
        return {"beta": None, "skipped": "the continuous oracle diverges on these records"}
    opts = replace(options, max_iter=BIAS_ITER)
    try:
        lm = run_start(oracle, np.asarray(xs, dtype=float), lower, upper, opts)
        if not np.all(np.isfinite(lm.x)) or lm.status == "diverged_at_start":
            return {"beta": None, "skipped": f"the refit on the oracle's record failed ({lm.status})"}
        iterations, change = int(lm.iterations), None
        if lm.status == "max_iter":
            # not converged: often only learned curves' weights still crawl along flat directions while the
            # physical parameters have settled; run as many iterations again and see how far beta moves
            first = _physical(problem, lm.x, estimates)
            more = run_start(oracle, np.asarray(lm.x, dtype=float), lower, upper, opts)
            if np.all(np.isfinite(more.x)) and more.status != "diverged_at_start":
                lm, iterations = more, iterations + int(more.iterations)
                now = _physical(problem, lm.x, estimates)
                change = max((abs(now[n] - first[n]) / abs(now[n] - estimates[n][0])
                              for n in estimates if now[n] != estimates[n][0]), default=0.0)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:  # the fit itself ran: say why, go on
        return {"beta": None, "skipped": f"the refit on the oracle's record failed: {exc}"}
    refitted = _physical(problem, lm.x, estimates)
    beta, corrected, widened, ratio = {}, {}, {}, {}
    for name, (value, stderr, ci) in estimates.items():
        b = refitted[name] - value
        beta[name] = b
        corrected[name] = {"value": value - b, "ci95": None if ci is None else [ci[0] - b, ci[1] - b]}
        widened[name] = None if ci is None else [ci[0] - abs(b), ci[1] + abs(b)]
        ratio[name] = None if not stderr else abs(b) / stderr
    return {"beta": beta, "corrected": corrected, "widened": widened, "ratio": ratio,
            "refit": {"iterations": iterations, "status": lm.status, "cost": float(lm.cost), "beta_change": change,
                      "method": f"the network refitted from the identified values to the continuous oracle's "
                                f"noise-free run of the identified chart (RK4, {oracle_steps(problem.network.substeps)}"
                                f" steps per sample, training input), {BIAS_ITER} LM iterations (as many more where "
                                f"unconverged); beta = refitted - identified, corrected = identified - beta"}}


def floor_bias_warnings(bias: dict, stderr: Mapping[str, float | None]) -> list[Notice]:
    """One warning naming every parameter whose |beta| exceeds BIAS_WARN of its standard error."""
    beta = bias.get("beta")
    if not beta:
        return []
    out = []
    refit = bias.get("refit") or {}
    if refit.get("status") == "max_iter" and (refit.get("beta_change") or 0.0) > BETA_SETTLED:
        out.append(Notice("FLOOR003", f"the discretization-bias refit did not converge in {refit.get('iterations')} "
                          f"iterations and beta still moved by {100 * refit['beta_change']:.0f} % over the last "
                          f"half: it is a first-order estimate that may fall short (the bias is large; more "
                          f"sub-steps shrink it)",
                          {"iterations": refit.get("iterations"), "beta_change": refit["beta_change"]},
                          "use more sub-steps"))
    over, shifted = [], {}
    for name, b in beta.items():
        s = stderr.get(name)
        if s and abs(b) > BIAS_WARN * s:
            over.append(f"{name} by {b:+.3g} ({abs(b) / s:.1f} standard errors)")
            shifted[name] = {"beta": b, "standard_errors": abs(b) / s}
    if not over:
        return out
    return out + [Notice("FLOOR004", f"the noise-only 95 % intervals (ci95_noise) reflect the noise only; the "
                         f"discretization shifts {', '.join(over)}: ci95 is widened by |beta|, the corrected values "
                         f"(identified - beta) are in RESULT.json discretization.bias (or use more sub-steps)",
                         {"warn_at": BIAS_WARN, "shifted": shifted},
                         "read ci95 (widened by |beta|) or the corrected values, or use more sub-steps")]
