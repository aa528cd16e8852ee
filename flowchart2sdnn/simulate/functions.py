"""The chart's `function` blocks, written from their definitions for the continuous oracle (shares no code
with the network's transfer functions, so that one checks the other)."""

from __future__ import annotations

import math

from numba import njit

__all__ = ["FUNCTION_CODES", "chart_function"]

FUNCTION_CODES = {"tanh": 0, "sin": 1, "cos": 2, "sign_smooth": 3, "sat": 4, "sqrt": 5, "abs": 6, "exp": 7,
                  "square": 8, "signed_square": 9}


@njit(cache=True, inline="always", error_model="numpy")
def _sqrt(z, eps):
    """The chart's square root: exact outside (-eps, eps), odd, and a cubic with a finite slope in between."""
    if z >= eps:
        return math.sqrt(z)
    if z <= -eps:
        return -math.sqrt(-z)
    u = z / eps
    return math.sqrt(eps) * (5.0 * u - u * u * u) / 4.0


@njit(cache=True, inline="always", error_model="numpy")
def chart_function(f, z, eps):
    """f(z) for the function code `f` (FUNCTION_CODES); `eps` is sign_smooth's and sqrt's width."""
    if f == 0:
        return math.tanh(z)
    if f == 1:
        return math.sin(z)
    if f == 2:
        return math.cos(z)
    if f == 4:
        return min(1.0, max(-1.0, z))
    if f == 5:
        return _sqrt(z, eps)
    if f == 6:
        return abs(z)
    if f == 7:
        return math.exp(z)
    if f == 8:
        return z * z
    if f == 9:
        return z * abs(z)
    return math.tanh(z / eps)  # 3: sign_smooth
