"""How far the fit can be trusted: the start's stability, the covariance with intervals widened for coloured
residuals, parameters that cannot be told apart, a network close to chattering, data that excite nothing.

Layer: identify.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ... import rules
from ...errors import SdnnError
from ...fit.uncertainty import covariance
from ...notices import Notice
from ..offline.problem import CHATTER_LIMIT, GROWTH_LIMIT, Problem
from ..result import Uncertainty

__all__ = ["sqrt_domain_warnings", "start_stability", "on_bound_warnings", "no_excitation_message", "Evidence", "assess", "CHATTER_WARN"]

#: Warn when the fitted network is this close to chattering at rest.
CHATTER_WARN = rules.value("chatter_warn")
_INFLATION_NOTE = ("stderr and ci95 are widened by interval_inflation = sqrt((1+rho)/(1-rho)) for the residual's "
                   "lag-1 autocorrelation rho (coloured residuals carry fewer independent samples)")


class Evidence:
    """The covariance analysis at the final point: standard errors and 95 % half-widths (already widened), or
    None where unavailable; the :class:`Uncertainty` of the result; warnings; whether the data excite nothing."""

    def __init__(self, stderr=None, half=None, uncertainty: Uncertainty | None = None,
                 warnings: list[Notice] | None = None, no_excitation: bool = False):
        self.stderr, self.half, self.uncertainty = stderr, half, uncertainty
        self.warnings = warnings or []
        self.no_excitation = no_excitation


def assess(problem: Problem, x: np.ndarray, diverged: bool) -> Evidence:
    """Uncertainty at ``x`` (the Jacobian of the whole training record) and the warnings it gives."""
    if not problem.names or diverged:
        return Evidence()
    fe = problem.fun(x)
    out = Evidence()
    cov = None
    if fe is not None and not np.any(fe[1]):
        out.no_excitation = True
    elif fe is not None:
        cov = covariance(fe[1], fe[0], names=problem.names)
        if cov.available and not math.isfinite(cov.sigma2):
            cov = None  # the residual's square overflows: no meaningful uncertainty
        else:
            out.warnings.extend(_identifiability_warnings(cov, problem))
            rho, inflation = _coloured_residual(fe[0], len(problem.compiled.output_names))
    radius = problem.chatter(x)
    if radius > CHATTER_WARN:
        out.warnings.append(Notice(
            "STAB001", f"the fitted network is close to chattering at rest (eigenvalue {-radius:.3f}); a "
            "learned curve is nearly as steep as the sample time allows (about 2*J/T)",
            {"eigenvalue": -float(radius), "warn_at": CHATTER_WARN},
            "more sub-steps, or bounds that keep the learned curve's slope below 2*J/T"))
    if cov is None or not cov.available:
        return out
    out.stderr = np.where(np.isfinite(cov.stderr), cov.stderr * inflation, np.nan)
    out.half = np.asarray(cov.ci95, dtype=float) * inflation
    corr = np.where(np.isfinite(cov.correlation), cov.correlation, np.nan)
    out.uncertainty = Uncertainty(
        names=tuple(problem.names),
        correlation=tuple(tuple(None if not np.isfinite(v) else round(float(v), 12) for v in row) for row in corr),
        condition_number=float(cov.condition_number) if np.isfinite(cov.condition_number) else None,
        unidentifiable=tuple(tuple(g) for g in cov.unidentifiable), sigma2=cov.sigma2, residual_lag1=rho,
        interval_inflation=inflation, note=_INFLATION_NOTE)
    return out


def no_excitation_message(problem: Problem) -> str:
    constant = [spec.name for spec, col in zip(problem.compiled.net.inputs, problem.inputs.T, strict=True)
                if np.ptp(col) == 0] if problem.inputs.size else []
    why = f" (constant input: {', '.join(constant)})" if constant else ""
    return ("the training data do not excite the model: no output depends on any free parameter or curve"
            f"{why}; the start values are returned, nothing was identified")


def _step_words(network) -> str:
    """The step the chatter limit 2*J/h is about: the sample time, or the sub-step h = T/N."""
    if network.substeps == 1:
        return f"sample time T = {network.sample_time:g} s (limit about 2*J/T)"
    return f"network step h = T/{network.substeps} = {network.step:g} s (limit about 2*J/h)"


def start_stability(problem: Problem, x0: np.ndarray) -> tuple[Problem, list[Notice]]:
    """Check the start at rest. Chatter (a sign flip every sample) cannot be fitted away: an error. A start that
    drifts away from rest can: warn, and let the guard accept steps no worse than the start."""
    if not problem.names:
        return problem, []
    chatter, growth = problem.stability(x0)
    if chatter > CHATTER_LIMIT:
        raise SdnnError.at(
            "FIT001", f"at its initial values (init) the chart's discrete network chatters at rest (eigenvalue "
            f"{-chatter:.3f}): a curve in a feedback loop is too steep for the {_step_words(problem.network)}",
            problem.diagram.file,
            hint="soften the curve (a larger eps of sign_smooth, a smaller k or init) or use a learned `nonlinear` block")
    if growth <= GROWTH_LIMIT:
        return problem, []
    warning = Notice(
        "START001", f"at its initial values the chart's discrete network drifts away from rest (eigenvalue "
        f"{growth:.3f}): a curve in a feedback loop has a negative slope at zero; the fit may take long to recover",
        {"eigenvalue": float(growth), "limit": GROWTH_LIMIT},
        "start the curve with a slope of zero or more at zero (its init)")
    return replace(problem, stability_floor=(chatter, growth)), [warning]


def on_bound_warnings(names, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> list[Notice]:
    """Starts exactly on a bound: allowed, but the bound transform is flat there and such a quantity moves slowly."""
    out = []
    for name, x, lo, hi in zip(names, x0, lower, upper, strict=True):
        side = "lower" if x == lo else "upper" if x == hi else None
        if side:
            out.append(Notice("START002", f"{name} starts on its {side} bound ({x:g}); it can move away only slowly "
                              "(the bound transform is flat there): start it inside the bounds",
                              {"parameter": name, "side": side, "value": float(x)},
                              f"give {name} an init strictly inside its bounds"))
    return out


def _coloured_residual(residual: np.ndarray, n_outputs: int) -> tuple[float | None, float]:
    """Lag-1 autocorrelation of the residual and the factor that widens the intervals for it.

    The textbook covariance assumes white residuals; model error makes them coloured and the intervals far
    too narrow. With an AR(1) residual of correlation rho the effective number of samples is
    n (1 - rho) / (1 + rho), so standard errors grow by sqrt((1 + rho) / (1 - rho)).
    """
    e = residual.reshape(-1, n_outputs)
    if len(e) < 3:
        return None, 1.0
    rhos = []
    for i in range(n_outputs):
        ei = e[:, i] - e[:, i].mean()
        denom = float(ei @ ei)
        if denom > 0:
            rhos.append(float(ei[1:] @ ei[:-1]) / denom)
    if not rhos:
        return None, 1.0
    rho = float(np.mean(rhos))
    r = min(max(rho, 0.0), 0.999)
    return rho, float(np.sqrt((1 + r) / (1 - r)))


def _identifiability_warnings(cov, problem: Problem) -> list[Notice]:
    """Groups that cannot be told apart, when they involve a physical parameter.

    The weights of one learned curve trade off against each other all the time (a*v of a nearly linear
    neuron); that says nothing about the physics, so such groups are not reported.
    """
    physical = {p.name for p in problem.network.parameters}
    out = []
    for group in cov.unidentifiable:
        if physical & set(group):
            out.append(Notice("IDENT001", f"cannot be told apart from this data: {', '.join(group)} (fix all but "
                              "one, or excite more)", {"parameters": list(group)},
                              "fix all but one, or excite more"))
    for a, b, r in cov.correlated:
        if {a, b} & physical and not any({a, b} <= set(g) for g in cov.unidentifiable):
            out.append(Notice("IDENT002", f"{a} and {b} are almost interchangeable here (correlation {r:+.4f})",
                              {"parameters": [a, b], "correlation": float(r)},
                              f"fix one of {a} and {b}, or excite the machine so that they act apart"))
    return out


def sqrt_domain_warnings(problem: Problem, x: np.ndarray) -> list[Notice]:
    """The samples where a `sqrt` block's argument went negative in the fitted model (lint can only say that it
    may). There the chart's sqrt is -sqrt(-z): a flow that reverses, never a NaN, but a level that should not
    go below 0 did, and the user should know."""
    layers = [la.name for la in problem.network.layers if any(n.transfer == "sqrt" for n in la.neurons)]
    if not layers:
        return []
    counts = dict.fromkeys(layers, 0)
    lowest = dict.fromkeys(layers, 0.0)
    total = 0
    for k, s in enumerate(problem.segments):
        signals = problem.compiled.signals(problem.record_x(x, k), s.inputs, s.init)
        total += s.inputs.shape[0]
        for name in layers:
            a = signals[name]
            a = a[np.isfinite(a)]
            counts[name] += int(np.sum(a < 0))  # the root is odd: negative exactly where its argument is
            lowest[name] = min(lowest[name], float(a.min()) if a.size else 0.0)
    blocks = {b.name: b for b in problem.diagram.blocks}
    # the network's root is the chart's over sqrt(eps) (compiler.discretize.output_scale)
    scale = {n: math.sqrt(blocks[n].eps or 1e-3) if n in blocks else 1.0 for n in layers}
    return [Notice("SQRT001", f"sqrt '{name}': its argument was negative on {counts[name]} of {total} samples of the "
                   f"training data (there sqrt(z) is taken as -sqrt(-z), a reversed flow; the root fell to "
                   f"{lowest[name] * scale[name]:.3g})",
                   {"block": name, "negative": counts[name], "samples": total, "lowest": lowest[name] * scale[name]},
                   "check the chart: a level that must stay at or above 0 went below it in the fitted model")
            for name in layers if counts[name]]
