"""How many network steps per data sample: `substeps: N` as given, or `auto` (the default) from the fastest mode.

The paper's scheme (implicit Euler forward, one step of delay in every feedback loop) is first order: a mode of
angular frequency w is carried with a phase and amplitude error of about w*h/2 per unit of its own amplitude.
`auto` linearizes the compiled network at rest (:func:`flowchart2sdnn.network.stability.rest_eigenvalues`, the
chatter guard's matrix) and in each region of its piecewise functions (:func:`operating_slopes`: a dead zone
is slack at rest but in contact while the drive runs), reads each eigenvalue z as a continuous rate
|log z| / h, and picks the smallest N with w_max * T / N <= AUTO_BOUND, w_max the fastest over them. The bound is measured, not derived: on the two- and three-mass benches
(`benchmarks/bench_substeps.py`, `delays: torques`) w*h <= 0.01 keeps every speed within 0.06 % of its RMS
(0.0025 rad/s at most on speeds of 3-5 rad/s RMS); 0.02 left the three-mass motor speed at 0.13 %. N is capped at AUTO_CAP; when the cap binds
(a steep friction curve at zero speed reads as a very fast mode) a warning says so.

`delays: midpoint` is second order (network.midstep): its bound is AUTO_BOUND_MIDPOINT, w*h <= 0.05, which
gives N = 2 on both benches (floors 0.0007 rad/s and below, under auto's first-order 0.0021 at N = 7-8), and its
modes are read from the network before the rewrite: the Adams-Bashforth extrapolation adds a parasitic root
near -0.5 s h / J per friction slope s, not a mode of the machine, that would read as pi / h.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..diagram.model import Diagram
from ..network.model import Network
from ..network.stability import rest_eigenvalues

__all__ = ["AUTO_BOUND", "AUTO_BOUND_MIDPOINT", "AUTO_CAP", "DEFAULT_SUBSTEPS", "SubstepChoice", "fastest_mode", "choose_substeps"]

#: auto keeps omega_max * h at or below this (rad per network step)
AUTO_BOUND = 0.01
#: ... and this under `delays: midpoint` (second order: the error falls as h^2)
AUTO_BOUND_MIDPOINT = 0.05
#: auto never takes more steps per sample than this
AUTO_CAP = 32
#: what a chart without `substeps` (and no --substeps) gets; `substeps: 1` is the paper's network
DEFAULT_SUBSTEPS = "auto"
#: eigenvalues of smaller modulus are not modes (see fastest_mode)
ZERO_MODULUS = 1e-3


@dataclass(frozen=True)
class SubstepChoice:
    """The sub-steps used and why: `requested` is the chart's or the caller's value (None: not given, so
    DEFAULT_SUBSTEPS)."""

    substeps: int
    requested: int | str | None
    omega_max: float | None = None  # rad/s, the fastest mode at rest or in a piecewise region (auto only)
    capped: bool = False
    bound: float = AUTO_BOUND  # auto's bound on omega_max * h

    def explain(self, sample_time: float) -> str:
        h = sample_time / self.substeps
        text = f"substeps N = {self.substeps} (h = T/N = {h:g} s)"
        if (self.requested or DEFAULT_SUBSTEPS) == "auto":
            w = self.omega_max or 0.0
            text += (f", auto{' (the default)' if self.requested is None else ''}: fastest mode (at rest or in a piecewise region) {w:.4g} rad/s ({w / (2 * math.pi):.4g} Hz), "
                     f"omega_max*h = {w * h:.3g} (bound {self.bound:g}, cap {AUTO_CAP})")
            if self.capped:
                text += " -- the cap binds"
        return text


#: the slopes auto reads a piecewise transfer at besides its slope at rest: `sat` beyond its limits (0). Not
#: its inner slope 1: a chart at rest inside the limits has it already, and a clip that rests beyond them is
#: diagnose's overflow stop (diagnose.overflow), a stiffness K = 1/T meant to act within one step, not a mode
#: to resolve (read at slope 1 it asked for the cap, N = 32, on the two-mass drive with a stop on any state)
REGION_SLOPES = {"sat": (0.0,)}


def operating_slopes(net: Network) -> list[dict[int, float]]:
    """The regions auto linearizes in besides rest: every piecewise neuron (REGION_SLOPES) at each of its
    region slopes, alone and all together.

    Why: at rest a dead zone ``x - g sat(x / g)`` is slack (sat' = 1, the spring's torque has slope 0), yet in
    contact (sat' = 0) the spring acts, and that mode is the fastest the drive reaches (the backlash bench:
    none at rest, N = 1; sqrt(c (1/J1 + 1/J2)) = 61 rad/s in contact). A saturation's limit reached (slope 0)
    cuts its loop (a slower mode, harmless). One at a time finds each region's mode, all together the fully engaged drive (two dead
    zones in contact at once); taking the fastest over them can only raise N, never lower it.
    """
    piecewise = [(k, nr.transfer) for k, nr in enumerate(nr for la in net.layers for nr in la.neurons)
                 if nr.transfer in REGION_SLOPES]
    points: list[dict[int, float]] = []
    for slope in sorted({s for _, t in piecewise for s in REGION_SLOPES[t]}):
        together = {k: slope for k, t in piecewise if slope in REGION_SLOPES[t]}
        points.append(together)
        if len(together) > 1:
            points += [{k: slope} for k in together]
    return points


def fastest_mode(net: Network) -> float:
    """The largest continuous-time rate |log z| / h (rad/s) among the network's eigenvalues at rest and in
    each region of its piecewise functions (:func:`operating_slopes`).

    Eigenvalues below ZERO_MODULUS are skipped: the companion matrix's delay lines (a delayed sum's or a delay
    block's memory) are zero eigenvalues that rounding spreads up to about 1e-5 (a defective block), and a mode
    that decays a thousandfold in one step is gone before the next sample whatever its error. An eigenvalue on the negative real axis (a network that already chatters) reads as
    pi / h, which asks for more steps, as it should.
    """
    values = net.weight_values()
    fastest = 0.0
    for slopes in [None, *operating_slopes(net)]:
        z = rest_eigenvalues(net, values, slopes)
        z = z[np.abs(z) > ZERO_MODULUS]
        if z.size:
            fastest = max(fastest, float(np.max(np.abs(np.log(z.astype(complex))))) / net.step)
    return fastest


def substeps_for(omega: float, sample_time: float, bound: float = AUTO_BOUND) -> tuple[int, bool]:
    """(N, capped): the smallest N with omega * T / N <= bound, at most AUTO_CAP."""
    if not math.isfinite(omega):
        return AUTO_CAP, True
    need = max(1, math.ceil(omega * sample_time / bound - 1e-9))
    return min(need, AUTO_CAP), need > AUTO_CAP


def requested_substeps(diagram: Diagram, override: int | str | None = None) -> int | str | None:
    """The caller's value when given (the command line's --substeps), else the chart's (None: not given)."""
    return override if override is not None else diagram.substeps


def choose_substeps(diagram: Diagram, build, override: int | str | None = None, probe=None,
                    bound: float = AUTO_BOUND) -> tuple[SubstepChoice, Network]:
    """Resolve the sub-steps and return the network compiled with them.

    `build(N)` compiles the chart at N sub-steps; `probe(N)` (default: `build`) is the network whose modes
    `auto` reads, with `bound` on omega_max * h. For `auto` the fastest mode is read at one step per sample and
    again at the chosen N (a coarse step distorts fast modes: implicit Euler slows them), and the larger N of the
    two is kept.
    """
    probe = probe or build
    requested = requested_substeps(diagram, override)
    if (requested or DEFAULT_SUBSTEPS) != "auto":
        n = int(requested or DEFAULT_SUBSTEPS)
        return SubstepChoice(n, requested, bound=bound), build(n)
    omega = fastest_mode(probe(1))
    n, capped = substeps_for(omega, diagram.sample_time, bound)
    if n > 1:
        omega = max(omega, fastest_mode(probe(n)))
        n, capped = substeps_for(omega, diagram.sample_time, bound)
    return SubstepChoice(n, requested, omega, capped, bound), build(n)
