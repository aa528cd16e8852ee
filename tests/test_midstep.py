"""The opt-in second-order rewrite of a compiled network (flowchart2sdnn.network.midstep, issue 13).

Oracles: the charts' physics read by hand (which edges carry speed-dependent torques), a hand-written numpy
recursion of symplectic Euler with Adams-Bashforth speed torques, central finite differences of the
simulation, the continuous RK4 oracle (the error must fall as h^2), and the root of the linear friction
recursion z^2 - (1 - 1.5 s h/J) z - 0.5 s h/J = 0 (stable iff s h/J < 1).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text, load_diagram
from flowchart2sdnn.network.midstep import extrapolate_speed_torques, speed_structure
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.network.stability import chatter_radius
from flowchart2sdnn.simulate.continuous import simulate_continuous
from tests.test_rtrl import assert_jacobian_matches

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"


def _net(chart: str, n: int):
    d = load_diagram(DIAGRAMS / chart)
    return compile_diagram(dataclasses.replace(d, delays="torques", substeps=n)).network


def _input(seconds: float, T: float = 0.001) -> np.ndarray:
    t = np.arange(int(round(seconds / T))) * T
    return 3.0 * np.sin(2 * np.pi * 1.7 * t) + 2.0 * np.sign(np.sin(2 * np.pi * 2.3 * t))


def test_speed_torques_are_friction_and_damping_not_springs():
    st = speed_structure(_net("two_mass_coulomb_plant.yaml", 1))
    net = _net("two_mass_coulomb_plant.yaml", 1)
    origins = {net.weights[j].origin for j in st.extrapolated}
    assert origins == {"MR1 -> MB1", "dw -> MD -> MB1", "MR2 -> MB2", "dw -> MD -> MB2"}
    names = {net.layers[m].name for m, _ in st.speed_integrators}
    assert names == {"w1", "w2"}
    assert "dphi" in {net.layers[m].name for m, _ in st.position_dependent}


def test_search_rule_twist_is_no_speed_integrator():
    """`delays: search` delays `w2 -> dw`: dw sees w1 without a delay and feeds the twist, so neither dw nor the
    twist is taken for a speed sum / speed integrator and no spring edge is extrapolated; only the motor's
    Newton's sum (which sees every integrator through a delay) is."""
    d = load_diagram(DIAGRAMS / "two_mass_coulomb_plant.yaml")
    net = compile_diagram(dataclasses.replace(d, delays="search", substeps=1)).network
    st = speed_structure(net)
    assert {net.layers[m].name for m, _ in st.speed_integrators} == {"w1"}
    assert {net.weights[j].origin for j in st.extrapolated} == {"MR1 -> MB1", "dw -> MD -> MB1"}


def test_rewrite_doubles_each_speed_torque_edge_and_keeps_the_rest():
    net = _net("three_mass_plant.yaml", 2)
    out = extrapolate_speed_torques(net)
    k = len(speed_structure(net).extrapolated)
    assert k == 7  # three frictions, two dampers into two sums each
    assert len(out.weights) == len(net.weights) + k
    assert sorted(w.delay for w in out.weights if w.delay == 2) == [2] * k
    np.testing.assert_allclose(np.sort(out.weight_values()[[w.delay == 2 for w in out.weights]]),
                               np.sort(-0.5 * net.weight_values()[list(speed_structure(net).extrapolated)]))


def _hand_ab2(u, T, n, J, c, d, Fc, b):
    """Three masses: w += h/J (M + 1.5 tau_v(k) - 0.5 tau_v(k-1) + springs(phi)); phi += h (w_i - w_i+1)."""
    h = T / n
    w, phi, tv_old = np.zeros(3), np.zeros(2), np.zeros(3)
    out = []
    for uk in u:
        for _ in range(n):
            fr = Fc * np.tanh(20 * w) + b * w
            dmp = d * (w[:-1] - w[1:])
            tv = -fr + np.array([-dmp[0], dmp[0] - dmp[1], dmp[1]])
            sp = c * phi
            ts = np.array([-sp[0], sp[0] - sp[1], sp[1]])
            w = w + h * (np.array([uk, 0.0, 0.0]) + 1.5 * tv - 0.5 * tv_old + ts) / J
            tv_old = tv
            phi = phi + h * (w[:-1] - w[1:])
        out.append(w.copy())
    return np.array(out)


@pytest.mark.parametrize("n", [1, 3])
def test_rewritten_network_equals_a_hand_recursion(n):
    u = _input(0.5)
    c = CompiledNetwork(extrapolate_speed_torques(_net("three_mass_plant.yaml", n)))
    expected = _hand_ab2(u, 0.001, n, np.array([0.19, 0.25, 0.38]), np.array([477.0, 300.0]),
                         np.array([0.24, 0.15]), np.array([0.8, 0.5, 0.6]), np.array([0.02, 0.015, 0.03]))
    np.testing.assert_allclose(c.simulate(c.theta0(), u[:, None]), expected, rtol=0, atol=1e-11)


@pytest.mark.parametrize("chart, n", [("three_mass.yaml", 1), ("two_mass.yaml", 2)])
def test_rtrl_stays_exact_after_the_rewrite(chart, n):
    """Physical parameters (three-mass) and learned friction curves (two-mass) through delay-2 edges."""
    net = extrapolate_speed_torques(_net(chart, n))
    assert any(w.delay == 2 for w in net.weights)
    c = CompiledNetwork(net)
    assert_jacobian_matches(c, c.theta0(), _input(0.3)[:, None], rtol=1e-5)


def test_error_against_the_continuous_plant_falls_as_h_squared():
    d = load_diagram(DIAGRAMS / "three_mass_plant.yaml")
    u = _input(2.0)
    truth = simulate_continuous(d, u, substeps=20)[1:]
    err = {}
    for stage in (False, True):
        for n in (1, 2):
            net = _net("three_mass_plant.yaml", n)
            c = CompiledNetwork(extrapolate_speed_torques(net) if stage else net)
            err[stage, n] = np.sqrt(np.mean((c.simulate(c.theta0(), u[:-1, None]) - truth) ** 2, axis=0))
    assert np.all(err[False, 1] / err[False, 2] < 2.5)  # the compiled network: first order
    assert np.all(err[True, 1] / err[True, 2] > 3.5)  # the rewrite: second order
    assert np.all(err[True, 1] < err[False, 1] / 3)


MASS = """\
sdnn: 1
name: mass
sample_time: 0.001
substeps: {n}
delays: torques
inputs:
  M: {{}}
outputs:
  w: {{}}
parameters:
  J: {{init: 0.1}}
  F: {{init: 2.0}}
blocks:
  MB: {{type: sum, in: [M, -MR]}}
  acc: {{type: gain, in: MB, k: 1/J}}
  w: {{type: integrator, in: acc}}
  sg: {{type: function, f: tanh, in: w, k: 200}}
  MR: {{type: gain, in: sg, k: F}}
"""


def _settled(net) -> float:
    """|w| at the end after a small push that friction should stop."""
    c = CompiledNetwork(net)
    u = np.zeros((400, 1))
    u[:5] = 0.05
    return float(np.abs(c.simulate(c.theta0(), u)[-50:, 0]).max())


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8])
def test_friction_stays_stable_only_below_half_the_euler_bound(n):
    """Friction slope s = 400 at rest, J = 0.1, z = s h / J = 4, 2, 1.33, 0.8, 0.5: Euler chatters when
    z > 2 (z = 2 is its margin), the rewrite when z > 1."""
    z = 400 * (0.001 / n) / 0.1
    roots = np.roots([1.0, -(1 - 1.5 * z), -0.5 * z])
    assert (np.abs(roots).max() > 1) == (z > 1)
    net = compile_diagram(diagram_from_text(MASS.format(n=n), "mass.yaml")).network
    rewritten = extrapolate_speed_torques(net)
    # the identification's chatter guard (the eigenvalues with a negative real part) linearizes the network
    # with all its delays: it sees the new bound
    negative = np.abs(roots[roots.real < 0]).max()
    assert chatter_radius(rewritten, rewritten.weight_values()) == pytest.approx(negative, rel=1e-9)
    stage = _settled(rewritten)
    assert (stage > 1e-4) if z > 1 else (stage < 1e-9)
    if z < 2:
        assert _settled(net) < 1e-9  # the compiled network itself is stable there
