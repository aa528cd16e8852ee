"""LM keeps stepping when J^T J overflows (a point near divergence), instead of stopping at a tiny step."""

import numpy as np
import pytest

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_a_jacobian_whose_gram_matrix_overflows_still_gives_a_descent_step():
    x = np.linspace(0.1, 1.0, 20)
    k = 1e160  # d yhat / d a ~ 1e160: (J^T J) ~ 1e321 overflows, e stays finite
    y = k * 2e-160 * x  # the optimum is a = 2e-160

    def fun(p):
        yhat = k * p[0] * x
        return y - yhat, (k * x)[:, None]

    res = levenberg_marquardt(fun, [5e-160], ["a"], options=LMOptions(max_iter=50))
    assert np.isfinite(res.cost)
    # closed form: the cost is 1/2 (a - 2e-160)^2 k^2 |x|^2; it must fall by many orders of magnitude
    start_cost = 0.5 * (3e-160 * k) ** 2 * float(x @ x)
    assert res.cost < 1e-6 * start_cost
    assert res.iterations >= 1
