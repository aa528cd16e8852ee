"""LM with bounds handled in the physical coordinates (``LMOptions.bounds = "box"``, fit.boxstep).

Oracles: scipy's bounded solvers, which share no code with the trainer: ``lsq_linear`` (a bounded linear
least-squares problem whose minimum sits on bounds) and ``least_squares(method='trf')`` (nonlinear problems whose
constrained minimum lies on a bound); and the bounds themselves: every trial point the trainer simulates (seen by
its ``guard``) lies inside them, strictly inside a bound at 0 (above a bound of 5.0 a distance under its
rounding ends on the bound).
"""

import math

import nist_misra1a as misra
import numpy as np
import pytest
from scipy.optimize import least_squares, lsq_linear

from flowchart2sdnn.fit.boxstep import BOX_THETA, feasible_step
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt

BOX = dict(bounds="box", scale="jac", tau=1e-3, damping="nielsen", trial_jacobian=True, max_iter=500,
           min_rel_cost_change=1e-15)


def _fit(fun, x0, lower, upper, **options):
    """The box fit and every trial point it simulated (its guard sees each one before the simulation)."""
    trials = []

    def guard(x):
        trials.append(np.array(x))

    names = [f"q{i}" for i in range(len(x0))]
    r = levenberg_marquardt(fun, x0, names, lower, upper, LMOptions(**{**BOX, **options}), guard=guard)
    return r, np.array(trials)


def _linear_problem():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 4)) * [1.0, 30.0, 0.02, 1.0]  # columns of very different sizes: the scaling matters
    b = A @ np.array([1.0, -0.5 / 30, 0.3 / 0.02, 2.0]) + 0.01 * rng.normal(size=40)
    lower = np.array([0.0, 0.0, -50.0, -np.inf])
    upper = np.array([np.inf, np.inf, 5.0, 1.5])
    return A, b, lower, upper


def test_a_linear_fit_whose_minimum_sits_on_bounds_is_lsq_linears():
    A, b, lower, upper = _linear_problem()
    ref = lsq_linear(A, b, bounds=(lower, upper), tol=1e-15, method="bvls")
    assert list(ref.active_mask) == [0, -1, 1, 1]  # three of four quantities end on a bound: the case tested
    r, trials = _fit(lambda x: (b - A @ x, A), [0.5, 0.02, 1.0, 1.0], lower, upper)
    assert r.converged
    assert r.cost == pytest.approx(0.5 * np.sum((b - A @ ref.x) ** 2), rel=1e-9)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6, atol=1e-9)
    assert np.all(trials >= lower) and np.all(trials <= upper)  # inside, every trial
    # strictly inside where floating point can tell: above the min 0 (q1's minimum), x + theta (5 - x) reaches 5.0
    # itself once 5 - x falls below its rounding
    assert np.all(trials[:, :2] > 0.0)
    assert r.iterations <= 30


def test_a_linear_fit_from_a_start_on_its_bounds_leaves_the_bound_it_should():
    """q0 starts on its min 0 and its minimum is above it; q1 starts on its min and stays there."""
    A, b, lower, upper = _linear_problem()
    ref = lsq_linear(A, b, bounds=(lower, upper), tol=1e-15, method="bvls")
    r, trials = _fit(lambda x: (b - A @ x, A), [0.0, 0.0, 5.0, 1.5], lower, upper)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6, atol=1e-9)
    assert np.all(trials >= lower) and np.all(trials <= upper)
    assert np.all(trials[:, 1] == 0.0)  # pushed outwards from its bound at every trial: held there


def _decay(t, y):
    """y = a exp(-k t) + c: residual and Jacobian, by hand."""
    def fun(p):
        ex = np.exp(-p[1] * t)
        return y - (p[0] * ex + p[2]), np.column_stack([ex, -p[0] * t * ex, np.ones_like(t)])
    return fun


@pytest.mark.parametrize("x0", [[1.0, 0.2, 0.5], [5.0, 3.0, 2.0], [0.3, 0.05, 0.01]])
def test_a_decay_whose_offset_goes_to_its_bound_ends_where_trf_does(x0):
    """The data's offset is -0.2 below the bound c >= 0: the constrained minimum has c = 0 and a, k adjusted."""
    t = np.linspace(0.0, 4.0, 60)
    y = 2.0 * np.exp(-1.3 * t) - 0.2 + 0.005 * np.random.default_rng(1).normal(size=t.size)
    fun = _decay(t, y)
    lower, upper = np.array([0.0, 0.0, 0.0]), np.array([np.inf, np.inf, np.inf])
    ref = least_squares(lambda p: fun(p)[0], x0, jac=lambda p: -fun(p)[1], bounds=(lower, upper), method="trf",
                        x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15)
    assert ref.x[2] < 1e-6  # the offset ends on its bound in the oracle
    r, trials = _fit(fun, x0, lower, upper)
    assert r.converged
    assert r.cost == pytest.approx(ref.cost, rel=1e-8)
    np.testing.assert_allclose(r.x[:2], ref.x[:2], rtol=1e-5)
    assert r.x[2] < 1e-6
    assert np.all(trials > lower)
    assert r.iterations <= 40


def test_misra1a_with_b1_capped_below_its_certified_value_ends_where_trf_does():
    lower, upper = np.array([0.0, 0.0]), np.array([200.0, np.inf])  # certified b1 = 238.9
    x0 = np.array([100.0, 1e-4])
    ref = least_squares(lambda b: misra.fun(b)[0], x0, jac=lambda b: -misra.fun(b)[1], bounds=(lower, upper),
                        method="trf", x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15)
    assert ref.x[0] == pytest.approx(200.0, rel=1e-9)
    r, trials = _fit(misra.fun, x0, lower, upper)
    assert r.converged
    assert r.cost == pytest.approx(ref.cost, rel=1e-8)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6)
    assert np.all(trials[:, 0] < 200.0)


def test_misra1a_unbounded_where_it_matters_gives_the_certified_values():
    r, _ = _fit(misra.fun, misra.START_1, [0.0, 0.0], None)
    np.testing.assert_allclose(r.x, misra.CERTIFIED, rtol=1e-6)
    assert 2 * r.cost == pytest.approx(misra.RESIDUAL_SUM_OF_SQUARES, rel=1e-8)


def test_a_crossing_component_is_held_at_theta_of_its_room_and_the_others_re_solved():
    """One step by hand: x = (1, 1) above min 0, dx = (-3, 0.5) crosses on q0; the resolve gets q0 held at
    -0.995 and returns its partner's step for it."""
    calls = []

    def resolve(held, value):
        calls.append((held.copy(), value.copy()))
        return np.array([123.0, 0.5 + 0.1 * value[0]])  # the held component's entry is ignored

    step = feasible_step(np.array([1.0, 1.0]), np.array([-3.0, 0.5]), np.array([0.0, 0.0]),
                         np.array([np.inf, np.inf]), resolve)
    assert len(calls) == 1 and list(calls[0][0]) == [True, False]
    np.testing.assert_allclose(step, [-BOX_THETA, 0.5 - 0.1 * BOX_THETA], rtol=1e-15)
    inside = feasible_step(np.array([1.0, 1.0]), np.array([-0.5, 6.9]), np.array([0.0, 0.0]),
                           np.array([np.inf, 8.0]), resolve)
    np.testing.assert_array_equal(inside, [-0.5, 6.9])  # within theta of every room: untouched, no resolve
    assert len(calls) == 1


def test_box_takes_plain_steps_only():
    with pytest.raises(ValueError, match="geodesic"):
        LMOptions(bounds="box", geodesic=0.75)
    with pytest.raises(ValueError, match="bound_width"):
        LMOptions(bounds="box", bound_width=0.01)
    with pytest.raises(ValueError, match="`bounds` must be"):
        LMOptions(bounds="clip")
    assert math.isclose(BOX_THETA, 0.995)


def test_a_sparse_jacobian_takes_the_same_box_steps_as_the_dense_one():
    """Multiple shooting hands the trainer CSR Jacobians (fit.lm): the held components' re-solve must take them."""
    from scipy import sparse

    A, b, lower, upper = _linear_problem()
    dense, _ = _fit(lambda x: (b - A @ x, A), [0.5, 0.02, 1.0, 1.0], lower, upper)
    csr, _ = _fit(lambda x: (b - A @ x, sparse.csr_matrix(A)), [0.5, 0.02, 1.0, 1.0], lower, upper)
    np.testing.assert_allclose(csr.cost_history, dense.cost_history, rtol=1e-10)
    np.testing.assert_allclose(csr.x, dense.x, rtol=1e-10, atol=1e-14)


# ------------------------------------------------------------------------------------ the trust-radius damping
def test_the_damping_for_a_radius_gives_a_step_of_that_length():
    """Oracle: the step solved directly, (A + mu I)^-1 g by numpy, for the mu the secular equation returned;
    a badly scaled A (columns 0.1 to 10) and radii from 1e-3 to half the Gauss-Newton step."""
    from flowchart2sdnn.fit.steps import RADIUS_TOLERANCE, mu_for_radius

    rng = np.random.default_rng(5)
    J = rng.normal(size=(30, 4)) * [1.0, 10.0, 0.1, 1.0]
    A, g = J.T @ J, J.T @ rng.normal(size=30)
    gauss_newton = float(np.linalg.norm(np.linalg.solve(A, g)))
    for radius in (1e-3, 0.1, 0.5 * gauss_newton):
        mu = mu_for_radius(A, g, radius)
        assert mu > 0
        assert np.linalg.norm(np.linalg.solve(A + mu * np.eye(4), g)) == pytest.approx(radius, rel=RADIUS_TOLERANCE)
    assert mu_for_radius(A, g, 2.0 * gauss_newton) == 0.0  # the Gauss-Newton step fits: no damping


def test_the_trust_radius_follows_the_gain_ratio():
    from flowchart2sdnn.fit.steps import trust_accepted

    assert trust_accepted(4.0, 0.1, 2.0) == 0.5  # a poor model: a quarter of the step taken
    assert trust_accepted(4.0, 0.5, 2.0) == 4.0  # fair: unchanged
    assert trust_accepted(4.0, 0.9, 3.0) == 6.0  # good: twice the step
    assert trust_accepted(10.0, 0.9, 3.0) == 10.0  # ... never below the radius it had


TRUST = dict(damping="trust")


def test_trust_steps_in_the_box_end_at_lsq_linears_minimum():
    A, b, lower, upper = _linear_problem()
    ref = lsq_linear(A, b, bounds=(lower, upper), tol=1e-15, method="bvls")
    r, trials = _fit(lambda x: (b - A @ x, A), [0.5, 0.02, 1.0, 1.0], lower, upper, **TRUST)
    assert r.converged
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6, atol=1e-9)
    assert np.all(trials >= lower) and np.all(trials <= upper) and np.all(trials[:, :2] > 0.0)


@pytest.mark.parametrize("x0", [[1.0, 0.2, 0.5], [5.0, 3.0, 2.0], [0.3, 0.05, 0.01]])
def test_trust_steps_on_the_decay_end_where_trf_does(x0):
    t = np.linspace(0.0, 4.0, 60)
    y = 2.0 * np.exp(-1.3 * t) - 0.2 + 0.005 * np.random.default_rng(1).normal(size=t.size)
    fun = _decay(t, y)
    lower, upper = np.zeros(3), np.full(3, np.inf)
    ref = least_squares(lambda p: fun(p)[0], x0, jac=lambda p: -fun(p)[1], bounds=(lower, upper), method="trf",
                        x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15)
    r, trials = _fit(fun, x0, lower, upper, **TRUST)
    assert r.converged
    assert r.cost == pytest.approx(ref.cost, rel=1e-8)
    np.testing.assert_allclose(r.x[:2], ref.x[:2], rtol=1e-5)
    assert np.all(trials > lower)


def test_trust_steps_give_misra1as_certified_values_and_its_capped_minimum():
    r, _ = _fit(misra.fun, misra.START_1, [0.0, 0.0], None, **TRUST)
    np.testing.assert_allclose(r.x, misra.CERTIFIED, rtol=1e-6)
    lower, upper = np.array([0.0, 0.0]), np.array([200.0, np.inf])
    ref = least_squares(lambda b: misra.fun(b)[0], [100.0, 1e-4], jac=lambda b: -misra.fun(b)[1],
                        bounds=(lower, upper), method="trf", x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15)
    r, _ = _fit(misra.fun, [100.0, 1e-4], lower, upper, **TRUST)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6)
