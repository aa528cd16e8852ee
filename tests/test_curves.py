"""Learned curves (diagram.curves): the tanh basis's fixed slopes, its linear term, what lint says of a curve,
and the chart keys that choose them. Oracles: the slopes written out by hand, the chart's own structure."""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.analysis.lint import curve_notes
from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.curves import BASIS_FUNCTIONS, basis_gains, has_linear_term, weight_names
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError

CHART = """\
sdnn: 1
name: one_mass
sample_time: 0.001
inputs:
  M: {unit: N*m}
outputs:
  w: {unit: rad/s}
parameters:
  J: {init: 0.2, unit: kg*m^2, min: 0}
  b: {init: 0.02, unit: N*m*s/rad, min: 0}
blocks:
  MB:  {type: sum, in: [M, -MR], unit: N*m}
  acc: {type: gain, in: MB, k: 1/J}
  w:   {type: integrator, in: acc, unit: rad/s}
  F:   {type: nonlinear, in: w CURVE}
  MR:  {type: sum, in: [F SUMMED], unit: N*m}
"""


def _chart(curve: str = "", viscous: bool = False):
    text = CHART.replace(" CURVE", curve).replace(" SUMMED", ", Fv" if viscous else "")
    if viscous:
        text += "  Fv:  {type: gain, in: w, k: b, unit: N*m}\n"
    return diagram_from_text(text, "one_mass.yaml")


def test_the_slopes_are_log_spaced_over_three_decades_at_two_a_decade():
    assert BASIS_FUNCTIONS == 7
    np.testing.assert_allclose(basis_gains(7), [1, 10**0.5, 10, 10**1.5, 100, 10**2.5, 1000], rtol=1e-12)
    net = compile_diagram(_chart(", span: 2.0")).network
    slopes = sorted(f.init for f in net.free_weights if f.role == "a")
    np.testing.assert_allclose(slopes, np.array([1, 10**0.5, 10, 10**1.5, 100, 10**2.5, 1000]) / 2.0, rtol=1e-12)
    assert all(f.fixed for f in net.free_weights if f.role == "a")
    assert all(not f.fixed and f.init == 0.0 for f in net.free_weights if f.role in ("v", "c"))


def test_the_linear_term_is_left_out_where_a_gain_of_the_same_input_sits_in_the_same_sum():
    alone, beside = _chart(), _chart(viscous=True)
    assert has_linear_term(alone, alone.block("F")) and not has_linear_term(beside, beside.block("F"))
    assert "F.c" in weight_names(alone, alone.block("F")) and "F.c" not in weight_names(beside, beside.block("F"))
    forced = _chart(", linear: true", viscous=True)
    assert has_linear_term(forced, forced.block("F"))
    assert not has_linear_term(_chart(", linear: false"), _chart(", linear: false").block("F"))


def test_the_papers_neurons_keep_free_slopes_and_no_linear_term():
    d = _chart(", basis: neurons, neurons: 3")
    assert d.block("F").neurons == 3 and not has_linear_term(d, d.block("F"))
    assert weight_names(d, d.block("F")) == ["F.a1", "F.v1", "F.a2", "F.v2", "F.a3", "F.v3"]
    net = compile_diagram(d).network
    assert not any(f.fixed for f in net.free_weights)


@pytest.mark.parametrize("curve, words", [
    (", basis: spline", "'basis' must be one of tanh, neurons"),
    (", span: -1", "'span' must be a positive number"),
    (", basis: neurons, linear: true", "'linear: true' needs the tanh basis"),
    (", weights: {a: [1, 2], v: [0, 0], c: .nan}", "weights 'c' (the linear term) must be a number"),
])
def test_bad_curve_keys_are_one_line_errors_naming_the_block(curve, words):
    with pytest.raises(SdnnError, match=re.escape(words)) as info:
        _chart(curve)
    assert "one_mass.yaml:" in str(info.value)


def test_lint_says_what_each_curve_can_represent(tmp_path):
    notes = curve_notes(_chart())
    assert [n.code for n in notes] == ["LINT013"] and notes[0].severity == "info"
    assert "odd" in notes[0].message and "linear term" in notes[0].message
    assert "+-2" in curve_notes(_chart(", span: 2"))[0].message
    assert "free-slope" in curve_notes(_chart(", basis: neurons"))[0].message
    path = tmp_path / "c.yaml"
    path.write_text(CHART.replace(" CURVE", "").replace(" SUMMED", ""))
    res = CliRunner().invoke(main, ["lint", str(path)])
    # the info line is not a warning: the count names b, which this chart leaves unused
    assert res.exit_code == 0 and "info[LINT013] block 'F'" in res.output and "0 error(s), 1 warning(s)" in res.output
