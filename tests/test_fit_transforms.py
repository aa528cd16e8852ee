"""Bounds transform: the four formulas written out independently, inverse, derivative by finite differences."""

import numpy as np
import pytest

from flowchart2sdnn.fit.transforms import BOUND_NUDGE, Bounds

INF = np.inf
NAMES = ("free", "lo_only", "hi_only", "both")
LO = np.array([-INF, 0.5, -INF, -2.0])
HI = np.array([INF, INF, 3.0, 5.0])


def reference_x(u):
    """The transform as given in the specification (lmfit / MINUIT formulas)."""
    return np.array(
        [
            u[0],
            LO[1] - 1 + np.sqrt(u[1] ** 2 + 1),
            HI[2] + 1 - np.sqrt(u[2] ** 2 + 1),
            LO[3] + (HI[3] - LO[3]) * (np.sin(u[3]) + 1) / 2,
        ]
    )


@pytest.fixture
def bounds():
    return Bounds.make(NAMES, LO, HI)


def test_external_matches_the_reference_formulas(bounds):
    rng = np.random.default_rng(1)
    for u in rng.normal(scale=3.0, size=(50, 4)):
        np.testing.assert_allclose(bounds.to_external(u), reference_x(u), rtol=1e-13, atol=1e-13)


def test_internal_inverts_external(bounds):
    rng = np.random.default_rng(2)
    for _ in range(50):
        x = np.array([rng.normal(), 0.5 + rng.exponential(), 3.0 - rng.exponential(), rng.uniform(-2, 5)])
        np.testing.assert_allclose(bounds.to_external(bounds.to_internal(x)), x, rtol=1e-12, atol=1e-12)


def test_derivative_matches_central_differences(bounds):
    rng = np.random.default_rng(3)
    h = 1e-6
    for u in rng.normal(scale=2.0, size=(20, 4)):
        fd = np.array(
            [
                (reference_x(u + h * np.eye(4)[i])[i] - reference_x(u - h * np.eye(4)[i])[i]) / (2 * h)
                for i in range(4)
            ]
        )
        np.testing.assert_allclose(bounds.dx_du(u), fd, rtol=1e-7, atol=1e-9)


def test_range_is_exactly_within_bounds_even_for_wild_u(bounds):
    for scale in (1e-200, 1.0, 1e8, 1e200):
        for sign in (-1, 1):
            x = bounds.to_external(np.full(4, sign * scale))
            assert np.all(np.isfinite(x))
            assert np.all(x >= LO) and np.all(x <= HI)
    # tiny offsets from a bound must not round below it (min - 1 + 1 would)
    b = Bounds.make(["k"], [1e-20], None)
    assert b.to_external(np.array([1e-12]))[0] >= 1e-20


def test_outside_bounds_names_the_quantity():
    b = Bounds.make(["J1", "J2"], [0.0, 0.0], [INF, INF])
    with pytest.raises(ValueError, match=r"`J2` = -1 is below its min 0"):
        b.to_internal(np.array([1.0, -1.0]))
    b = Bounds.make(["c"], None, [10.0])
    with pytest.raises(ValueError, match=r"`c` = 12 is above its max 10"):
        b.check(np.array([12.0]))


def test_value_on_a_bound_is_allowed_and_the_start_is_moved_inside(bounds):
    x = np.array([0.0, 0.5, 3.0, 5.0])
    u = bounds.to_internal(x)
    np.testing.assert_allclose(bounds.to_external(u), x, atol=1e-15)
    start = bounds.start(x)
    assert np.all(bounds.dx_du(start)[1:] != 0)  # the quantity can move
    moved = bounds.to_external(start)
    assert moved[0] == 0.0
    assert 0.5 < moved[1] <= 0.5 + BOUND_NUDGE**2
    assert 3.0 - BOUND_NUDGE**2 <= moved[2] < 3.0
    assert 5.0 - 7 * BOUND_NUDGE**2 <= moved[3] < 5.0


def test_bad_bounds_are_refused():
    with pytest.raises(ValueError, match="`a` has min 2 >= max 1"):
        Bounds.make(["a"], [2.0], [1.0])
    with pytest.raises(ValueError, match="`lower` has 1 entries, expected 2"):
        Bounds.make(["a", "b"], [0.0], None)
    with pytest.raises(ValueError, match="NaN"):
        Bounds.make(["a"], [np.nan], None)
