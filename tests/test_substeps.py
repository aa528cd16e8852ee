"""Sub-steps (the network at h = T/N, inputs held over the sample) and the `delays: torques` rule.

Oracles: a hand recursion of the sub-stepped first-order lag, central finite differences of the simulation,
the chatter eigenvalue 1 - h*s/J of a mass with a friction slope s, the undamped frequency sqrt(k/m) for auto,
and the continuous RK4 plant (`sdnn excite`, noise-free) for the floor. Never numbers copied from our output.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.analysis.loops import analyse_loops
from flowchart2sdnn.cli.main import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.compiler.substeps import AUTO_BOUND, AUTO_CAP
from flowchart2sdnn.diagram.validate import diagram_from_text, load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.model import Network
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.network.stability import chatter_radius
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite
from tests.test_rtrl import assert_jacobian_matches

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
EULER = Path(__file__).resolve().parent / "data" / "two_mass_euler.yaml"  # two_mass.yaml at N = 1

LAG = """\
sdnn: 1
name: lag
sample_time: 0.01
{extra}
inputs:
  u: {{}}
outputs:
  x: {{}}
parameters:
  tau: {{init: 0.05, min: 0}}
blocks:
  s: {{type: sum, in: [u, -x]}}
  a: {{type: gain, in: s, k: 1/tau}}
  x: {{type: integrator, in: a}}
"""


def _chart(text: str, name: str = "chart.yaml"):
    return diagram_from_text(text, name)


def _compiled(diagram, substeps=None) -> CompiledNetwork:
    return CompiledNetwork(compile_diagram(diagram, substeps=substeps).network)


# ------------------------------------------------------------------------------------------------ semantics
@pytest.mark.parametrize("n", [1, 2, 5])
def test_lag_equals_hand_recursion_at_substeps(n):
    """s = u - x(t-1) (the delayed feedback), x = x(t-1) + h/tau*s, u held over the sample, x read every N."""
    c = _compiled(_chart(LAG.format(extra=f"substeps: {n}")))
    u = np.random.default_rng(0).uniform(-1, 1, (40, 1))
    h, tau = 0.01 / n, 0.05
    x, expected = 0.0, []
    for k in range(40):
        for _ in range(n):
            x = x + h / tau * (u[k, 0] - x)
        expected.append(x)
    np.testing.assert_allclose(c.simulate(c.theta0(), u)[:, 0], expected, rtol=1e-13, atol=1e-15)


def test_substeps_converge_to_the_exact_step_response():
    """First order: the error of the held-input step response halves with every doubling of N."""
    u = np.ones((30, 1))
    exact = 1 - np.exp(-0.01 * np.arange(1, 31) / 0.05)
    errors = []
    for n in (1, 2, 4, 8):
        c = _compiled(_chart(LAG.format(extra="")), substeps=n)
        errors.append(np.max(np.abs(c.simulate(c.theta0(), u)[:, 0] - exact)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.7) & (ratios < 2.3)), ratios


def test_substeps_one_is_todays_network_bit_for_bit():
    """`substeps: 1` (two_mass_euler.yaml pins it) and --substeps 1 over a chart without the key or with another N
    give the same network and the same numbers, to the last bit."""
    base = load_diagram(EULER)
    assert base.substeps == 1 and base.delays == "search"
    nets = [compile_diagram(base).network, compile_diagram(dataclasses.replace(base, substeps=None), substeps=1).network,
            compile_diagram(dataclasses.replace(base, substeps=4), substeps=1).network]
    assert nets[0].weights == nets[1].weights == nets[2].weights
    assert nets[0].delayed_edges == nets[1].delayed_edges
    u = np.random.default_rng(1).uniform(-3, 3, (500, 1))
    runs = []
    for net in nets:
        c = CompiledNetwork(net)
        runs.append((c.simulate(c.theta0(), u), *c.jacobian(c.theta0(), u)))
    for other in runs[1:]:
        for a, b in zip(runs[0], other, strict=True):
            assert np.array_equal(a, b)


def test_weights_carry_the_step_and_delay_blocks_keep_seconds():
    text = LAG.format(extra="substeps: 4").replace("  s: {type: sum, in: [u, -x]}",
                                                   "  ud: {type: delay, in: u, n: 3}\n  s: {type: sum, in: [ud, -x]}")
    net = compile_diagram(_chart(text)).network
    coefs = {w.origin: w for w in net.weights}
    assert float(coefs["s -> a -> x"].coef.split("*")[0]) == pytest.approx(0.0025)
    assert coefs["u -> ud -> s"].delay == 12  # 3 samples of 4 steps
    assert net.step == pytest.approx(0.0025) and net.substeps == 4


def test_network_file_records_h_and_n():
    net = compile_diagram(_chart(LAG.format(extra="substeps: 3"))).network
    doc = net.to_dict()
    assert doc["substeps"] == 3 and doc["step"] == pytest.approx(0.01 / 3) and doc["sample_time"] == 0.01
    assert Network.from_dict(doc).substeps == 3
    del doc["substeps"], doc["step"]  # a file written before sub-steps
    assert Network.from_dict(doc).substeps == 1


# ------------------------------------------------------------------------------------------------ Jacobian
@pytest.mark.parametrize("chart, n", [("three_mass.yaml", 3), ("two_mass.yaml", 2)])
def test_rtrl_through_substeps_equals_finite_differences(chart, n):
    """Physical parameters (three-mass, tanh Coulomb) and learned curves (two-mass) through N steps a sample."""
    diagram = load_diagram(DIAGRAMS / chart)
    c = _compiled(diagram, substeps=n)
    assert c.substeps == n
    t = np.arange(300) * diagram.sample_time
    u = (2.0 * np.sin(2 * np.pi * 1.3 * t) + np.sign(np.sin(2 * np.pi * 3.1 * t)))[:, None]
    assert_jacobian_matches(c, c.theta0(), u, rtol=1e-5)


# ------------------------------------------------------------------------------------------------ guard
MASS = """\
sdnn: 1
name: mass
sample_time: 0.001
substeps: {n}
inputs:
  M: {{}}
outputs:
  w: {{}}
parameters:
  J: {{init: 0.1}}
  F: {{init: 2.0}}
blocks:
  MB: {{type: sum, in: [M, -MR]}}
  acc: {{type: gain, in: MB, k: 1/J}}
  w: {{type: integrator, in: acc}}
  sg: {{type: function, f: tanh, in: w, k: 200}}
  MR: {{type: gain, in: sg, k: F}}
"""


@pytest.mark.parametrize("n", [1, 2, 3, 4, 8])
def test_chatter_guard_bound_is_2J_over_h(n):
    """Friction slope s = F*k = 400 at zero: eigenvalue 1 - h*s/J, chatter when s > 2*J/h (h = T/n)."""
    net = compile_diagram(_chart(MASS.format(n=n))).network
    h, s, J = 0.001 / n, 400.0, 0.1
    z = 1 - h * s / J
    expected = abs(z) if z < 0 else 0.0
    assert chatter_radius(net, net.weight_values()) == pytest.approx(expected, abs=1e-12)
    assert (chatter_radius(net, net.weight_values()) > 1) == (s > 2 * J / h + 1e-9)


# ------------------------------------------------------------------------------------------------ auto
def test_auto_follows_the_fastest_mode():
    """Mass-spring-damper, k = 1250: omega_n = sqrt(k/m) = 25 rad/s (|lambda| of the damped pair is omega_n
    too); auto takes the smallest N with omega*T/N <= bound."""
    text = (DIAGRAMS / "mass_spring_damper.yaml").read_text().replace("init: 800", "init: 1250")
    comp = compile_diagram(_chart(text), substeps="auto")
    omega = math.sqrt(1250 / 2.0)
    assert comp.substeps.omega_max == pytest.approx(omega, rel=0.02)
    assert comp.network.substeps == math.ceil(omega * 0.001 / AUTO_BOUND - 1e-9)
    assert f"substeps N = {comp.network.substeps}" in comp.substeps.explain(0.001)


def test_auto_caps_and_warns():
    """A friction slope of 4000 at zero (J = 0.1) is a mode of 40 000 1/s: more than the cap asks for."""
    comp = compile_diagram(_chart(MASS.format(n="auto").replace("k: 200", "k: 2000")))
    assert comp.network.substeps == AUTO_CAP and comp.substeps.capped
    assert any(w.code == "COMPILE010" for w in comp.warnings)


# ------------------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize("value", ["0", "-2", "2.5", "fast", "true", "[2]", "1001"])
def test_bad_substeps_names_file_and_line(value):
    text = LAG.format(extra=f"substeps: {value}")
    with pytest.raises(SdnnError) as info:
        _chart(text, "lag.yaml")
    line = info.value.diagnostics[0].one_line()
    assert line.startswith("lag.yaml:4") and "substeps" in line, line


def test_bad_delays_rule_names_file_and_line():
    with pytest.raises(SdnnError) as info:
        _chart(LAG.format(extra="delays: fastest"), "lag.yaml")
    assert info.value.diagnostics[0].one_line().startswith("lag.yaml:4")


def test_cli_substeps_option(tmp_path):
    chart = tmp_path / "lag.yaml"
    chart.write_text(LAG.format(extra=""))
    runner = CliRunner()
    out = runner.invoke(main, ["compile", str(chart), "--substeps", "4", "--explain"])
    assert out.exit_code == 0, out.output
    assert "substeps N = 4" in out.output and "4 steps per sample" in out.output
    bad = runner.invoke(main, ["compile", str(chart), "--substeps", "0"])
    assert bad.exit_code == 2 and "--substeps" in bad.output
    for command in ("simulate", "identify", "diagnose", "batch"):
        assert "--substeps" in runner.invoke(main, [command, "--help"]).output


def test_result_records_the_discretization():
    import flowchart2sdnn as sd

    d = load_diagram(DIAGRAMS / "three_mass.yaml")
    data = excite(load_diagram(DIAGRAMS / "three_mass_plant.yaml"), ExcitationSettings(seconds=0.3, seed=1))
    ds = sd.dataset_from_frame(__import__("pandas").DataFrame(data), time="time", inputs=["M1"],
                               outputs=["w1", "w2", "w3"])
    result = sd.identify(d, ds, max_iter=1)
    n = compile_diagram(d).network.substeps
    doc = __import__("json").loads(result.to_json())
    # the floor: tests/test_floor.py; the bias: tests/test_floorbias.py
    disc = {k: v for k, v in doc["discretization"].items() if k not in ("floor", "bias")}
    assert disc == {"substeps": n, "requested": "auto", "sample_time": 0.001,
                    "step": pytest.approx(0.001 / n), "delays": "torques"}
    assert result.chart.substeps == n  # the identified chart runs on the network it was fitted with


# ------------------------------------------------------------------------------------------------ delays
def test_torques_rule_delays_every_torque_into_a_speed_sum():
    d = load_diagram(DIAGRAMS / "three_mass_plant.yaml")
    delayed = {(u, v) for u, v, _ in analyse_loops(d).delayed_edges}
    assert delayed == {("MC1", "MB1"), ("MD1", "MB1"), ("MR1", "MB1"), ("MC1", "MB2"), ("MD1", "MB2"),
                       ("MC2", "MB2"), ("MD2", "MB2"), ("MR2", "MB2"), ("MC2", "MB3"), ("MD2", "MB3"),
                       ("MR3", "MB3")}
    search = {(u, v) for u, v, _ in analyse_loops(dataclasses.replace(d, delays="search")).delayed_edges}
    assert ("w2", "dw1") in search  # the search alone delays a neighbour's speed instead


def test_torques_rule_keeps_one_delay_per_loop():
    """DC motor: the loop current -> torque -> speed -> back-EMF -> current passes two speed sums; delaying
    both would be explicit Euler on the electromechanical coupling."""
    d = dataclasses.replace(load_diagram(DIAGRAMS / "dc_motor.yaml"), delays="torques")
    report = analyse_loops(d)
    delayed = {(u, v) for u, v, _ in report.delayed_edges}
    for u, v, loop in report.delayed_edges:
        cycle = list(loop) + [loop[0]]
        edges = set(zip(cycle, cycle[1:], strict=False))
        assert len(edges & delayed) == 1, (u, v, loop)


# ------------------------------------------------------------------------------------------------ the floor
@pytest.mark.parametrize("plant", ["two_mass_coulomb_plant", "three_mass_plant"])
def test_floor_with_auto_is_below_a_third_of_sensor_noise(plant):
    """True parameters against the continuous RK4 plant, noise-free: <= 0.003 rad/s RMS on every output."""
    d = load_diagram(DIAGRAMS / f"{plant}.yaml")
    data = excite(d, ExcitationSettings(seconds=4, seed=3, noise_std=0.0))
    u = np.column_stack([data[n] for n in d.input_names])
    y = np.column_stack([data[n] for n in d.output_names])

    def floor(diagram):
        c = CompiledNetwork(compile_diagram(diagram).network)
        return np.sqrt(np.mean((run_aligned(c, c.theta0(), u)[1:] - y[1:]) ** 2, axis=0))

    assert np.all(floor(d) <= 0.003), floor(d)
    before = floor(dataclasses.replace(d, substeps=1, delays="search"))
    assert np.max(before) > 3 * np.max(floor(d))
