"""Covariance and identifiability against textbook formulas and NIST certified standard deviations."""

import nist_misra1a as misra
import numpy as np
import pytest
from scipy.stats import t as student_t

from flowchart2sdnn.fit.lm import levenberg_marquardt
from flowchart2sdnn.fit.uncertainty import covariance


def test_linear_least_squares_matches_the_textbook_formula():
    rng = np.random.default_rng(11)
    m = 40
    X = np.column_stack([np.ones(m), rng.normal(size=m), rng.uniform(-2, 2, size=m)])
    beta = np.array([1.0, -2.0, 0.5])
    y = X @ beta + 0.3 * rng.normal(size=m)
    bhat = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ bhat
    sigma2 = e @ e / (m - 3)
    textbook = sigma2 * np.linalg.solve(X.T @ X, np.eye(3))

    c = covariance(X, e, names=["b0", "b1", "b2"])
    assert c.available and c.dof == m - 3
    np.testing.assert_allclose(c.sigma2, sigma2, rtol=1e-12)
    np.testing.assert_allclose(c.cov, textbook, rtol=1e-10)
    se = np.sqrt(np.diag(textbook))
    np.testing.assert_allclose(c.stderr, se, rtol=1e-10)
    np.testing.assert_allclose(c.ci95, student_t.ppf(0.975, m - 3) * se, rtol=1e-10)
    np.testing.assert_allclose(c.correlation, textbook / np.outer(se, se), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(c.condition_number, np.linalg.cond(X), rtol=1e-10)
    assert c.unidentifiable == () and c.warning is None


def test_misra1a_certified_standard_deviations():
    res = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"])
    c = covariance(res.jac, res.residual, names=res.names)
    np.testing.assert_allclose(c.stderr, misra.CERTIFIED_SD, rtol=1e-6)
    np.testing.assert_allclose(np.sqrt(c.sigma2), misra.RESIDUAL_SD, rtol=1e-8)
    # columns differ by 1e5 in size, yet nothing is unidentifiable: the rank test is scale-free
    assert c.condition_number > 1e6
    assert c.unidentifiable == ()


def product_jacobian(a, b, c, t):
    # yhat = a * b * t + c
    return np.column_stack([b * t, a * t, np.ones_like(t)])


def test_parameters_appearing_only_as_a_product_are_unidentifiable_by_name():
    t = np.linspace(0, 1, 30)
    rng = np.random.default_rng(5)
    e = 0.1 * rng.normal(size=t.size)
    for a, b in [(2.0, 3.0), (1e3, 1e-3)]:  # the second case: very different scales
        c = covariance(product_jacobian(a, b, 0.5, t), e, names=["gain_a", "gain_b", "offset"])
        assert c.unidentifiable == (("gain_a", "gain_b"),)
        assert "`gain_a`, `gain_b` cannot be told apart" in c.warning
        assert np.isinf(c.stderr[0]) and np.isinf(c.stderr[1]) and np.isfinite(c.stderr[2])
        assert np.isnan(c.correlation[0, 2])


def test_two_separate_degenerate_pairs_are_two_groups():
    t = np.linspace(0.1, 1, 40)
    # yhat = a*b*t + c*d*t^2 + f: the null space is two-dimensional, any basis of it mixes the pairs
    J = np.column_stack([2 * t, 3 * t, 0.5 * t**2, 4 * t**2, np.ones_like(t)])
    rng = np.random.default_rng(6)
    perm = rng.permutation(5)  # the grouping must not depend on the parameter order
    names = np.array(["a", "b", "c", "d", "f"])
    c = covariance(J[:, perm], 0.01 * rng.normal(size=t.size), names=list(names[perm]))
    groups = sorted(tuple(sorted(g)) for g in c.unidentifiable)
    assert groups == [("a", "b"), ("c", "d")]


def test_a_quantity_without_effect_and_an_almost_collinear_pair():
    t = np.linspace(0, 1, 50)
    rng = np.random.default_rng(8)
    J = np.column_stack([t, t + 1e-4 * rng.normal(size=t.size), np.ones_like(t), np.zeros_like(t)])
    c = covariance(J, 0.01 * rng.normal(size=t.size), names=["J2", "c", "d", "unused"])
    assert ("unused",) in c.unidentifiable
    assert ("J2", "c") in c.unidentifiable
    assert [(a, b) for a, b, _ in c.correlated] == [("J2", "c")]
    assert abs(c.correlated[0][2]) > 0.999
    assert "`unused` has no visible effect" in c.warning
    assert "practically interchangeable" in c.warning
    assert np.isfinite(c.stderr[0]) and np.isinf(c.stderr[3])


def test_too_few_residuals_gives_no_covariance_but_a_reason():
    J = np.array([[1.0, 2.0], [3.0, 4.0]])
    c = covariance(J, np.array([0.1, -0.1]), names=["a", "b"])
    assert not c.available and c.cov is None and c.stderr is None and c.ci95 is None
    assert "2 residuals for 2 parameters" in c.reason
    c = covariance(np.ones((3, 1)), np.zeros(3), n_params=3)
    assert not c.available and c.dof == 0


def test_arguments_are_validated():
    with pytest.raises(ValueError, match="shape"):
        covariance(np.ones((4, 2)), np.ones(3))
    with pytest.raises(ValueError, match="finite"):
        covariance(np.full((4, 2), np.nan), np.ones(4))
    with pytest.raises(ValueError, match="`names` has 1 entries"):
        covariance(np.ones((4, 2)), np.ones(4), names=["a"])
