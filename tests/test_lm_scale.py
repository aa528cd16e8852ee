"""LM with the damping scaled per quantity (`scale="jac"`, Moré's D² = running max of the Jacobian's squared
column norms, as MINPACK's lmder and scipy's x_scale='jac').

Oracles: NIST's certified Misra1a values; the invariance that defines the scaling (a quantity expressed in
other units, x = 1000·x', gives the same iterates), which trainlm's mu I lacks; scipy's least_squares on the
same problem."""

from __future__ import annotations

import nist_misra1a as misra
import numpy as np
import pytest
from scipy.optimize import least_squares

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt

JAC = LMOptions(max_iter=500, scale="jac", tau=1e-3)


def test_misra1a_reaches_the_certified_values():
    r = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], options=JAC)
    np.testing.assert_allclose(r.x, misra.CERTIFIED, rtol=1e-6)
    np.testing.assert_allclose(2 * r.cost, misra.RESIDUAL_SUM_OF_SQUARES, rtol=1e-8)


def _rescaled(k: float):
    """Misra1a with b2 given in units k times smaller: b2 = b2' / k."""
    def fun(c):
        e, j = misra.fun(np.array([c[0], c[1] / k]))
        return e, j * np.array([1.0, 1.0 / k])
    return fun


@pytest.mark.parametrize("options, invariant", [(JAC, True), (LMOptions(max_iter=500), False)])
def test_iterates_do_not_depend_on_units_with_jac_scaling(options, invariant):
    a = levenberg_marquardt(misra.fun, misra.START_1, ["b1", "b2"], options=options)
    b = levenberg_marquardt(_rescaled(1e3), misra.START_1 * [1, 1e3], ["b1", "b2"], options=options)
    same = (a.iterations == b.iterations
            and np.allclose(a.cost_history, b.cost_history, rtol=1e-9)
            and np.allclose(a.x, b.x / [1, 1e3], rtol=1e-9))
    assert same is invariant


def test_bounded_problem_matches_scipy_trf():
    """Positivity bounds through the transform, a start 3x off: the same minimum as scipy's trf."""
    lo = np.zeros(2)
    start = misra.CERTIFIED * [3.0, 1 / 3.0]
    r = levenberg_marquardt(misra.fun, start, ["b1", "b2"], lo, None, JAC)
    ref = least_squares(lambda b: -misra.fun(b)[0], start, jac=lambda b: misra.fun(b)[1], bounds=(lo, np.inf),
                        method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    np.testing.assert_allclose(r.x, ref.x, rtol=1e-6)
    assert r.converged


def test_bad_scale_is_refused():
    with pytest.raises(ValueError, match="`scale` must be 'none' or 'jac'"):
        LMOptions(scale="unit")
