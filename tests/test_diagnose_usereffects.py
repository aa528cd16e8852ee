"""Effects written in YAML (--effects-file): loading, placeholders, patching, and every mistake at its line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_bench import DATA, aprbs_input, chart, simulate

from flowchart2sdnn.diagnose.graph import Place, speeds
from flowchart2sdnn.diagnose.usereffects import load_effects_file
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError

ONE = chart("one_mass")


def _set(diagram, name, value):
    return dataclasses.replace(diagram, parameters=tuple(
        dataclasses.replace(p, init=value) if p.name == name else p for p in diagram.parameters))


def _hand(term: str, blocks: str):
    """The one-mass chart written by hand with one more torque `term` against the motion and its `blocks` (at the
    paper's scheme, as tests/data/diagnose/one_mass.yaml pins it)."""
    return diagram_from_text(f"""
sdnn: 1
name: hand
sample_time: 0.001
substeps: 1
delays: search
inputs: {{F: {{}}}}
outputs: {{v: {{}}}}
parameters: {{m: {{init: 2.4}}, b: {{init: 0.4}}}}
blocks:
  Fsum: {{type: sum, in: [F, -Fv, -{term}]}}
  acc:  {{type: gain, in: Fsum, k: 1/m}}
  v:    {{type: integrator, in: acc}}
  Fv:   {{type: gain, in: v, k: b}}
""" + blocks)


@pytest.fixture(scope="module")
def effects():
    return load_effects_file(DATA / "user_effects.yaml")


def test_the_file_loads_with_attach_kinds_and_options(effects):
    assert set(effects) == {"stiction", "gain_error"}
    s = effects["stiction"]
    assert s.attach == "speed" and s.options(ONE, None, None) == (0.05, 0.2) and s.extra_dof == 1
    assert [p.at for p in s.places(ONE)] == ["v"]
    assert effects["gain_error"].options(ONE, None, None) == (None,)


def test_a_speed_effect_is_neutral_and_with_a_value_equals_a_hand_written_chart(effects):
    (place,) = speeds(ONE)
    patched = effects["stiction"].patch(ONE, place, 0.2)
    assert ONE.block("Fsum").inputs == chart("one_mass").block("Fsum").inputs  # input chart untouched
    u = aprbs_input(2000, seed=1, amplitude=3.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(ONE, u), atol=1e-12)
    hand = _hand("ST", "  s:    {type: function, f: sign_smooth, in: v, eps: 0.2}\n"
                       "  ST:   {type: gain, in: s, k: 0.3}\n")
    np.testing.assert_allclose(simulate(_set(patched, "stiction_v_F", 0.3), u), simulate(hand, u), atol=1e-12)


def test_an_input_effect_reroutes_the_consumers(effects):
    patched = effects["gain_error"].patch(ONE, Place("F", "input"), None)
    assert patched.block("Fsum").inputs[0].signal == "gain_error_F"
    u = aprbs_input(2000, seed=2, amplitude=3.0)
    np.testing.assert_allclose(simulate(_set(patched, "gain_error_F_g", 0.1), u), simulate(ONE, 1.1 * u),
                               rtol=1e-12, atol=1e-12)


def _write(tmp_path, text):
    p = tmp_path / "fx.yaml"
    p.write_text(text)
    return p


BASE = """sdnn_effects: 1
effects:
  bad:
    attach: speed
    blocks:
      "{name}": {type: gain, in: "{at}", k: 2}
    output: "{name}"
"""


@pytest.mark.parametrize("change,message,line", [
    (("attach: speed", "attach: sped"), "'attach' must be one of", 4),
    (('output: "{name}"', 'output: "{name}_x"'), "output 'bad_v_x' is not one of its blocks", None),
    (("    attach: speed\n", "    attach: speed\n    colour: red\n"), "unknown key(s) colour", 5),
    (("sdnn_effects: 1", "sdnn_effects: 2"), "sdnn_effects: 1", 1),
    (('k: 2}', 'k: nope}'), "unknown name 'nope'", 5),
])
def test_mistakes_are_reported_at_their_line(tmp_path, change, message, line):
    path = _write(tmp_path, BASE.replace(*change))
    with pytest.raises(SdnnError) as err:
        effect = load_effects_file(path)["bad"]
        (place,) = speeds(ONE)
        effect.patch(ONE, place, None)
    d = err.value.diagnostics[0]
    assert message in d.message and d.location.file == str(path)
    if line is not None:
        assert d.location.line == line


def test_a_fragment_may_not_redefine_a_chart_signal(tmp_path):
    path = _write(tmp_path, BASE.replace('"{name}": {type: gain', '"Fv": {type: gain').replace(
        'output: "{name}"', 'output: "Fv"'))
    (place,) = speeds(ONE)
    with pytest.raises(SdnnError, match="adds Fv, which the chart already has"):
        load_effects_file(path)["bad"].patch(ONE, place, None)


def test_user_effects_may_use_the_new_functions_and_the_product_block(tmp_path):
    """A quadratic drag c*w*|w| (signed_square) and a load-dependent friction mu*F*w (a product block) written
    as user effects: each patched chart equals the same chart written by hand (the hand chart is the oracle)."""
    path = tmp_path / "fx.yaml"
    path.write_text("""sdnn_effects: 1
effects:
  drag:
    attach: speed
    parameters: {"{name}_c": {init: 0}}
    blocks:
      "{name}_q": {type: function, f: signed_square, in: "{at}"}
      "{name}": {type: gain, in: "{name}_q", k: "{name}_c"}
    output: "{name}"
  loaded:
    attach: speed
    parameters: {"{name}_mu": {init: 0}}
    blocks:
      "{name}": {type: product, in: ["{at}", F], k: "{name}_mu"}
    output: "{name}"
""")
    fx = load_effects_file(path)
    (place,) = speeds(ONE)
    u = aprbs_input(2000, seed=2, amplitude=3.0)
    drag = _set(fx["drag"].patch(ONE, place, None), "drag_v_c", 0.05)
    loaded = _set(fx["loaded"].patch(ONE, place, None), "loaded_v_mu", 0.02)
    hand_drag = _hand("X", "  q: {type: function, f: signed_square, in: v}\n  X: {type: gain, in: q, k: 0.05}\n")
    hand_loaded = _hand("X", "  X: {type: product, in: [v, F], k: 0.02}\n")
    np.testing.assert_allclose(simulate(drag, u), simulate(hand_drag, u), atol=1e-12)
    np.testing.assert_allclose(simulate(loaded, u), simulate(hand_loaded, u), atol=1e-12)
    assert not np.allclose(simulate(drag, u), simulate(ONE, u))  # the effect acts


# ------------------------------------------------------------------------------------------------ positions, signals
SPRING = """
sdnn: 1
name: spring
sample_time: 0.01
inputs: {u: {}}
outputs: {x: {}}
parameters: {m: {init: 1.0, fixed: true}, k: {init: 150}, d: {init: 1.2}}
blocks:
  F:  {type: sum, in: [u, -Fk, -Fd]}
  a:  {type: gain, in: F, k: 1/m}
  v:  {type: integrator, in: a}
  x:  {type: integrator, in: v}
  Fk: {type: gain, in: x, k: k}
  Fd: {type: gain, in: v, k: d}
"""
CUBIC = """
  cubic:
    attach: {attach}
    parameters: {{"{{name}}_k3": {{init: 0}}}}
    blocks:
      "{{name}}": {{type: product, in: ["{{at}}", "{{at}}", "{{at}}"], k: "{{name}}_k3"}}
    output: "{{name}}"
"""


def _effects(tmp_path, body: str):
    return load_effects_file(_write(tmp_path, "sdnn_effects: 1\neffects:" + body))


@pytest.mark.parametrize("attach", ["position", "position\n    at: x", "null\n    at: x"])
def test_an_effect_at_a_position_is_a_force_against_it(tmp_path, attach):
    # the user effect: a cubic spring k3 x^3; oracle: the chart with the cubic written by hand
    chart = diagram_from_text(SPRING)
    effect = _effects(tmp_path, CUBIC.format(attach=attach))["cubic"]
    (place,) = effect.places(chart)
    assert (place.at, place.kind) == ("x", "position")
    patched = effect.patch(chart, place, None)
    u = aprbs_input(1500, seed=3, amplitude=100.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(chart, u), atol=1e-12)  # neutral
    hand = diagram_from_text(SPRING.replace("-Fd]", "-Fd, -C]") + "  C: {type: product, in: [x, x, x], k: 40}\n")
    np.testing.assert_allclose(simulate(_set(patched, "cubic_x_k3", 40.0), u), simulate(hand, u), rtol=1e-10,
                               atol=1e-10)


def test_an_effect_at_a_named_signal_reroutes_its_readers(tmp_path):
    # a spring force 10 % off: every reader of Fk reads Fk (1 + g); oracle: the chart with k scaled by hand
    effect = _effects(tmp_path, """
  force_error:
    attach: signal
    at: Fk
    parameters: {"{name}_g": {init: 0}}
    blocks:
      "{name}_d": {type: gain, in: "{at}", k: "{name}_g"}
      "{name}":   {type: sum, in: ["{at}", "{name}_d"]}
    output: "{name}"
""")["force_error"]
    chart = diagram_from_text(SPRING)
    (place,) = effect.places(chart)
    patched = _set(effect.patch(chart, place, None), "force_error_Fk_g", 0.1)
    u = aprbs_input(1500, seed=4, amplitude=100.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(_set(chart, "k", 165.0), u), rtol=1e-9, atol=1e-10)


def test_an_effect_at_a_state_leaks_from_its_integrand(tmp_path):
    # x' = v - r x: oracle, the leak written by hand
    effect = _effects(tmp_path, """
  leak:
    attach: state
    at: x
    parameters: {"{name}_r": {init: 0}}
    blocks:
      "{name}": {type: gain, in: "{at}", k: "{name}_r"}
    output: "{name}"
""")["leak"]
    chart = diagram_from_text(SPRING)
    patched = _set(effect.patch(chart, effect.places(chart)[0], None), "leak_x_r", 2.0)
    hand = diagram_from_text(SPRING.replace("x:  {type: integrator, in: v}", "x:  {type: integrator, in: xi}")
                             + "  L: {type: gain, in: x, k: 2}\n  xi: {type: sum, in: [v, -L]}\n")
    u = aprbs_input(1500, seed=5, amplitude=100.0)
    np.testing.assert_allclose(simulate(patched, u), simulate(hand, u), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("attach,message", [
    ("position\n    at: v", "at: 'v' is no position of the chart (its positions: x)"),
    ("null\n    at: q", "at: 'q' is no signal of the chart"),
])
def test_an_at_the_chart_lacks_is_reported_at_its_line(tmp_path, attach, message):
    effect = _effects(tmp_path, CUBIC.format(attach=attach))["cubic"]
    with pytest.raises(SdnnError) as err:
        effect.places(diagram_from_text(SPRING))
    d = err.value.diagnostics[0]
    assert message in d.message and d.location.line == 5  # the line of `at:`


def test_attach_signal_needs_an_at(tmp_path):
    with pytest.raises(SdnnError, match="'attach: signal' needs 'at: <signal>'"):
        _effects(tmp_path, CUBIC.format(attach="signal"))


def test_the_cli_reports_an_at_the_chart_lacks_before_any_fit(tmp_path):
    from click.testing import CliRunner

    from flowchart2sdnn.cli import main

    (tmp_path / "c.yaml").write_text(SPRING)
    (tmp_path / "d.csv").write_text("time,u,x\n" + "".join(f"{i * 0.01:.2f},0,0\n" for i in range(20)))
    fx = _write(tmp_path, "sdnn_effects: 1\neffects:" + CUBIC.format(attach="null\n    at: q"))
    res = CliRunner().invoke(main, ["diagnose", str(tmp_path / "c.yaml"), str(tmp_path / "d.csv"),
                                    "--effects-file", str(fx), "--quiet"])
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert f"{fx}:5" in res.output and "at: 'q' is no signal of the chart" in res.output
    assert len(res.output.strip().splitlines()) <= 2  # the error and at most its hint
