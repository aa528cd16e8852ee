"""Inputs between their samples: `intersample: hold | linear` and a fractional dead time `delay: tau`.

Oracles: scipy's quad over the reconstructed signal (the step means), central finite differences (the RTRL
Jacobian with a fitted dead time), and scipy's solve_ivp run of a hardening-spring oscillator with a smooth
input (tests/smooth_oracle.py) for the acceptance fits.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import smooth_oracle as so
from click.testing import CliRunner
from scipy.integrate import quad

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.diagram.dump import dump_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.inputsignal import step_inputs
from flowchart2sdnn.network.model import Network
from flowchart2sdnn.network.runtime import CompiledNetwork
from tests.test_rtrl import assert_jacobian_matches


# ------------------------------------------------------------------------------------------- step means
def _reconstruction(u, linear):
    """The continuous input of the samples u (time in samples), independent of network.inputsignal."""
    q = len(u)

    def f(s):
        if s <= 0:
            return u[0]
        if not linear:
            return u[min(int(np.floor(s)), q - 1)]
        if s >= q - 1:
            return u[-1] + (min(s, q) - (q - 1)) * (u[-1] - u[-2])
        return float(np.interp(s, np.arange(q), u))

    return f


@pytest.mark.parametrize("linear", [False, True])
@pytest.mark.parametrize("shift", [0.0, 0.3, 1.5, 4.7, -0.4])
@pytest.mark.parametrize("substeps", [1, 3])
def test_step_inputs_are_the_means_of_the_reconstructed_signal(linear, shift, substeps):
    u = np.random.default_rng(2).standard_normal(12)
    p, dp = step_inputs(u[:, None], substeps, np.array([linear]), np.array([shift]), with_derivative=True)
    f = _reconstruction(u, linear)
    h = 1.0 / substeps
    for k in range(len(p)):
        a = k * h - shift
        brk = [x for x in np.arange(np.floor(a), np.ceil(a + h) + 1) if a < x < a + h]
        mean = quad(f, a, a + h, points=brk or None, limit=200)[0] / h
        assert p[k, 0] == pytest.approx(mean, abs=1e-10), k
    # d mean / d shift against central differences (at a held signal's kinks, whole-sample shifts, the mean of
    # the one-sided derivatives)
    e = 1e-7
    plus = step_inputs(u[:, None], substeps, np.array([linear]), np.array([shift + e]))[0]
    minus = step_inputs(u[:, None], substeps, np.array([linear]), np.array([shift - e]))[0]
    np.testing.assert_allclose(dp, (plus - minus) / (2 * e), atol=1e-6)


def test_held_input_without_delay_is_each_sample_repeated():
    u = np.random.default_rng(1).standard_normal((7, 2))
    p, _ = step_inputs(u, 4, np.array([False, False]), np.zeros(2))
    np.testing.assert_allclose(p, np.repeat(u, 4, axis=0), rtol=0, atol=1e-14)


# ----------------------------------------------------------------------------------------------- charts
def _chart(input_keys: str = "", more: str = "", blocks: str = "", substeps: int = 2) -> str:
    return (f"sdnn: 1\nname: t\nsample_time: 0.01\nsubsteps: {substeps}\ninputs:\n  u: {{unit: N{input_keys}}}\n"
            "outputs:\n  x: {}\nparameters:\n  k: {init: 40}\n  c: {init: 0.3}\n" + more + "blocks:\n"
            + (blocks or "  F: {type: sum, in: [u, -Fk, -Fd]}\n  v: {type: integrator, in: F}\n"
                         "  x: {type: integrator, in: v}\n  Fk: {type: gain, in: x, k: k}\n"
                         "  Fd: {type: product, in: [v, u], k: c}\n"))


@pytest.mark.parametrize("keys", [", intersample: linear", ", delay: tau", ", intersample: linear, delay: tau"])
@pytest.mark.parametrize("substeps", [1, 3])
def test_jacobian_with_a_fitted_dead_time_matches_finite_differences(keys, substeps):
    # the input also enters a product neuron: its dead time's sensitivity goes through the product rule there
    text = _chart(keys, "  tau: {init: 0.0237, unit: s}\n" if "tau" in keys else "", substeps=substeps)
    cn = CompiledNetwork(compile_diagram(diagram_from_text(text, "t.yaml")).network)
    u = np.cumsum(np.random.default_rng(4).standard_normal((80, 1)), axis=0)
    assert_jacobian_matches(cn, cn.theta0(), u, rtol=1e-5)
    if "tau" in keys:
        assert cn.fitted_delays and "tau" in cn.names


def test_network_file_keeps_intersample_and_delay_and_held_inputs_write_as_before():
    text = _chart(", intersample: linear, delay: tau", "  tau: {init: 0.01, unit: s}\n")
    net = compile_diagram(diagram_from_text(text, "t.yaml")).network
    again = Network.from_json(net.to_json())
    assert again.inputs[0].intersample == "linear" and again.inputs[0].delay == "tau"
    held = compile_diagram(diagram_from_text(_chart(), "t.yaml")).network
    assert set(held.to_dict()["inputs"][0]) == {"name", "unit"}


def test_identified_chart_writes_the_keys_back():
    text = _chart(", intersample: linear, delay: 0.004")
    dumped = dump_diagram(diagram_from_text(text, "t.yaml"))
    again = diagram_from_text(dumped, "again.yaml")
    assert again.inputs[0].intersample == "linear" and float(again.inputs[0].delay) == 0.004


@pytest.mark.parametrize(("keys", "code", "words"), [
    (", intersample: cubic", "CHART004", "'intersample' must be one of hold, linear"),
    (", delay: tua", "CHART009", "delay 'tua' is not a parameter"),
    (", delay: [1]", "CHART004", "'delay' must be a dead time in seconds"),
])
def test_bad_input_keys_are_one_line_errors(keys, code, words):
    with pytest.raises(SdnnError) as info:
        diagram_from_text(_chart(keys, "  tau: {init: 0.01}\n"), "t.yaml")
    first = info.value.diagnostics[0]
    assert first.code == code and words in first.message


def test_outputs_take_no_intersample():
    text = _chart().replace("outputs:\n  x: {}", "outputs:\n  x: {intersample: linear}")
    with pytest.raises(SdnnError) as info:
        diagram_from_text(text, "t.yaml")
    assert "intersample" in str(info.value)


# ---------------------------------------------------------------------------------------- acceptance
@functools.cache
def _smooth(tau: float = 0.0):
    t, u, x, sigma = so.record(n=3000, noise=1e-3, tau=tau)
    data = Dataset(path="smooth.csv", columns={"u": u, "x": x}, time=t, n_rows=len(t), sample_time=so.T,
                   max_step_deviation=0.0, sha256="", source_columns={"u": "u", "x": "x"}, time_column="time")
    return data, sigma


def _corrected(ident) -> dict:
    """The tool's values with the discretization's bias taken out (RESULT.json discretization.bias)."""
    bias = ident.to_document()["discretization"]["bias"]
    return {name: bias["corrected"][name]["value"] for name in bias["corrected"]}


def test_linear_intersample_recovers_the_smooth_oscillator_and_hold_is_biased_and_warns(tmp_path):
    data, sigma = _smooth()
    (tmp_path / "linear.yaml").write_text(so.chart_text(input_keys=", intersample: linear"))
    (tmp_path / "hold.yaml").write_text(so.chart_text())
    linear = sd.identify(str(tmp_path / "linear.yaml"), data)
    corrected = _corrected(linear)
    for name in ("k", "d", "k3"):
        assert corrected[name] == pytest.approx(so.TRUE[name], rel=0.01), name
    assert linear.fit.train.rms["x"] < 1.5 * sigma  # the rest is the network's own step error (its floor)
    assert not any("lag 0" in w for w in linear.warnings)
    hold = sd.identify(str(tmp_path / "hold.yaml"), data)
    assert max(abs(hold.parameters[n].value / so.TRUE[n] - 1) for n in ("k", "d", "k3")) > 0.05
    assert hold.fit.train.rms["x"] > 10 * sigma
    warning = next(n for n in hold.notices if n.code == "LAG001")
    assert "intersample: linear" in warning.message and "--intersample u=linear" in warning.message
    assert warning.numbers["input"] == "u" and abs(warning.numbers["r"]) > warning.numbers["chance"]


@pytest.mark.parametrize("samples", [0.3, 1.5, 4.7])
def test_fractional_dead_time_is_recovered_with_a_covering_interval(tmp_path, samples):
    data, _ = _smooth(samples * so.T)
    (tmp_path / "delay.yaml").write_text(so.chart_text(
        input_keys=", intersample: linear, delay: tau",
        more_parameters="  tau: {init: 0.0, unit: s, min: -0.02, max: 0.1}\n"))
    ident = sd.identify(str(tmp_path / "delay.yaml"), data)
    tau = ident.parameters["tau"]
    lo, hi = tau.ci95
    assert lo <= samples * so.T <= hi
    assert abs(_corrected(ident)["tau"] / so.T - samples) < 0.05
    assert abs(tau.value / so.T - samples) < 0.05


def test_command_line_intersample_is_the_chart_key(tmp_path):
    data, _ = _smooth()
    path = tmp_path / "smooth.csv"
    so.write(path, data.time, data.columns["u"], data.columns["x"])
    (tmp_path / "hold.yaml").write_text(so.chart_text())
    res = CliRunner().invoke(main, ["identify", str(path), "--diagram", str(tmp_path / "hold.yaml"),
                                    "--intersample", "u=linear", "--no-floor-bias", "--max-iter", "5",
                                    "-o", str(tmp_path / "r.json")])
    assert res.exit_code == 0, res.output
    assert "intersample: linear" in (tmp_path / "r.chart.yaml").read_text()
    bad = CliRunner().invoke(main, ["identify", str(path), "--diagram", str(tmp_path / "hold.yaml"),
                                    "--intersample", "v=linear"])
    assert bad.exit_code == 2 and "'v' is not an input of the chart" in bad.output


def test_the_online_window_sees_the_inputs_the_offline_kernels_see():
    from flowchart2sdnn.identify.online.run import OnlineRun

    text = _chart(", intersample: linear", substeps=3)
    cn = CompiledNetwork(compile_diagram(diagram_from_text(text, "t.yaml")).network)
    u = np.cumsum(np.random.default_rng(6).standard_normal((40, 1)), axis=0)
    run = OnlineRun(cn, u, np.zeros((40, 1)))
    np.testing.assert_allclose(run.step_inputs, cn.step_inputs(u), rtol=0, atol=0)
    fitted = _chart(", delay: tau", "  tau: {init: 0.01, unit: s}\n")
    cd = CompiledNetwork(compile_diagram(diagram_from_text(fitted, "t.yaml")).network)
    with pytest.raises(SdnnError, match="FIT007"):
        OnlineRun(cd, u, np.zeros((40, 1)))
