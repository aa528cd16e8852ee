"""Where a learned curve in a feedback loop starts: a stick-slip step at a safe slope, not random weights.

A learned friction curve's local minima are set by its steepest neuron: its slope at zero (how hard the curve
holds a shaft at rest in the discrete network) barely moves during a fit, because that neuron is saturated
over almost all samples and its input weight's Jacobian column is tiny. From the chart's random +-0.5 weights
the two-mass drive's fits ended anywhere from 1.1 to 2.8 times the best cost, even from the true physical
values (docs/rough_init.md). So a curve whose slope the network's step bounds (a curve in a feedback loop: above
about 2J/T at zero the delayed feedback chatters, network.stability) starts as

* neuron 1: a step of level ``STEP_LEVEL`` whose slope at zero is ``STICK_FRACTION`` of the slope at which the
  network would chatter (found by bisection on the rest eigenvalues, every other curve flat; with N sub-steps
  the limit of the network's step T/N);
* neuron k >= 2: input weight g * 10^-(k-2) / RMS of the curve's input in a free run (a log grid
  across the signal's range: neuron 2 bends at 1/g of the RMS, the Stribeck fall, then a nearly linear viscous
  part), output weight 0 (and bias 0);

all of it at the physical values of ``BRIEF_ITERATIONS`` LM iterations from the chart's own start; then
``BRIEF_ITERATIONS`` LM iterations fit the whole chart (the physical parameters, an inertia among them,
settle), and the step is re-sloped to ``STICK_FRACTION`` of the limit at the fitted values, keeping its level.
This runs once for each g of ``GRID_TOPS`` (a brief internal multi-start over the curves' shape); the fit itself
starts from the re-sloped point of lower cost. Curves with stored weights, fixed curves and curves whose slope no chatter
bounds (outside any loop) keep the chart's start.

Layer: identify (below it: fit, network).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ... import rules
from .problem import CHATTER_LIMIT, Problem
from .workers import run_start

__all__ = ["CurveStart", "STICK_FRACTION", "BRIEF_ITERATIONS", "STEP_LEVEL", "GRID_TOPS", "startable_curves", "slope_limit",
           "stick_template", "curve_start"]

#: The step neuron's slope at zero as a fraction of the slope at which the network chatters. On the two-mass
#: bench (truth start, 10 s) the fit's cost against this fraction: 0.05 1.306, 0.1 1.253, 0.2 1.163, 0.3 1.125,
#: 0.4 1.230, 0.6 1.396, 0.9 1.472 (docs/rough_init.md).
STICK_FRACTION = rules.value("stick_fraction")
#: LM iterations before the step is re-sloped at the fitted physical values (an inertia drawn x/3 moves the
#: chatter limit x/3; 50 iterations put J2 within 0.3 % on the bench).
BRIEF_ITERATIONS = rules.value("curve_brief_iterations")
#: The step's starting output weight, in the curve's output unit (the fit moves it; only its slope is kept).
STEP_LEVEL = rules.value("step_level")
#: Neuron 2's input weight times the RMS of the curve's input (neuron k: 10^-(k-2) times less), one brief fit
#: each, the lower cost kept. On the two-mass bench (20 rough draws) 1 alone left 2 draws in a minimum 1.3-1.7x
#: higher (neuron 2 merged with neuron 3 into one linear term), 3 alone 3 others (docs/rough_init.md).
GRID_TOPS = rules.value("grid_tops")
#: Bisection range of a slope at zero.
_SLOPES = rules.value("slope_bracket")


@dataclass(frozen=True)
class CurveStart:
    """What :func:`curve_start` did: the start it returns and the brief fit's iterations (0 when no curve
    qualified), the curves it set and their slope limits at the brief fit's values."""

    x: np.ndarray
    curves: tuple[str, ...]
    iterations: int
    limits: dict
    template: np.ndarray | None = None  # the chart's start with the curves' step + grid: further starts' centre
    stopped: object | None = None  # the brief fit's LMResult when the callback stopped it (Ctrl-C): the run ends

    def to_dict(self) -> dict:
        return {"curves": list(self.curves), "iterations": self.iterations,
                "slope_limits": {k: float(v) for k, v in self.limits.items()},
                "stick_fraction": STICK_FRACTION, "brief_iterations": BRIEF_ITERATIONS}


def startable_curves(problem: Problem) -> dict[str, dict[str, list[int]]]:
    """{block: {"a": [index in problem.names, neuron order], "v": [...], "b": [...]}} of the learned curves
    that start from random weights (no stored `weights`, not fixed)."""
    if problem.diagram is None:
        return {}
    random_start = {b.name for b in problem.diagram.blocks
                    if b.kind == "nonlinear" and b.weights is None and not b.fixed}
    index = {n: i for i, n in enumerate(problem.names)}
    out: dict[str, dict[str, list[int]]] = {}
    for fw in problem.network.free_weights:
        if fw.block in random_start and fw.role in ("a", "v", "b") and fw.name in index:
            out.setdefault(fw.block, {"a": [], "v": [], "b": []})[fw.role].append(index[fw.name])
    return {b: r for b, r in out.items() if r["a"] and len(r["a"]) == len(r["v"])}


def _flat(x: np.ndarray, curves: dict) -> np.ndarray:
    y = np.array(x, dtype=float)
    for roles in curves.values():
        y[roles["v"]] = 0.0
    return y


def slope_limit(problem: Problem, x: np.ndarray, block: str, curves: dict) -> float:
    """The slope at zero of `block`'s first neuron (every learned curve otherwise flat) at which the network
    starts to chatter at rest; inf when no slope does (the curve is in no loop the step bounds)."""
    roles = curves[block]
    y = _flat(x, curves)
    y[roles["b"]] = 0.0
    a1, v1 = roles["a"][0], roles["v"][0]
    y[v1] = 1.0

    def chatters(s: float) -> bool:
        y[a1] = s
        return problem.stability(y)[0] > CHATTER_LIMIT

    lo, hi = _SLOPES
    if not chatters(hi):
        return float("inf")
    if chatters(lo):
        return 0.0
    for _ in range(60):  # log bisection: ~1e-9 relative after 60 halvings of 21 decades
        mid = float(np.sqrt(lo * hi))
        lo, hi = (lo, mid) if chatters(mid) else (mid, hi)
    return lo


def _input_rms(problem: Problem, x: np.ndarray, block: str) -> float:
    """RMS of the signal feeding `block` in a free run from x over the training record (1 when unknown)."""
    b = next(b for b in problem.diagram.blocks if b.name == block)
    name = b.inputs[0].signal
    with np.errstate(all="ignore"):
        signals = problem.compiled.signals(x, problem.inputs, problem.init)
    sig = signals.get(name)
    if sig is None:
        return 1.0
    sig = np.asarray(sig, dtype=float)
    rms = float(np.sqrt(np.mean(sig[np.isfinite(sig)] ** 2))) if np.isfinite(sig).any() else 0.0
    return rms if rms > 0 else 1.0


def _stick_slope(limit: float) -> float:
    """The step's slope at zero: STICK_FRACTION of the limit at the network's own step h = T/N. With N sub-steps
    the limit (2J/h) is N times the sample's (2J/T), and the step starts that much steeper: on the three-mass
    learned chart (N = 8 by `substeps: auto`, a plant whose sign is smoothed over 1 mrad/s) a step at 0.3 of
    the sample's limit (0.0375 of the network's) left the fits in a minimum 1.25x the best (b2 at its bound 0)
    or crawling up to 0.1-0.3 of the network's limit at the 1000-iteration limit; from 0.3 of the network's the
    brief fits end at the minimum and the fit converges (docs/rough_init.md). The engine example at N = 4 did not
    converge from 2J/h with plain LM steps (why the sample's limit was used); with geodesic steps it converges
    at the same J1 (150 + 204 iterations)."""
    return STICK_FRACTION * limit


def stick_template(problem: Problem, x: np.ndarray, curves: dict | None = None,
                   top: float = 1.0) -> tuple[np.ndarray, dict]:
    """x with every qualifying curve set to the step + log grid of the module docstring; (x, {block: limit})."""
    curves = startable_curves(problem) if curves is None else curves
    y = np.array(x, dtype=float)
    limits = {}
    for block, roles in curves.items():
        limit = slope_limit(problem, y, block, curves)
        if not np.isfinite(limit) or limit <= 0:
            continue
        limits[block] = limit
        y[roles["a"][0]] = _stick_slope(limit) / STEP_LEVEL
        y[roles["v"][0]] = STEP_LEVEL
        y[roles["v"][1:]] = 0.0
        y[roles["b"]] = 0.0
    for block in limits:  # the free run sees every step in place and the other neurons flat
        roles = curves[block]
        rms = _input_rms(problem, y, block)
        for k, i in enumerate(roles["a"][1:]):
            y[i] = top * 10.0 ** (-k) / rms
    return y, limits


def _brief(problem: Problem, y: np.ndarray, curves: dict, limits: dict, lower, upper, options, callback):
    """The brief fit from template y and the steps re-sloped: (start, its cost, iterations, limits)."""
    brief = run_start(problem, y, lower, upper, replace(options, max_iter=BRIEF_ITERATIONS), callback=callback)
    if brief.status in ("callback_stop", "interrupted"):
        return brief
    if not np.isfinite(brief.cost):
        return None
    y, limits = np.array(brief.x, dtype=float), dict(limits)
    for block in limits:
        roles = curves[block]
        limit = slope_limit(problem, y, block, curves)
        v1 = y[roles["v"][0]]
        if np.isfinite(limit) and limit > 0 and abs(v1) > 1e-9:
            limits[block] = limit
            y[roles["a"][0]] = _stick_slope(limit) / v1  # the sign of v1: a positive (damping) slope
    e = problem.residual(y)
    cost = 0.5 * float(e @ e) if e is not None and np.all(np.isfinite(e)) else float("inf")
    return y, cost, int(brief.iterations), limits


def curve_start(problem: Problem, x: np.ndarray, lower: np.ndarray, upper: np.ndarray, options,
                callback=None) -> CurveStart:
    """The start of an offline fit with learned curves (module docstring): one brief fit per grid of
    ``GRID_TOPS``, the re-sloped point of lower cost kept. `options` are the fit's LMOptions; `callback` is LM's
    (progress, stop)."""
    curves = startable_curves(problem)
    x = np.asarray(x, dtype=float)
    if not curves or not any(np.isfinite(slope_limit(problem, x, b, curves)) for b in curves):
        return CurveStart(x, (), 0, {})
    # the physical values first, from the chart's own start: a step of level 1 on a stiffness and an inertia
    # both drawn x2 too large sent both brief fits to c +96 % (docs/rough_init.md, seed 2)
    first = run_start(problem, x, lower, upper, replace(options, max_iter=BRIEF_ITERATIONS), callback=callback)
    if first.status in ("callback_stop", "interrupted"):
        return CurveStart(np.array(first.x, dtype=float), (), first.iterations, {}, stopped=first)
    start = np.array(first.x, dtype=float) if np.isfinite(first.cost) else x
    best, iterations, template = None, int(first.iterations), None
    for top in GRID_TOPS:
        y, limits = stick_template(problem, start, curves, top)
        if not limits:
            return CurveStart(x, (), 0, {})
        out = _brief(problem, y, curves, limits, lower, upper, options, callback)
        if out is None:
            continue
        if not isinstance(out, tuple):  # stopped by the callback: no further work
            return CurveStart(np.array(out.x, dtype=float), tuple(limits), iterations + out.iterations, limits, y,
                              stopped=out)
        iterations += out[2]
        if best is None or out[1] < best[1]:
            best, template = out, y
    if best is None:  # every template diverged: leave the chart's own start
        return CurveStart(x, (), 0, {})
    # further starts of a multi-start: the chart's own physical values, the curves as the kept template
    around = x.copy()
    for block in best[3]:
        for role in ("a", "v", "b"):
            around[curves[block][role]] = template[curves[block][role]]
    return CurveStart(best[0], tuple(best[3]), iterations, best[3], around)
