"""FitResult: exact JSON round trip, refusal of non-finite values, assembly from a trainer result."""

import json
import math

import numpy as np
import pytest
from scipy.stats import t as student_t

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.result import FitResult, fit_result_from_lm
from flowchart2sdnn.fit.uncertainty import covariance


def sample_result(**over):
    kwargs = dict(
        names=("J2", "c", "d"),
        values=np.array([0.3838, 477.2, 0.2406]),
        initial_values=[0.7, 100, 0.4],
        status="min_grad",
        message="the gradient norm fell below `min_grad`",
        units=("kg m^2", "N m/rad", None),
        fixed=(False, False, True),
        stderr=(np.float64(0.0012), 1.5, None),
        ci95=((0.381, 0.386), [474.2, 480.2], None),
        correlation=[[1.0, 0.31, None], [0.31, 1.0, None], [None, None, None]],
        cost=np.float32(0.03792),
        iterations=np.int64(12),
        cost_history=[5.0, 1.0, 0.1 + 0.2],  # 0.30000000000000004 must survive exactly
        mu_history=[1e-3, 1e-4, 1e-5],
        warnings=["something to know"],
        seed=np.int64(42),
        settings={
            "window": 25000,
            "sample_time": 0.001,
            "nested": {"flag": np.bool_(True), "list": (1, 2.5)},
        },
        starts={"n": 3, "costs": [0.03, 0.05, None]},
        trajectories={"J2": np.linspace(0.7, 0.38, 5)},
        nonlinear_weights={"friction2": {"a": [0.1, -0.2, 0.3], "v": [1.0, 2.0, 3.0], "b": [0.0, 0.1, -0.1]}},
    )
    kwargs.update(over)
    return FitResult(**kwargs)


def test_round_trip_is_exact():
    r = sample_result()
    d = r.to_dict()
    assert d["format"] == "flowchart2sdnn-fit-result" and d["version"] == 1
    assert FitResult.from_dict(d) == r
    assert json.loads(r.to_json()) == d
    assert FitResult.from_json(r.to_json()) == r
    assert FitResult.from_dict(json.loads(r.to_json())).to_dict() == d
    assert d["cost_history"][2] == 0.1 + 0.2
    # numpy types are gone, the int/float distinction of settings is kept
    assert type(d["iterations"]) is int and type(d["seed"]) is int and type(d["values"][0]) is float
    assert type(d["settings"]["window"]) is int and type(d["settings"]["nested"]["flag"]) is bool
    assert d["trajectories"]["J2"][0] == 0.7


def test_extra_keys_are_ignored_and_wrong_format_refused():
    d = sample_result().to_dict()
    d["chart"] = "two_mass.yaml"
    assert FitResult.from_dict(d) == sample_result()
    with pytest.raises(ValueError, match="not a fit result"):
        FitResult.from_dict({**d, "format": "network"})
    with pytest.raises(ValueError, match="lacks values"):
        FitResult.from_dict({k: v for k, v in d.items() if k != "values"})


@pytest.mark.parametrize(
    "over, path",
    [
        ({"values": [0.1, math.nan, 0.2]}, "values"),
        ({"stderr": (np.inf, 1.0, None)}, "stderr"),
        ({"settings": {"nested": {"x": [1.0, math.inf]}}}, r"settings.nested.x\[1\]"),
        ({"trajectories": {"c": [1.0, math.nan]}}, r"trajectories.c\[1\]"),
        ({"cost": math.inf}, "cost"),
    ],
)
def test_non_finite_values_are_refused_with_their_path(over, path):
    with pytest.raises(ValueError, match=path):
        sample_result(**over)


def test_inconsistent_lengths_and_types_are_refused():
    with pytest.raises(ValueError, match="`units` has 2 entries"):
        sample_result(units=("a", "b"))
    with pytest.raises(ValueError, match="correlation"):
        sample_result(correlation=[[1.0]])
    with pytest.raises(ValueError, match="non-string key"):
        sample_result(settings={1: 2})
    with pytest.raises(ValueError, match="not JSON data"):
        sample_result(settings={"x": object()})


def test_result_is_immutable():
    r = sample_result()
    with pytest.raises(TypeError):
        r.settings["window"] = 1
    with pytest.raises(AttributeError):
        r.status = "other"
    assert isinstance(r.values, tuple) and isinstance(r.trajectories["J2"], tuple)


def test_assembled_from_a_line_fit_with_a_fixed_quantity():
    t = np.linspace(0, 1, 12)
    rng = np.random.default_rng(3)
    y = 2.0 * t + 1.0 + 0.05 * rng.normal(size=t.size)
    X = np.column_stack([t, np.ones_like(t)])

    lm = levenberg_marquardt(lambda p: (y - X @ p, X), [0.0, 0.0], ["a", "b"], options=LMOptions())
    cov = covariance(lm.jac, lm.residual, names=lm.names)
    fr = fit_result_from_lm(
        lm,
        initial_values=[0.0, 0.0],
        covariance=cov,
        units={"a": "1/s", "T": "s"},
        fixed_values={"T": 0.001},
        order=["T", "a", "b"],
        seed=7,
        settings={"max_iter": 100},
    )
    # oracle: ordinary least squares by hand
    bhat = np.linalg.lstsq(X, y, rcond=None)[0]
    e = y - X @ bhat
    se = np.sqrt(np.diag(e @ e / (12 - 2) * np.linalg.solve(X.T @ X, np.eye(2))))
    half = student_t.ppf(0.975, 10) * se
    assert fr.names == ("T", "a", "b") and fr.fixed == (True, False, False)
    assert fr.units == ("s", "1/s", None)
    np.testing.assert_allclose(fr.values, [0.001, *bhat], rtol=1e-9)
    assert fr.stderr[0] is None and fr.ci95[0] is None
    np.testing.assert_allclose(fr.stderr[1:], se, rtol=1e-6)
    np.testing.assert_allclose(fr.ci95[1], [bhat[0] - half[0], bhat[0] + half[0]], rtol=1e-6)
    assert fr.correlation[0] == (None, None, None) and fr.correlation[1][1] == 1.0
    assert fr.warnings == () and fr.seed == 7
    assert FitResult.from_json(fr.to_json()) == fr


def test_assembly_carries_warnings_and_maps_infinite_errors_to_none():
    t = np.linspace(0, 1, 20)
    y = 6.0 * t

    def fun(p):  # yhat = a * b * t: a and b cannot be told apart
        return y - p[0] * p[1] * t, np.column_stack([p[1] * t, p[0] * t])

    lm = levenberg_marquardt(fun, [1.0, 1.0], ["a", "b"], options=LMOptions(max_iter=2))
    cov = covariance(lm.jac, lm.residual, names=lm.names)
    fr = fit_result_from_lm(lm, initial_values=[1.0, 1.0], covariance=cov)
    assert fr.stderr == (None, None) and fr.ci95 == (None, None)
    assert any("did not converge" in w or "before converging" in w for w in fr.warnings)
    assert any("`a`, `b` cannot be told apart" in w for w in fr.warnings)
    json.loads(fr.to_json())
