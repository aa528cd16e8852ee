"""Second-order speed torques: an opt-in rewrite of a compiled network (issue 13; not used by the compiler).

With ``delays: torques`` the network is symplectic Euler: a speed integrator adds h/J times its *speed sum*
(Newton's sum), whose torques arrive one step late. Under a zero-order-hold input that scheme is second order
in everything but the speed-dependent torques (friction, viscous and shaft damping): the input is integrated
exactly into the speed, and the spring torques come from angles that run half a step ahead (the angle adds the
*new* speed), so they act at the step's midpoint. The speed-dependent torques act at the step's left end: that
is the whole first-order error (benchmarks/bench_readout.py measures it). Extrapolating them to the midpoint,

    tau(t_k + h/2) ~ 1.5 tau(k) - 0.5 tau(k - 1)        (second-order Adams-Bashforth),

makes the network second order at the same cost: each such delayed edge (delay 1, weight w) becomes two,
delay 1 weight 1.5 w and delay 2 weight -0.5 w. The result is a GDNN of the same kind, so RTRL stays exact.

Which edges: decided from the network alone. A *speed sum* is a neuron that feeds an integrator without delay,
receives edges delayed by one step and is reached from no integrator without a delay; that integrator is a
*speed integrator*; every other integrator is a *position integrator*. A neuron is *position-dependent* when a
delay-free path leads to it from a position integrator. The rewrite extrapolates the delay-1 edges into speed
sums from neurons that are not position-dependent (their values are on time with the speeds); spring torques
(position-dependent) keep their single delay. A neuron that mixes a spring and a damper (a chart that sums them
before Newton's sum) is position-dependent and stays first order: write spring and damper as separate gains.

Stability: for a friction slope s (N*m*s/rad) on inertia J, explicit Euler is stable for s*h/J < 2, the
extrapolation only for s*h/J < 1 (the chatter guard's bound 2*J/h becomes J/h).
"""

from __future__ import annotations

import dataclasses

from .model import Network, WeightSpec

__all__ = ["SpeedStructure", "speed_structure", "extrapolate_speed_torques"]


@dataclasses.dataclass(frozen=True)
class SpeedStructure:
    """What :func:`speed_structure` reads off a network; neurons are (layer, row) pairs.

    speed_integrators : integrator neurons fed by a speed sum
    speed_sums : the sums feeding them (with one-step-delayed edges)
    position_dependent : neurons reached without delay from a position integrator
    extrapolated : indices into ``net.weights`` of the delayed edges that the rewrite extrapolates
    """

    speed_integrators: frozenset
    speed_sums: frozenset
    position_dependent: frozenset
    extrapolated: tuple[int, ...]


def speed_structure(net: Network) -> SpeedStructure:
    """Classify the network's integrators and delayed edges (see the module docstring)."""
    lw = [(j, w) for j, w in enumerate(net.weights) if w.matrix == "LW"]
    integrators = {(m, r) for m, la in enumerate(net.layers) if la.kind == "integrator" for r in range(la.size)}
    delayed_into = {(w.layer, w.row) for _, w in lw if w.delay == 1}
    # a speed sum sees every integrator only through a delay (Newton's sum under `delays: torques`); the sum
    # of the search rule's `w2 -> dw` sees w1 without one and feeds the twist: not a speed sum
    on_integrators = _reached_without_delay(net, lw, integrators)
    speed_sums, speed_ints = set(), set()
    for _, w in lw:
        tgt, src = (w.layer, w.row), (w.source, w.col)
        if w.delay == 0 and tgt in integrators and src in delayed_into and src not in on_integrators:
            speed_sums.add(src)
            speed_ints.add(tgt)
    position = _reached_without_delay(net, lw, integrators - speed_ints)
    extrapolated = tuple(
        j for j, w in lw
        if w.delay == 1 and (w.layer, w.row) in speed_sums and (w.source, w.col) not in position
    )
    return SpeedStructure(frozenset(speed_ints), frozenset(speed_sums), frozenset(position), extrapolated)


def _reached_without_delay(net: Network, lw, start: set) -> set:
    """`start` and every neuron a delay-free path leads to from it."""
    out = set(start)
    for m in range(len(net.layers)):  # delay-free edges go from earlier to later layers: one ordered sweep
        for _, w in lw:
            if w.layer == m and w.delay == 0 and (w.source, w.col) in out:
                out.add((w.layer, w.row))
    return out


def extrapolate_speed_torques(net: Network) -> Network:
    """The network with every speed-dependent torque extrapolated to the step's midpoint (a new Network).

    Each edge of ``speed_structure(net).extrapolated`` (delay 1, coef c) becomes delay 1 with coef 1.5*(c) and
    delay 2 with coef -0.5*(c), same free weight and origin. Nothing else changes; a network without such
    edges comes back equal.
    """
    chosen = set(speed_structure(net).extrapolated)
    weights: list[WeightSpec] = []
    for j, w in enumerate(net.weights):
        if j not in chosen:
            weights.append(w)
            continue
        weights.append(dataclasses.replace(w, coef=f"1.5*({w.coef})"))
        weights.append(dataclasses.replace(w, delay=2, coef=f"-0.5*({w.coef})"))
    out = dataclasses.replace(net, weights=tuple(weights))
    out.verify()
    return out
