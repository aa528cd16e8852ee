"""Loading, validating and linting charts: the examples, the YAML corner cases, and the malformed charts.

The malformed charts in tests/data/bad_charts/ each carry one mistake; the table below says which error code
it must raise, which block it must name and a marker text on the line it must point at (so a message that
names the wrong line fails). The CLI side (one line on stderr, exit 1, no file) is tests/test_cli_charts.py.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.analysis.lint import lint_diagram
from flowchart2sdnn.compiler import compile_diagram, compile_file
from flowchart2sdnn.diagram.validate import diagram_from_text, load_diagram
from flowchart2sdnn.diagram.yamlload import MAX_CHART_BYTES, parse_yaml_text
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.network.model import Network

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"
BAD = ROOT / "tests" / "data" / "bad_charts"
EXAMPLES = sorted(p.stem for p in DIAGRAMS.glob("*.yaml"))

# file -> (error code, block named or None, text on the line reported or a line number)
BAD_CHARTS = {
    "algebraic_loop": ("LINT001", "e", "e: {type: sum"),
    "alias_bomb": ("YAML005", None, "  f: &f"),
    "bad_unit": ("LINT008", None, "J1: {init"),
    "bad_yaml_syntax": ("YAML004", None, 11),
    "binary": ("YAML003", None, 2),
    "control_char": ("YAML003", None, "bell"),
    "deep_nesting": ("YAML005", None, "description: [[["),
    "delay_negative": ("CHART004", "Md", "n: -1"),
    "driven_twice": ("CHART008", "M1", "M1:   {type: constant"),
    "duplicate_key": ("YAML008", None, "k: 2/J1"),
    "empty": ("YAML006", None, 1),
    "gain_chain_too_long": ("COMPILE004", "g4", "g4:"),
    "gain_delay_loop": ("COMPILE003", "b", "b: {type: gain"),
    "gain_overflow": ("COMPILE002", "y", "y: {type: integrator"),
    "in_list_for_gain": ("CHART004", "g", "g:  {type: gain"),
    "init_data_not_output": ("CHART011", "phi", "init: data"),
    "init_outside_bounds": ("LINT006", None, "J1: {init: 2.0"),
    "k_call": ("CHART007", "acc1", "__import__"),
    "measured_by_not_output": ("CHART011", "w1true", "measured_by: w2"),
    "measured_by_without_data": ("CHART011", "w1true", "measured_by: w1"),
    "merge_key": ("YAML007", None, "<<: *defaults"),
    "min_ge_max": ("LINT006", None, "J1: {init"),
    "missing_field": ("CHART002", "acc1", "acc1: {type: gain"),
    "missing_sample_time": ("CHART002", None, 1),
    "neurons_zero": ("CHART004", "MR1", "neurons: 0"),
    "no_inputs": ("LINT010", None, 1),
    "nonlinear_into_nonlinear": ("COMPILE001", "MR2", "MR2:"),
    "not_utf8": ("YAML003", None, 2),
    "output_not_block": ("CHART009", None, "w2: {}"),
    "sample_time_negative": ("CHART004", None, "sample_time: -0.001"),
    "top_level_list": ("CHART001", None, 1),
    "two_documents": ("YAML004", None, 11),  # the second document's first line
    "undefined_parameter": ("CHART007", "acc1", "1/J11"),
    "undefined_signal": ("CHART009", "MR1", "in: w11"),
    "unit_mismatch": ("LINT005", "MB1", "MB1:"),
    "unknown_block_type": ("CHART006", "w1", "integrater"),
    "unknown_key": ("CHART003", "w1", "intit"),
    "wrong_version": ("CHART002", None, "sdnn: 2"),
    "zero_inertia": ("LINT011", "acc1", "acc1: {type: gain"),
}


def _first_error(path: Path) -> SdnnError:
    with pytest.raises(SdnnError) as info:
        compile_file(path)
    return info.value


# ------------------------------------------------------------------------------------------- examples
@pytest.mark.parametrize("name", EXAMPLES)
def test_every_example_lints_clean_and_compiles(name):
    path = DIAGRAMS / f"{name}.yaml"
    diagram = load_diagram(path)
    assert [d for d in lint_diagram(diagram) if d.severity == "error"] == []
    comp = compile_file(path)
    net = comp.network
    assert Network.from_json(net.to_json()) == net  # the network file loads back to the same object
    assert net.source["sha256"] and net.source["file"] == str(path)
    # block locations point at the block's line in the file
    lines = path.read_text().splitlines()
    for b in diagram.blocks:
        assert lines[b.location.line - 1].lstrip().startswith(f"{b.name}:")
    # only nonlinear blocks (tanh) and function blocks have a nonlinear transfer
    for layer in net.layers:
        transfers = {n.transfer for n in layer.neurons}
        assert transfers == {"linear"} or layer.kind in ("nonlinear", "function")


def test_sample_time_folds_into_the_weight_before_an_integrator():
    """The paper's T/J1: the weight MB1 -> w1 is the sample time over the inertia, for any J1."""
    net = compile_file(ROOT / "tests" / "data" / "two_mass_euler.yaml").network  # the paper's network: N = 1
    layer = {la.name: m for m, la in enumerate(net.layers)}
    (j,) = [j for j, w in enumerate(net.weights)
            if w.matrix == "LW" and w.layer == layer["w1"] and w.source == layer["MB1"]]
    for J1 in (0.1912, 0.5, 3.0):
        assert net.weight_values({"J1": J1})[j] == pytest.approx(net.sample_time / J1, rel=1e-15)
    assert net.weights[j].delay == 0  # forward path: implicit Euler


def test_the_network_file_is_versioned_and_documents_its_matrices():
    data = compile_file(DIAGRAMS / "engine.yaml").network.to_dict()
    assert data["format"] == "sdnn-network" and data["version"] == 1
    kinds = {m["matrix"] for m in data["matrices"]}
    assert kinds == {"LW", "IW"}  # engine: no constant, so no bias
    for m in data["matrices"]:
        admin = np.asarray(m["admin"])
        values = np.asarray(m["values"])
        assert set(np.unique(admin)) <= {0, 1}
        assert np.all(values[admin == 0] == 0)


# ------------------------------------------------------------------------------------------- YAML corners
def test_numbers_in_e_notation_and_yaml11_words_are_read_as_a_chart_author_means():
    text = """\
sdnn: 1
name: notation
sample_time: 1e-3
inputs: {u: {}}
outputs: {y: {}}
parameters: {g: {init: 5e2, fixed: yes}}
blocks:
  off: {type: constant, k: 2}
  on:  {type: sum, in: [u, off]}
  y:   {type: integrator, in: on}
"""
    diagram = diagram_from_text(text, "notation.yaml")
    assert diagram.sample_time == 1e-3
    assert diagram.parameter("g").init == 500.0 and diagram.parameter("g").fixed is True
    assert diagram.block("on").signals_in == ("u", "off")


@pytest.mark.parametrize("value", ["1" + "0" * 400, "0x" + "f" * 5000, ".nan", ".inf"])
@pytest.mark.parametrize("field", ["sample_time", "init", "k", "neurons", "weights"])
def test_huge_and_non_finite_numbers_are_errors_not_crashes(field, value):
    base = (DIAGRAMS / "engine.yaml").read_text()
    curve = (DIAGRAMS.parent / "tests" / "data" / "engine_neurons.yaml").read_text()  # a curve with `neurons: 3`
    text = {
        "sample_time": base.replace("sample_time: 0.001", f"sample_time: {value}"),
        "init": base.replace("init: 0.6", f"init: {value}"),
        "k": base.replace("k: 1/J1", f"k: {value}"),
        "neurons": curve.replace("neurons: 3", f"neurons: {value}"),
        "weights": curve.replace("neurons: 3", f"neurons: 1, weights: {{a: [{value}], v: [1]}}"),
    }[field]
    with pytest.raises(SdnnError) as info:
        compile_diagram(diagram_from_text(text, "big.yaml"))
    message = str(info.value)
    assert message.startswith("big.yaml:") and len(message) < 400


def test_alias_bomb_and_deep_nesting_are_refused_quickly():
    bomb = ["sdnn: 1", "x-bomb:", "  a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    prev = "a"
    for name in "bcdefghijk":
        bomb.append(f"  {name}: &{name} [" + ", ".join([f"*{prev}"] * 10) + "]")
        prev = name
    for text in ("\n".join(bomb), "a: &a [*a]", "x: " + "[" * 200_000 + "]" * 200_000, "x:\n" + "".join(
            "  " * i + f"k{i}:\n" for i in range(1, 500))):
        t0 = time.process_time()
        with pytest.raises(SdnnError) as info:
            parse_yaml_text(text, "evil.yaml")
        assert time.process_time() - t0 < 0.5  # CPU seconds: a shared machine does not make it flaky
        assert info.value.diagnostics[0].code == "YAML005"


def test_oversized_files_and_lone_surrogates_are_refused(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_bytes(b"# " + b"x" * MAX_CHART_BYTES + b"\n")
    with pytest.raises(SdnnError, match="YAML002"):
        load_diagram(big)
    with pytest.raises(SdnnError, match="YAML003"):
        parse_yaml_text("sdnn: 1\nname: \ud800\n", "s.yaml")
    with pytest.raises(SdnnError, match="YAML001"):
        load_diagram(tmp_path / "missing.yaml")
    with pytest.raises(SdnnError, match="YAML001"):
        load_diagram(tmp_path)


def test_a_broken_block_does_not_also_make_its_consumers_undefined():
    """An unknown type is one error: the block exists, so its readers are not 'undefined' as well."""
    err = _first_error(BAD / "unknown_block_type.yaml")
    assert [d.code for d in err.diagnostics] == ["CHART006"]


# ------------------------------------------------------------------------------------------- malformed charts
def test_there_are_at_least_twenty_malformed_charts():
    files = sorted(p.stem for p in BAD.glob("*.yaml"))
    assert len(files) >= 20
    assert files == sorted(BAD_CHARTS)


@pytest.mark.parametrize("name", sorted(BAD_CHARTS))
def test_each_malformed_chart_names_file_line_and_block(name):
    code, block, where = BAD_CHARTS[name]
    path = BAD / f"{name}.yaml"
    first = _first_error(path).diagnostics[0]
    assert first.code == code, str(first.one_line())
    assert first.severity == "error"
    assert first.location is not None and first.location.file == str(path)
    if isinstance(where, int):
        assert first.location.line == where
    else:
        lines = path.read_text(errors="replace").splitlines()
        assert where in lines[first.location.line - 1], f"line {first.location.line}: {first.one_line()}"
    assert first.block == block
    if block:
        assert f"block '{block}'" in first.one_line()
    assert "\n" not in first.one_line()


def test_did_you_mean_for_near_miss_names():
    assert "did you mean 'w1'?" in str(_first_error(BAD / "undefined_signal.yaml"))
    assert "did you mean 'J1'?" in str(_first_error(BAD / "undefined_parameter.yaml"))
    assert "did you mean 'integrator'?" in str(_first_error(BAD / "unknown_block_type.yaml"))
    assert "did you mean 'init'?" in str(_first_error(BAD / "unknown_key.yaml"))


def test_algebraic_loop_lists_its_blocks_in_signal_order():
    err = _first_error(BAD / "algebraic_loop.yaml")
    assert "e -> g -> f -> e" in str(err)


def test_k_is_never_evaluated_as_python(tmp_path):
    target = Path("/tmp/pwned_by_sdnn")
    target.unlink(missing_ok=True)
    _first_error(BAD / "k_call.yaml")
    assert not target.exists()


# ------------------------------------------------------------------------------------------- lint
PRODUCT = """\
sdnn: 1
name: wheel
sample_time: 0.001
inputs: {F: {}}
outputs: {w: {}}
parameters:
  J: {init: 0.2, min: 0}
  r: {init: 0.1, min: 0}
  b: {init: 0.01}
blocks:
  MB:    {type: sum, in: [F, -Mb]}
  acc:   {type: gain, in: MB, k: J*r}
  w:     {type: integrator, in: acc}
  Mb:    {type: gain, in: w, k: b}
  spare: {type: gain, in: w, k: 2}
"""


def test_parameters_only_seen_as_a_product_are_flagged_and_an_unused_block_too():
    diags = lint_diagram(diagram_from_text(PRODUCT, "wheel.yaml"))
    codes = {d.code: d for d in diags}
    assert "J, r" in codes["LINT007"].message and "b" not in codes["LINT007"].message.split("only")[0]
    assert codes["LINT002"].block == "spare" and codes["LINT002"].location.line == 15
    assert all(d.severity == "warning" for d in diags)
    # fixing one of them makes the other identifiable
    fixed = PRODUCT.replace("r: {init: 0.1, min: 0}", "r: {init: 0.1, min: 0, fixed: true}")
    assert "LINT007" not in {d.code for d in lint_diagram(diagram_from_text(fixed, "wheel.yaml"))}


def test_identifiability_check_scales_to_long_chains():
    """A 300-mass chain (900 parameters) is checked in well under a second, and one product is still found."""
    lines = ["sdnn: 1", "name: chain", "sample_time: 0.001", "inputs: {F: {}}", "outputs: {x299: {}}",
             "parameters:", "  r: {init: 0.5}"]
    lines += [f"  m{i}: {{init: 1.0}}\n  k{i}: {{init: 100.0}}" for i in range(300)]
    lines.append("blocks:")
    prev = "F"
    for i in range(300):
        k = f"k{i}*r" if i == 0 else f"k{i}"  # k0 and r only appear as k0*r
        lines += [f"  s{i}: {{type: sum, in: [{prev}, -f{i}]}}", f"  v{i}: {{type: integrator, in: s{i}}}",
                  f"  x{i}: {{type: gain, in: v{i}, k: 1/m{i}}}", f"  f{i}: {{type: gain, in: x{i}, k: {k}}}"]
        prev = f"x{i}"
    diagram = diagram_from_text("\n".join(lines) + "\n", "chain.yaml")
    t0 = time.process_time()
    diags = lint_diagram(diagram)
    assert time.process_time() - t0 < 1.5
    found = [d.message for d in diags if d.code == "LINT007"]
    assert len(found) == 1 and "parameters r, k0 only" in found[0]


def test_a_numeric_constant_with_a_declared_unit_is_not_a_unit_error():
    text = """\
sdnn: 1
name: offset
sample_time: 0.001
inputs: {M1: {unit: N*m}}
outputs: {w1: {unit: rad/s}}
parameters: {J1: {init: 0.2, unit: kg*m^2}}
blocks:
  M0:   {type: constant, k: 0.3, unit: N*m}
  Fs:   {type: gain, in: sg, k: 1.2}
  sg:   {type: function, f: sign_smooth, in: w1}
  MB1:  {type: sum, in: [M1, -M0, -Fs]}
  acc1: {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: acc1}
"""
    diags = lint_diagram(diagram_from_text(text, "offset.yaml"))
    assert [d for d in diags if d.severity == "error"] == []
    wrong = text.replace("M0:   {type: constant, k: 0.3, unit: N*m}", "M0:   {type: constant, k: 0.3, unit: rad/s}")
    assert "LINT005" in {d.code for d in lint_diagram(diagram_from_text(wrong, "offset.yaml"))}
