"""Chart language for real machines (issue 15): sqrt, abs, exp, square, signed_square, and the product block.

Oracles: central finite differences of the network's own simulation (the RTRL Jacobian), the continuous RK4
simulation of the chart (simulate.continuous shares no code with the compiler), and values written by hand
from the documented definitions.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from flowchart2sdnn.analysis.lint import lint_diagram
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.dump import dump_diagram
from flowchart2sdnn.diagram.units import parse_unit
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.explain import explain_network
from flowchart2sdnn.network.model import Network
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.network.stability import rest_eigenvalues
from flowchart2sdnn.simulate.continuous import simulate_continuous
from tests.test_rtrl import assert_jacobian_matches


def chart(blocks: str, outputs: str = "y: {}", parameters: str = "{}", sample_time: float = 0.01,
          inputs: str = "u: {}") -> str:
    """A chart at the paper's scheme (`substeps: 1`, `delays: search`): the hand values and eigenvalues below
    are those of one step per sample, and the subject is the language, not the discretization."""
    return (f"sdnn: 1\nname: t\nsample_time: {sample_time}\nsubsteps: 1\ndelays: search\n"
            f"inputs: {{{inputs}}}\noutputs: {{{outputs}}}\n"
            f"parameters: {parameters}\nblocks:\n" + "\n".join("  " + line for line in blocks.strip().splitlines())
            + "\n")


def network(text: str) -> CompiledNetwork:
    return CompiledNetwork(compile_diagram(diagram_from_text(text, "t.yaml")).network)


# --------------------------------------------------------------------------------------------- hand values
def hand_sqrt(z, eps):
    z = np.asarray(z, float)
    u = z / eps
    inner = math.sqrt(eps) * (5 * u - u**3) / 4
    return np.where(np.abs(z) >= eps, np.sign(z) * np.sqrt(np.abs(z)), inner)


HAND = {
    "abs": np.abs,
    "exp": np.exp,
    "square": lambda z: z * z,
    "signed_square": lambda z: z * np.abs(z),
}


@pytest.mark.parametrize("f", ["sqrt", "abs", "exp", "square", "signed_square"])
def test_static_function_of_an_input_is_the_documented_function(f):
    """y = f(k u) read straight off the network (direct alignment: row k uses u(k))."""
    eps = 0.04
    u = np.concatenate([np.linspace(-2, 2, 81), [0.0, 0.01, -0.01, 0.02, 0.0199, 0.0201]])[:, None]
    cn = network(chart(f"y: {{type: function, f: {f}, in: u, k: 0.5, eps: {eps}}}"))
    y = run_aligned(cn, cn.theta0(), u, "direct")[:, 0]
    z = 0.5 * u[:, 0]
    want = hand_sqrt(z, eps) if f == "sqrt" else HAND[f](z)
    np.testing.assert_allclose(y, want, rtol=1e-13, atol=1e-15)
    y_c = simulate_continuous(diagram_from_text(chart(f"y: {{type: function, f: {f}, in: u, k: 0.5, eps: {eps}}}")),
                              u)[:, 0]
    np.testing.assert_allclose(y_c, want, rtol=1e-13, atol=1e-15)


def test_sqrt_is_exact_beyond_eps_continuous_at_eps_and_finite_at_zero():
    eps = 1e-3
    z = np.array([eps * (1 - 1e-9), eps, eps * (1 + 1e-9)])
    assert np.ptp(hand_sqrt(z, eps)) < 1e-9  # continuous at eps
    assert hand_sqrt(np.array([4.0]), eps)[0] == 2.0 and hand_sqrt(np.array([-4.0]), eps)[0] == -2.0
    slope = (hand_sqrt(np.array([1e-9]), eps) - hand_sqrt(np.array([-1e-9]), eps))[0] / 2e-9
    assert slope == pytest.approx(1.25 / math.sqrt(eps), rel=1e-6)  # 39.5, finite


def test_product_of_inputs_with_signs_and_k():
    cn = network(chart("y: {type: product, in: [u, -v, u], k: 2*c}", inputs="u: {}, v: {}",
                       parameters="{c: {init: 1.5}}"))
    rng = np.random.default_rng(1)
    u = rng.normal(size=(50, 2))
    y = run_aligned(cn, cn.theta0(), u, "direct")[:, 0]
    np.testing.assert_allclose(y, 3.0 * u[:, 0] * (-u[:, 1]) * u[:, 0], rtol=1e-13)
    # the repeated factor u*u is two factors, not one connection of weight 2 (flat merges sums, never products)
    _, dy = cn.jacobian(cn.theta0(), u)
    np.testing.assert_allclose(run_aligned(cn, cn.theta0(), u, "direct")[:, 0], y)
    assert dy.shape[-1] == 1


# --------------------------------------------------------------------------------------------- RTRL vs FD
TANKS = """
s1: {type: sum, in: [q_in, -q1]}
q_in: {type: gain, in: u, k: k4}
h1: {type: integrator, in: s1, init: 0.3}
r1: {type: function, f: sqrt, in: h1, eps: 0.01}
q1: {type: gain, in: r1, k: k1}
s2: {type: sum, in: [q1, -q2]}
h2: {type: integrator, in: s2, init: 0.2}
r2: {type: function, f: sqrt, in: h2, eps: 0.01}
q2: {type: gain, in: r2, k: k3}
"""
TANK_PARAMS = "{k1: {init: 0.6}, k3: {init: 0.5}, k4: {init: 0.8}}"


def test_rtrl_of_two_tanks_with_sqrt_through_zero_equals_finite_differences():
    """The upper tank is emptied (u < 0 pumps out): its level crosses 0 and the inner cubic of sqrt is used."""
    cn = network(chart(TANKS, "h1: {}, h2: {}", TANK_PARAMS, sample_time=0.05))
    u = np.concatenate([np.full(60, 0.4), np.full(60, -0.3), np.full(80, 0.5)])[:, None]
    sig = cn.signals(cn.theta0(), u)
    h1 = sig["h1"]
    assert h1.min() < 0 and np.min(np.abs(h1)) < 0.01  # below 0 and through (-eps, eps)
    assert_jacobian_matches(cn, cn.theta0(), u)


@pytest.mark.parametrize("f", ["abs", "exp", "square", "signed_square", "sqrt"])
def test_rtrl_of_each_function_in_a_loop_equals_finite_differences(f):
    """A mass whose speed w crosses zero; the function of w feeds back (drag, |w| friction, ...)."""
    blocks = f"""
acc: {{type: sum, in: [u, -fr, -lin]}}
a: {{type: gain, in: acc, k: 1/J}}
w: {{type: integrator, in: a, init: 0.3}}
g: {{type: function, f: {f}, in: w, k: s, eps: 0.01}}
fr: {{type: gain, in: g, k: c}}
lin: {{type: gain, in: w, k: d}}
y: {{type: sum, in: [w, g]}}
"""
    cn = network(chart(blocks, "y: {}", "{J: {init: 0.5}, c: {init: 0.2}, d: {init: 0.8}, s: {init: 0.7}}"))
    t = np.arange(400) * 0.01
    u = (0.8 * np.sin(2 * np.pi * 0.7 * t))[:, None]
    w = cn.signals(cn.theta0(), u)["w"]
    assert w.min() < 0 < w.max()
    if f in ("abs", "sqrt"):  # the chart passes close to the kink (sqrt: into its inner cubic)
        assert np.min(np.abs(0.7 * w)) < 0.01
    assert_jacobian_matches(cn, cn.theta0(), u)


def test_rtrl_exactly_near_the_kink_of_abs():
    """A speed that passes 1e-4 from zero: the sign of the slope flips there and RTRL follows it."""
    blocks = """
w: {type: integrator, in: u, init: -0.05}
g: {type: function, f: abs, in: w}
y: {type: gain, in: g, k: c}
"""
    cn = network(chart(blocks, "y: {}", "{c: {init: 2.0}}", sample_time=0.01))
    u = np.full((20, 1), 1.0)  # w = -0.05 + 0.01 k: 1e-4 off zero is not reachable exactly; shift the start
    cn2 = network(chart(blocks.replace("-0.05", "-0.0501"), "y: {}", "{c: {init: 2.0}}", sample_time=0.01))
    w = cn2.signals(cn2.theta0(), u)["w"]
    assert np.min(np.abs(w)) == pytest.approx(1e-4, rel=1e-6)
    for c in (cn, cn2):
        assert_jacobian_matches(c, c.theta0(), u)


PRODUCT_OF_STATES = """
s1: {type: sum, in: [u, -p, -l1]}
l1: {type: gain, in: x1, k: a}
x1: {type: integrator, in: s1, init: 0.5}
p: {type: product, in: [x1, x2], k: c}
s2: {type: sum, in: [p, -l2]}
l2: {type: gain, in: x2, k: b}
x2: {type: integrator, in: s2, init: 0.4}
"""
PRODUCT_PARAMS = "{a: {init: 0.5}, b: {init: 1.2}, c: {init: 1.5}}"


def test_rtrl_of_a_product_of_two_states_equals_finite_differences():
    cn = network(chart(PRODUCT_OF_STATES, "x1: {}, x2: {}", PRODUCT_PARAMS))
    rng = np.random.default_rng(3)
    u = np.repeat(rng.uniform(-1, 2, 30), 15)[:, None]
    assert_jacobian_matches(cn, cn.theta0(), u)
    assert_jacobian_matches(cn, np.array([0.3, 2.0, -0.7]), u)


def test_product_with_a_delayed_factor_a_constant_and_a_parameter_gain():
    blocks = """
w: {type: integrator, in: e, init: 0.2}
e: {type: sum, in: [u, -y]}
dl: {type: delay, in: w, n: 2}
one: {type: constant, k: m}
gw: {type: gain, in: w, k: g}
y: {type: product, in: [gw, dl, one, -u]}
"""
    cn = network(chart(blocks, "y: {}", "{g: {init: 0.7}, m: {init: 1.3}}"))
    u = np.sin(np.arange(120) * 0.1)[:, None] + 0.3
    assert_jacobian_matches(cn, cn.theta0(), u)


# --------------------------------------------------------------------------------------------- network vs RK4
def _relative_rms(text: str, u: np.ndarray, substeps: int = 20) -> float:
    diagram = diagram_from_text(text)
    cn = CompiledNetwork(compile_diagram(diagram).network)
    y_d = run_aligned(cn, cn.theta0(), u, "zoh")
    y_c = simulate_continuous(diagram, u, substeps=substeps)
    assert np.all(np.isfinite(y_d)) and np.linalg.norm(y_c) > 0
    return float(np.linalg.norm(y_d - y_c) / np.linalg.norm(y_c))


def test_two_tanks_with_sqrt_agree_with_the_continuous_chart():
    """Torricelli's two tanks (levels a few units, time constants of seconds) at T = 20 ms: within 2 %."""
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(0.2, 1.5, 40), 50)[:, None]
    assert _relative_rms(chart(TANKS, "h1: {}, h2: {}", TANK_PARAMS, sample_time=0.02), u) <= 0.02


def test_two_tanks_error_halves_with_the_sample_time():
    rng = np.random.default_rng(1)
    levels = rng.uniform(0.2, 1.5, 40)
    e1 = _relative_rms(chart(TANKS, "h1: {}, h2: {}", TANK_PARAMS, sample_time=0.04), np.repeat(levels, 25)[:, None])
    e2 = _relative_rms(chart(TANKS, "h1: {}, h2: {}", TANK_PARAMS, sample_time=0.02), np.repeat(levels, 50)[:, None])
    assert 1.6 < e1 / e2 < 2.4  # first order, as every other chart


def test_product_of_two_states_agrees_with_the_continuous_chart():
    rng = np.random.default_rng(2)
    u = np.repeat(rng.uniform(-1, 2, 40), 50)[:, None]
    assert _relative_rms(chart(PRODUCT_OF_STATES, "x1: {}, x2: {}", PRODUCT_PARAMS, sample_time=0.005), u) <= 0.02


def test_rest_eigenvalues_of_a_product_with_one_signal_factor_are_those_of_the_same_gain():
    """At rest a product x1 * one * c is the gain 2c on x1: stability.rest_eigenvalues must see the same
    nonzero eigenvalues as for the chart written with that gain (the product rule at the rest point)."""
    product = PRODUCT_OF_STATES.replace("in: [x1, x2], k: c", "in: [x1, one], k: c") + "one: {type: constant, k: 2}\n"
    gain = PRODUCT_OF_STATES.replace("type: product, in: [x1, x2], k: c", "type: gain, in: x1, k: 2*c")
    eig = []
    for blocks in (product, gain):
        net = compile_diagram(diagram_from_text(chart(blocks, "x1: {}, x2: {}", PRODUCT_PARAMS))).network
        e = rest_eigenvalues(net, net.weight_values())
        eig.append(np.sort_complex(e[np.abs(e) > 1e-12]))
    assert len(eig[0]) == 2
    np.testing.assert_allclose(eig[0], eig[1], rtol=1e-12)
    # and a product of two states has no linear part at rest: each state decays on its own (hand values)
    net = compile_diagram(diagram_from_text(chart(PRODUCT_OF_STATES, "x1: {}, x2: {}", PRODUCT_PARAMS))).network
    e = rest_eigenvalues(net, net.weight_values())
    # (the loops through l1 and l2 carry the feedback delay: explicit Euler, 1 - T a and 1 - T b)
    np.testing.assert_allclose(np.sort(np.abs(e[np.abs(e) > 1e-12])), [1 - 0.01 * 1.2, 1 - 0.01 * 0.5], rtol=1e-12)


# --------------------------------------------------------------------------------------------- units and lint
def _codes(text: str) -> list[str]:
    return [d.code for d in lint_diagram(diagram_from_text(text))]


def test_units_of_sqrt_abs_square_and_product():
    text = chart("""
r: {type: function, f: sqrt, in: u, unit: V^0.5}
a: {type: function, f: abs, in: u, unit: V}
s: {type: function, f: square, in: u, unit: V^2}
ss: {type: function, f: signed_square, in: u, unit: V^2}
p: {type: product, in: [u, r], k: c, unit: A*V^(3/2)}
y: {type: sum, in: [p, q]}
q: {type: product, in: [a, r], k: c}
""", "y: {unit: A*V^(3/2)}", "{c: {init: 1, unit: A}}", inputs="u: {unit: V}")
    assert _codes(text) == ["LINT002", "LINT002"]  # s and ss are unused; every unit adds up
    cubed = text.replace("in: [a, r], k: c}", "in: [a, ss], k: c}")  # A*V^3 added to A*V^(3/2)
    assert [d.block for d in lint_diagram(diagram_from_text(cubed)) if d.code == "LINT005"] == ["y"]
    bad = text.replace("unit: V^0.5}", "unit: V}")
    diags = [d for d in lint_diagram(diagram_from_text(bad)) if d.code == "LINT005"]
    assert diags and diags[0].block == "r"
    assert parse_unit("V^0.5") * parse_unit("V^(1/2)") == parse_unit("V")


def test_product_units_multiply_and_a_wrong_declaration_is_named():
    text = chart("y: {type: product, in: [u, v], unit: N*m}", "y: {}", inputs="u: {unit: N}, v: {unit: m/s}")
    diags = [d for d in lint_diagram(diagram_from_text(text)) if d.code == "LINT005"]
    assert len(diags) == 1 and diags[0].block == "y" and "kg*m^2*s^-3" in diags[0].message  # N*m/s = W
    assert "LINT005" not in _codes(text.replace("unit: N*m}", "unit: W}"))


def test_exp_needs_a_dimensionless_argument():
    text = chart("y: {type: function, f: exp, in: u}", inputs="u: {unit: V}")
    assert "LINT009" in _codes(text)
    assert "LINT009" not in _codes(chart("y: {type: function, f: exp, in: u}", inputs="u: {unit: 1}"))


def test_lint_warns_where_a_sqrt_argument_can_be_known_negative():
    assert "LINT012" in _codes(chart("d: {type: sum, in: [u, -v]}\ny: {type: function, f: sqrt, in: d}",
                                     inputs="u: {}, v: {}"))
    assert "LINT012" in _codes(chart("y: {type: function, f: sqrt, in: u, k: -2}"))
    assert "LINT012" in _codes(chart("x: {type: integrator, in: u, init: -1}\ny: {type: function, f: sqrt, in: x}"))
    assert "LINT012" not in _codes(chart("x: {type: integrator, in: u, init: 1}\ny: {type: function, f: sqrt, in: x}"))


def test_a_product_is_direct_feedthrough_for_algebraic_loops():
    text = chart("y: {type: product, in: [u, z]}\nz: {type: sum, in: [y, u]}")
    diags = [d for d in lint_diagram(diagram_from_text(text)) if d.code == "LINT001"]
    assert diags and "algebraic loop" in diags[0].message


# --------------------------------------------------------------------------------------------- bad charts
@pytest.mark.parametrize("block, fragment", [
    ("y: {type: product, in: [u]}", "at least two signals"),
    ("y: {type: product, in: [u, v], n: 2}", "unknown key 'n'"),
    ("y: {type: function, f: sqr, in: u}", "'f' must be one of"),
    ("y: {type: function, f: sqrt, in: u, eps: 0}", "'eps' must be positive"),
])
def test_bad_new_blocks_are_one_line_errors_with_file_and_line(block, fragment):
    with pytest.raises(SdnnError) as info:
        diagram_from_text(chart(block, inputs="u: {}, v: {}"), "bad.yaml")
    text = str(info.value)
    assert fragment in text and "bad.yaml:" in text
    # the block's line in chart(): sdnn, name, sample_time, substeps, delays, inputs, outputs, parameters, blocks
    assert info.value.diagnostics[0].location.line == 10


def test_a_learned_curve_as_a_factor_is_refused_with_a_fix():
    text = chart("c: {type: nonlinear, in: u, neurons: 2}\ny: {type: product, in: [u, c]}")
    with pytest.raises(SdnnError) as info:
        compile_diagram(diagram_from_text(text, "bad.yaml"))
    assert "COMPILE005" in str(info.value) and "sum block" in str(info.value)


def test_sqrt_of_a_negative_input_is_never_nan():
    cn = network(chart("y: {type: function, f: sqrt, in: u}"))
    u = np.linspace(-5, 5, 101)[:, None]
    y, dy = cn.jacobian(cn.theta0(), u)
    assert np.all(np.isfinite(y)) and np.all(np.isfinite(dy))
    assert np.all(np.isfinite(simulate_continuous(diagram_from_text(chart("y: {type: function, f: sqrt, in: u}")),
                                                  u)))


# --------------------------------------------------------------------------------------------- round trips
def test_new_blocks_survive_dump_and_network_file_and_explain():
    text = chart(TANKS + "pp: {type: product, in: [h1, -h2], k: k1}\nab: {type: function, f: abs, in: pp}\n",
                 "h1: {}, h2: {}, ab: {}", TANK_PARAMS)
    diagram = diagram_from_text(text)
    again = diagram_from_text(dump_diagram(diagram))
    assert [replace(b, location=None) for b in again.blocks] == [replace(b, location=None) for b in diagram.blocks]
    net = compile_diagram(diagram).network
    back = Network.from_json(net.to_json())
    u = np.linspace(0, 1, 50)[:, None]
    np.testing.assert_array_equal(CompiledNetwork(back).simulate(back.parameter_values() and
                                                                 CompiledNetwork(back).theta0(), u),
                                  CompiledNetwork(net).simulate(CompiledNetwork(net).theta0(), u))
    text_out = explain_network(net)
    assert "netprod" in text_out and "sqrt" in text_out and "abs" in text_out
    plain = compile_diagram(diagram_from_text(chart("y: {type: sum, in: [u]}"))).network
    assert "net_input" not in plain.to_json()  # files of charts without products are unchanged


def test_identify_says_when_a_sqrt_argument_went_negative_and_never_returns_nan():
    import pandas as pd

    import flowchart2sdnn as sd

    text = chart("r: {type: function, f: sqrt, in: u}\ny: {type: gain, in: r, k: c}", "y: {}", "{c: {init: 1}}")
    t = np.arange(300) * 0.01
    u = np.sin(2 * np.pi * t)  # goes negative on half the record
    y = 2.0 * np.sign(u) * np.sqrt(np.abs(u))
    frame = pd.DataFrame({"t": t, "u": u, "y": np.concatenate([[0.0], y[:-1]])})  # zoh: row k sees u(k-1)
    data = sd.dataset_from_frame(frame, time="t", inputs=["u"], outputs=["y"])
    result = sd.identify(diagram_from_text(text), data, max_iter=50)
    assert result.parameters["c"].value == pytest.approx(2.0, rel=1e-3)
    assert all(math.isfinite(v) for v in result.fit.train.rms.values())
    (warning,) = [n for n in result.notices if n.code == "SQRT001" and n.numbers["block"] == "r"]
    # the network sees u(0) .. u(Q-2) on the Q-1 fitted rows (zoh)
    negative = int(np.sum(u[:-1] < 0))
    assert warning.numbers["negative"] == negative and warning.numbers["samples"] == 299
    assert f"negative on {negative} of 299 samples" in warning.message and "-sqrt(-z)" in warning.message


def test_cli_lint_explain_and_excite_know_the_new_blocks(tmp_path):
    from click.testing import CliRunner

    from flowchart2sdnn.cli import main

    path = tmp_path / "tanks.yaml"
    path.write_text(chart(TANKS + "p: {type: product, in: [h1, h2], k: k1}\nab: {type: function, f: abs, in: p}\n",
                          "h2: {}, ab: {}", TANK_PARAMS, sample_time=0.05))
    runner = CliRunner()
    lint = runner.invoke(main, ["lint", str(path)])
    assert lint.exit_code == 0 and "0 error(s)" in lint.output
    explain = runner.invoke(main, ["compile", str(path), "--explain"])
    assert explain.exit_code == 0 and "netprod" in explain.output and " sqrt" in explain.output
    out = tmp_path / "bench.csv"
    excite = runner.invoke(main, ["excite", str(path), "--seconds", "5", "--seed", "1", "-o", str(out)])
    assert excite.exit_code == 0, excite.output
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert np.all(np.isfinite(data["h2"])) and np.all(np.isfinite(data["ab"]))
    diagram = diagram_from_text(path.read_text())
    y = simulate_continuous(diagram, data["u"][:, None], parameters=None)
    np.testing.assert_allclose(y[:, 1], np.abs(0.6 * y[:, 0] * simulate_continuous(diagram, data["u"][:, None],
                                                                                   signals=True)["h1"]), rtol=1e-12)
