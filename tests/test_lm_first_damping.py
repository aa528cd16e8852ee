"""The first LM damping scaled to the problem (LMOptions.tau) and each start's own stability floor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.transforms import Bounds
from flowchart2sdnn.identify.offline.problem import CHATTER_LIMIT, GROWTH_LIMIT, build_problem

CHARTS = Path(__file__).resolve().parents[1] / "diagrams" / "paper"


def _engine_problem():
    chart = load_diagram(CHARTS / "engine.yaml")
    rng = np.random.default_rng(5)
    n = 2000
    columns = {"M1": rng.uniform(-10, 10, n), "w1": np.cumsum(rng.normal(0, 0.05, n))}
    data = Dataset(path="<test>", columns=columns, time=None, n_rows=n, sample_time=chart.sample_time,
                   max_step_deviation=None, sha256="", source_columns={k: k for k in columns})
    return build_problem(chart, data, "zoh", seed=3)


def test_first_mu_is_tau_times_the_largest_diagonal_of_the_internal_normal_matrix():
    """mu0 = tau * max_j sum_q (d yhat_q / d u_j)^2, with the Jacobian by central differences in the trainer's
    internal coordinates u (bounds by transform); never below the fixed mu0."""
    problem = _engine_problem()
    x = problem.compiled.theta0()
    lower, upper = problem.bounds()
    bounds = Bounds.make(problem.names, lower, upper)
    u = bounds.start(x)
    cols = []
    for j in range(len(u)):
        h = 1e-6 * max(1.0, abs(u[j]))
        up, dn = u.copy(), u.copy()
        up[j] += h
        dn[j] -= h
        # residual e = y - yhat: d yhat/du = -(e(u+h) - e(u-h)) / 2h
        cols.append(-(problem.residual(bounds.to_external(up)) - problem.residual(bounds.to_external(dn))) / (2 * h))
    expected = 1e-3 * max(float(c @ c) for c in cols)
    assert expected > 1.0

    def first_mu(tau):
        options = LMOptions(max_iter=1, tau=tau)
        result = levenberg_marquardt(problem.fun, x, problem.names, lower, upper, options, residual=problem.residual)
        return result.mu_history[0]

    assert first_mu(1e-3) == pytest.approx(expected, rel=1e-5)
    assert first_mu(1e-12) == 1e-3  # never less damping than trainlm's mu0
    assert first_mu(0.0) == 1e-3  # tau = 0: trainlm's schedule unchanged


def test_tau_must_be_a_finite_non_negative_number():
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="tau"):
            LMOptions(tau=bad)


def test_a_damped_start_still_reaches_the_least_squares_solution():
    """Linear least squares (closed form by numpy.linalg.lstsq): the scaled damping only slows the first steps."""
    rng = np.random.default_rng(0)
    A = rng.normal(size=(200, 3)) * [1.0, 30.0, 1e3]
    y = A @ [0.5, -2.0, 3e-3] + rng.normal(0, 0.01, 200)

    def fun(x):
        return y - A @ x, A

    result = levenberg_marquardt(fun, np.zeros(3), ["a", "b", "c"], None, None, LMOptions(tau=1e-3))
    np.testing.assert_allclose(result.x, np.linalg.lstsq(A, y, rcond=None)[0], rtol=1e-8)
    assert result.mu_history[0] == pytest.approx(1e-3 * max(np.sum(A * A, axis=0)))


def test_each_start_gets_its_own_stability_floor():
    """A start whose linearization at rest drifts (growth > limit) raises the floor to its own radii; a stable
    start leaves the problem as it is."""
    problem = _engine_problem()
    x = problem.compiled.theta0()
    assert problem.from_start(x) is problem
    names = problem.names
    # a negative friction slope at zero feeds energy in: v*a < 0 for every neuron
    drifting = x.copy()
    for j, name in enumerate(names):
        if name.startswith("MR1.a"):
            drifting[j] = abs(drifting[j]) + 1.0
        elif name.startswith("MR1.v"):
            drifting[j] = -abs(drifting[j]) - 5.0
    chatter, growth = problem.stability(drifting)
    assert growth > GROWTH_LIMIT and chatter <= CHATTER_LIMIT
    own = problem.from_start(drifting)
    assert own.stability_floor == (0.0, growth)
    assert own.guard(drifting) is None and problem.guard(drifting) is not None
