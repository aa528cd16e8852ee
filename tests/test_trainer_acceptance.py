"""Trainer acceptance on compiled charts: exact RTRL Jacobians and LM convergence to the true parameters."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_rtrl import assert_jacobian_matches

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.model import NonlinearWeights
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.network.runtime import CompiledNetwork

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
EULER = Path(__file__).resolve().parent / "data" / "two_mass_euler.yaml"  # two_mass.yaml at N = 1


def _excitation(n: int, seed: int) -> np.ndarray:
    """A zero-mean staircase (APRBS-like) input: bounded, so the integrating drive stays near the origin."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-3, 3, n // 40 + 1)
    u = np.repeat(levels, 40)[:n]
    return (u - u.mean())[:, None]


def _all_free(diagram):
    """Every parameter free (J1 too, so that a 1/J weight is differentiated)."""
    return replace(diagram, parameters=tuple(replace(p, fixed=False) for p in diagram.parameters))


@pytest.mark.parametrize("chart", ["engine.yaml", "two_mass.yaml"])
def test_rtrl_jacobian_of_compiled_charts_equals_central_differences(chart):
    diagram = _all_free(load_diagram(DIAGRAMS / chart))
    cn = CompiledNetwork(compile_diagram(diagram, seed=3).network)
    assert any(n.startswith("J") for n in cn.names)  # parameters entering as T/J
    rng = np.random.default_rng(7)
    theta = cn.theta0() * rng.uniform(0.8, 1.2, cn.n_theta)
    assert_jacobian_matches(cn, theta, _excitation(400, 1))


def _two_mass_with_known_friction():
    d = load_diagram(EULER)  # the paper's network: one step per sample
    curve = NonlinearWeights(a=(2.0, 0.5, 8.0), v=(0.3, 0.2, 0.1))
    blocks = tuple(replace(b, weights=curve, fixed=True) if b.kind == "nonlinear" else b for b in d.blocks)
    return replace(d, blocks=blocks)


def test_lm_recovers_the_parameters_of_a_noise_free_compiled_network_to_1e_6():
    """The optimizer's own oracle: data made by the network at known values, a start 20-50 % off."""
    diagram = _two_mass_with_known_friction()
    truth = {"J2": 0.3838, "c": 477.2, "d": 0.2406}
    diagram = replace(diagram, parameters=tuple(replace(p, init=truth.get(p.name, p.init)) for p in diagram.parameters))
    cn = CompiledNetwork(compile_diagram(diagram).network)
    assert cn.names == ("J2", "c", "d")
    u = _excitation(3000, 2)
    x_true = np.array([truth[n] for n in cn.names])
    y = cn.simulate(x_true, u)

    def fun(x):
        yhat, jac = cn.jacobian(x, u)
        if not np.all(np.isfinite(yhat)):
            return None
        return (y - yhat).ravel(), jac.reshape(-1, jac.shape[-1])

    x0 = x_true * np.array([1.3, 0.75, 1.5])
    lower = np.zeros(3)
    seen = []

    def callback(it, x, cost, mu):
        seen.append(np.array(x))

    res = levenberg_marquardt(fun, x0, cn.names, lower=lower, options=LMOptions(max_iter=200, min_grad=0.0),
                              callback=callback)
    np.testing.assert_allclose(res.x, x_true, rtol=1e-6)
    assert all(np.all(x >= lower) for x in seen)
