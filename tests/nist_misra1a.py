"""NIST StRD nonlinear regression data set Misra1a (lower difficulty): y = b1 * (1 - exp(-b2 * x)).

Data and certified values from https://www.itl.nist.gov/div898/strd/nls/data/misra1a.shtml
"""

import numpy as np

X = np.array(
    [77.6, 114.9, 141.1, 190.8, 239.9, 289.0, 332.8, 378.4, 434.8, 477.3, 536.8, 593.1, 689.1, 760.0]
)
Y = np.array(
    [10.07, 14.73, 17.94, 23.93, 29.61, 35.18, 40.02, 44.82, 50.76, 55.05, 61.01, 66.40, 75.47, 81.78]
)
START_1 = np.array([500.0, 1e-4])
CERTIFIED = np.array([2.3894212918e02, 5.5015643181e-04])
CERTIFIED_SD = np.array([2.7070075241e00, 7.2668688436e-06])
RESIDUAL_SUM_OF_SQUARES = 1.2455138894e-01
RESIDUAL_SD = 1.0187876330e-01


def fun(b):
    """(e, J): residual y - yhat and the model Jacobian d yhat / db (derived by hand)."""
    ex = np.exp(-b[1] * X)
    return Y - b[0] * (1 - ex), np.column_stack([1 - ex, b[0] * X * ex])


def residual(b):
    return Y - b[0] * (1 - np.exp(-b[1] * X))
