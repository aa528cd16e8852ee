"""The block registry is the one place a block kind is defined (diagram.blocks).

A toy kind registered at run time, ``square`` (y = k x^2, lowered onto a product of its input with itself),
must validate, get its unit from its rule, draw with its label, write back to YAML, compile, and agree with
the continuous oracle and with values by hand, with no other file knowing it. Oracles: k u^2 by hand; the
RK4 simulation of the chart (simulate.continuous shares no code with the compiler); the slope 2 k x by hand.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.analysis.drawing import chart_svg
from flowchart2sdnn.analysis.linearize import linearize
from flowchart2sdnn.analysis.lint import lint_diagram
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.blocks import (
    CORE_KINDS,
    BlockType,
    block_type,
    block_types,
    register_block_type,
    registered,
    unregister_block_type,
)
from flowchart2sdnn.diagram.dump import dump_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous


def _square_unit(b, ins, k, complain):
    if ins[0] is None:
        return None
    ku = k()
    return None if ku is None else ku * ins[0] * ins[0]


SQUARE = BlockType(
    "square", "k x^2", ("in", "k"), "one", label=lambda b: "x²" + (f" (k = {b.k})" if b.k is not None else ""),
    k="optional", unit=_square_unit,
    lower=lambda b: replace(b, kind="product", inputs=(b.inputs[0], b.inputs[0])),
)


@pytest.fixture
def square():
    with registered(SQUARE) as bt:
        yield bt
    assert "square" not in block_types()


def chart(blocks: str, outputs: str = "y: {}", parameters: str = "{}", inputs: str = "u: {}",
          sample_time: float = 0.01) -> str:
    return (f"sdnn: 1\nname: t\nsample_time: {sample_time}\nsubsteps: 1\ndelays: search\n"
            f"inputs: {{{inputs}}}\noutputs: {{{outputs}}}\nparameters: {parameters}\nblocks:\n"
            + "\n".join("  " + line for line in blocks.strip().splitlines()) + "\n")


def _messages(text: str) -> str:
    with pytest.raises(SdnnError) as err:
        diagram_from_text(text)
    return str(err.value)


def test_the_core_kinds_are_registered_and_protected():
    assert tuple(block_types())[: len(CORE_KINDS)] == CORE_KINDS
    with pytest.raises(ValueError, match="already registered"):
        register_block_type(block_type("gain"))
    with pytest.raises(ValueError, match="core block type"):
        unregister_block_type("sum")
    with pytest.raises(ValueError, match="needs `lower`"):
        register_block_type(BlockType("toy_cube", "x^3", ("in",)))
    with pytest.raises(ValueError, match="keys must name k"):
        BlockType("toy_cube", "k x^3", ("in",), k="required")
    with pytest.raises(ValueError, match="no core kind takes power"):
        register_block_type(BlockType("toy_cube", "x^p", ("in", "power"), lower=lambda b: b))
    with pytest.raises(ValueError, match="cuts no edge"):
        register_block_type(BlockType("toy_cube", "x^3", ("in",), cut="in", lower=lambda b: b))
    assert "toy_cube" not in block_types()


def test_a_registered_kind_reads_the_keys_it_names():
    """`eps` is read (and checked, and written back) for any kind that names it, not only for `function`."""
    soft = BlockType("soft_sign", "tanh(k x / eps)", ("in", "k", "eps"), k="optional",
                     lower=lambda b: replace(b, kind="function", f="sign_smooth"))
    with registered(soft):
        diagram = diagram_from_text(chart("y: {type: soft_sign, in: u, eps: 0.5}"))
        assert diagram.block("y").eps == 0.5
        assert "'eps' must be positive" in _messages(chart("y: {type: soft_sign, in: u, eps: -1}"))
        assert diagram_from_text(dump_diagram(diagram)).block("y").eps == 0.5
        u = np.linspace(-1, 1, 11)[:, None]
        np.testing.assert_allclose(simulate_continuous(diagram, u)[:, 0], np.tanh(u[:, 0] / 0.5), rtol=1e-13)


def test_a_registered_kind_validates_and_is_unknown_before_and_after(square):
    text = chart("y: {type: square, in: -u, k: 2}")
    assert diagram_from_text(text).block("y").kind == "square"
    assert "unknown key 'n'" in _messages(chart("y: {type: square, in: u, n: 2}"))
    assert "missing 'in'" in _messages(chart("y: {type: square, k: 2}"))
    assert "'in' must be one signal" in _messages(chart("y: {type: square, in: [u, u]}"))
    unregister_block_type("square")
    try:
        assert "unknown block type 'square'" in _messages(text)
    finally:
        register_block_type(SQUARE)


def test_a_registered_kind_gets_its_unit_from_its_rule(square):
    params = "{c: {init: 2, unit: N/m^2}}"
    ok = diagram_from_text(chart("y: {type: square, in: u, k: c}", "y: {unit: N}", params, "u: {unit: m}"))
    assert not [d for d in lint_diagram(ok) if d.code == "LINT005"]
    bad = diagram_from_text(chart("y: {type: square, in: u, k: c}", "y: {unit: N*m}", params, "u: {unit: m}"))
    (d,) = [d for d in lint_diagram(bad) if d.code == "LINT005"]
    assert d.block == "y" and "unit mismatch" in d.message


def test_a_registered_kind_draws_and_writes_back(square):
    diagram = diagram_from_text(chart("y: {type: square, in: -u, k: 2}"))
    assert "x² (k = 2)" in chart_svg(diagram)
    again = diagram_from_text(dump_diagram(diagram))
    assert [replace(b, location=None) for b in again.blocks] == [replace(b, location=None) for b in diagram.blocks]


def test_a_registered_kind_compiles_to_the_hand_values_and_the_oracle(square):
    diagram = diagram_from_text(chart("y: {type: square, in: -u, k: c}", parameters="{c: {init: 0.5}}"))
    u = np.linspace(-2, 2, 41)[:, None]
    want = 0.5 * u[:, 0] ** 2
    cn = CompiledNetwork(compile_diagram(diagram).network)
    np.testing.assert_allclose(run_aligned(cn, cn.theta0(), u, "direct")[:, 0], want, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(simulate_continuous(diagram, u)[:, 0], want, rtol=1e-13, atol=1e-15)


def test_a_registered_kind_in_a_loop_agrees_with_the_continuous_chart(square):
    """dx/dt = u - c x^2 (a quadratic drag): the network against RK4 within 2 %, and the slope -2 c x."""
    blocks = "e: {type: sum, in: [u, -d]}\nd: {type: square, in: x, k: c}\nx: {type: integrator, in: e, init: 0.2}"
    diagram = diagram_from_text(chart(blocks, "x: {}", "{c: {init: 1.5}}", sample_time=0.005))
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(0.2, 2.0, 40), 50)[:, None]
    cn = CompiledNetwork(compile_diagram(diagram).network)
    y_d = run_aligned(cn, cn.theta0(), u, "zoh")
    y_c = simulate_continuous(diagram, u, substeps=20)
    assert np.linalg.norm(y_d - y_c) / np.linalg.norm(y_c) <= 0.02
    model = linearize(diagram, {"x": 0.4})
    assert model.A[0, 0] == pytest.approx(-2 * 1.5 * 0.4, rel=1e-12)


def test_a_registered_kind_may_not_lower_onto_a_state(square):
    """Loop analysis reads the chart as written: a kind lowered onto an integrator would be a false algebraic
    loop there, so lowering is to the kinds without a state only."""
    angle = BlockType("angle", "integral of x", ("in",), lower=lambda b: replace(b, kind="integrator", init=0.0))
    with registered(angle):
        diagram = diagram_from_text(chart("y: {type: angle, in: u}"))
        with pytest.raises(ValueError, match="one of sum, gain, constant, function, product"):
            compile_diagram(diagram)


def test_every_shipped_kind_has_a_row_in_the_chart_format_guide():
    from flowchart2sdnn.diagram.blocks import BLOCK_KINDS

    text = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "chart-format.md").read_text(encoding="utf-8")
    assert [k for k in BLOCK_KINDS if f"| `{k}` |" not in text] == []
