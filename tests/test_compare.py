"""`sdnn compare` and Identification.compare: free run and k-step-ahead prediction against hand formulas.

The oracle chart is one integrator, w' = M / J: with the zoh alignment its network is
w(k) = w(k-1) + T/J * M(k-1), so the free run is a cumulative sum and the k-step prediction restarts that sum
from the measured w at every k-th row (the definition in flowchart2sdnn.identify.compare).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.correlation import bound, xcorr
from flowchart2sdnn.identify.compare import compare_records, predict
from flowchart2sdnn.network.runtime import CompiledNetwork

T, J = 0.01, 2.0
CHART = f"""sdnn: 1
name: inertia
sample_time: {T}
inputs:
  M: {{unit: N*m}}
outputs:
  w: {{unit: rad/s}}
parameters:
  J: {{init: {J}, unit: kg*m^2, min: 0}}
blocks:
  acc: {{type: gain, in: M, k: 1/J}}
  w:   {{type: integrator, in: acc}}
"""


@pytest.fixture()
def case(tmp_path):
    chart = tmp_path / "inertia.yaml"
    chart.write_text(CHART)
    rng = np.random.default_rng(3)
    n = 400
    M = rng.uniform(-1, 1, n)
    w = np.concatenate([[0.0], np.cumsum(T / J * M[:-1])]) + 0.05 * np.sin(np.arange(n) / 7.0)  # a model error
    csv = tmp_path / "rec.csv"
    write_csv(csv, {"time": np.arange(n) * T, "M": M, "w": w}, float_format="%.17g")
    return chart, csv, M, w


def _network(chart):
    compiled = CompiledNetwork(compile_diagram(load_diagram(chart)).network)
    return compiled, compiled.theta0()


def _fit(y, yhat):
    return 100 * (1 - np.linalg.norm(y - yhat) / np.linalg.norm(y - y.mean()))


@pytest.mark.parametrize("k", [1, 7, 50])
def test_k_step_prediction_restarts_from_the_measured_output_every_k_samples(case, k):
    chart, csv, M, w = case
    compiled, theta = _network(chart)
    data = sd.read_csv(csv, chart=chart)
    yhat = predict(compiled, theta, data, "zoh", horizon=k)[:, 0]
    expected = np.zeros_like(w)
    for row in range(1, len(w)):
        start = row - 1 - (row - 1) % k  # the row each segment restarts from: 0, k, 2k, ...
        base = 0.0 if start == 0 else w[start]  # the first segment starts from the chart's init
        expected[row] = base + T / J * M[start:row].sum()
    np.testing.assert_allclose(yhat, expected, rtol=0, atol=1e-12)


def test_free_run_and_long_horizons_are_the_cumulative_sum(case):
    chart, csv, M, w = case
    compiled, theta = _network(chart)
    data = sd.read_csv(csv, chart=chart)
    free = np.concatenate([[0.0], np.cumsum(T / J * M[:-1])])
    for horizon in (None, len(w) - 1, 10 * len(w)):
        np.testing.assert_allclose(predict(compiled, theta, data, "zoh", horizon)[:, 0], free, atol=1e-12)
    with pytest.raises(ValueError, match="horizon"):
        predict(compiled, theta, data, "zoh", 0)


def test_metrics_are_fit_percent_and_rms_by_hand(case):
    chart, csv, M, w = case
    compiled, theta = _network(chart)
    data = sd.read_csv(csv, chart=chart)
    free = np.concatenate([[0.0], np.cumsum(T / J * M[:-1])])
    out = compare_records(compiled, theta, [("all", data, 0), ("tail", data, 300)], "zoh", None,
                          load_diagram(chart))
    whole, tail = out.records
    assert whole.rows == len(w) - 1  # row 0 is the initial state, never scored
    assert whole.fit_percent["w"] == pytest.approx(_fit(w[1:], free[1:]), rel=1e-12)
    assert whole.rms["w"] == pytest.approx(np.sqrt(np.mean((w[1:] - free[1:]) ** 2)), rel=1e-12)
    assert tail.rows == 100 and tail.time[0] == pytest.approx(300 * T)
    assert tail.fit_percent["w"] == pytest.approx(_fit(w[300:], free[300:]), rel=1e-12)
    assert out.units == {"M": "N*m", "w": "rad/s"}
    assert [r["record"] for r in out.table()] == ["all", "tail"]


def test_the_resid_correlations_match_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=500), rng.normal(size=500)
    a0, b0 = a - a.mean(), b - b.mean()
    for tau in (-3, 0, 5):
        # r(tau) = sum_t a(t) b(t - tau) / (N std a std b), the biased estimate of Ljung
        full = np.correlate(a0, b0, mode="full")[len(a) - 1 + tau]
        assert xcorr(a, b, [tau])[0] == pytest.approx(full / (500 * a.std() * b.std()), rel=1e-12)
    assert bound(10000) == pytest.approx(2.5758293035489004 / 100)


def test_cli_compare_prints_the_table_and_draws(case, tmp_path):
    chart, csv, M, w = case
    runner = CliRunner()
    res = runner.invoke(main, ["compare", str(chart), str(csv), "--horizon", "7"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "7-step-ahead prediction" in res.output and "rad/s" in res.output
    assert res.output.splitlines()[-1].split()[:2] == ["rec.csv", "w"]
    pytest.importorskip("matplotlib")
    fig = tmp_path / "cmp.png"
    res = runner.invoke(main, ["compare", str(chart), str(csv), str(csv), "-o", str(fig), "--format", "json"])
    assert res.exit_code == 0, res.output
    assert fig.read_bytes()[:4] == b"\x89PNG"
    assert '"fit_percent"' in res.output


def test_cli_compare_errors_are_one_line(case, tmp_path):
    chart, csv, M, w = case
    runner = CliRunner()
    bad = tmp_path / "bad.csv"
    write_csv(bad, {"time": np.arange(5) * T, "M": np.zeros(5)})
    res = runner.invoke(main, ["compare", str(chart), str(bad)])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1 and "'w'" in res.output
    res = runner.invoke(main, ["compare", str(chart), str(csv), "--horizon", "0"])
    assert res.exit_code == 2
    res = runner.invoke(main, ["compare", str(tmp_path / "none.json"), str(csv)])
    assert res.exit_code == 1 and "none.json" in res.output


def test_identification_compare_from_a_result_file(case, tmp_path):
    chart, csv, M, w = case
    data = sd.read_csv(csv, chart=chart)
    result = sd.identify(chart, data, max_iter=5)
    out = result.compare({"rec": data}, horizon=3)
    expected = compare_records(*_network_of(result), [("rec", data, 0)], "zoh", 3)
    assert out.records[0].fit_percent == expected.records[0].fit_percent
    (tmp_path / "r.json").write_text(result.to_json())
    res = CliRunner().invoke(main, ["compare", str(tmp_path / "r.json"), str(csv)])
    assert res.exit_code == 1 and "r.chart.yaml" in res.output  # the identified chart is not beside it
    res = CliRunner().invoke(main, ["compare", str(tmp_path / "r.json"), str(csv), "--diagram", str(chart)])
    assert res.exit_code == 0, res.output
    assert f"{result.fit.train.fit_percent['w']:.6g}" in res.output  # the same number as identify's table
    assert Path(csv).name in res.output


def _network_of(result):
    return result.problem.compiled, result.x


def test_compare_plot_delegates_to_the_report_and_draws_what_it_returns(case, tmp_path, monkeypatch):
    """`plot=` (docs/guide/api.md) still draws, through the view report/ registered: the figure gets the very
    Comparison the call returns, and the PNG is written."""
    pytest.importorskip("matplotlib")
    from flowchart2sdnn.report import figures

    chart, csv, M, w = case
    data = sd.read_csv(csv, chart=chart)
    result = sd.identify(chart, data, max_iter=5)
    seen = []
    real = figures.write_compare
    monkeypatch.setattr(figures, "write_compare", lambda c, path, name="": seen.append(c) or real(c, path, name))
    out = result.compare({"rec": data}, plot=tmp_path / "c.png")
    assert seen == [out]
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
