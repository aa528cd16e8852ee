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
    hand = diagram_from_text("""
sdnn: 1
name: hand
sample_time: 0.001
inputs: {F: {}}
outputs: {v: {}}
parameters: {m: {init: 2.4}, b: {init: 0.4}}
blocks:
  Fsum: {type: sum, in: [F, -Fv, -ST]}
  acc:  {type: gain, in: Fsum, k: 1/m}
  v:    {type: integrator, in: acc}
  Fv:   {type: gain, in: v, k: b}
  s:    {type: function, f: sign_smooth, in: v, eps: 0.2}
  ST:   {type: gain, in: s, k: 0.3}
""")
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
