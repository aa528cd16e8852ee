"""`sdnn lint`, `sdnn compile` and `sdnn simulate` on charts: exit codes, one-line errors, files written or not."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_file
from flowchart2sdnn.network.model import Network

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"
BAD = ROOT / "tests" / "data" / "bad_charts"
BAD_FILES = sorted(BAD.glob("*.yaml"))
EXAMPLES = sorted(DIAGRAMS.glob("*.yaml"))
# the block each message must name (charts whose mistake is in a block)
BLOCK = {"algebraic_loop": "e", "delay_negative": "Md", "driven_twice": "M1", "gain_chain_too_long": "g4",
         "gain_delay_loop": "b", "gain_overflow": "y", "in_list_for_gain": "g", "init_data_not_output": "phi",
         "k_call": "acc1", "missing_field": "acc1", "neurons_zero": "MR1", "nonlinear_into_nonlinear": "MR2",
         "undefined_parameter": "acc1", "undefined_signal": "MR1", "unit_mismatch": "MB1",
         "unknown_block_type": "w1", "unknown_key": "w1", "zero_inertia": "acc1"}


def _run(*args: str):
    return CliRunner().invoke(main, list(args), catch_exceptions=True)


def _assert_one_line_error(stderr: str, path: Path) -> str:
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    line = lines[0]
    assert re.match(re.escape(str(path)) + r":\d+(:\d+)?: error\[[A-Z]+\d{3}\] ", line), line
    assert "Traceback" not in line and "internal error" not in line
    return line


@pytest.mark.parametrize("path", BAD_FILES, ids=lambda p: p.stem)
def test_compile_of_a_malformed_chart_is_one_line_exit_1_and_no_file(path, tmp_path):
    out, dot = tmp_path / "net.json", tmp_path / "net.dot"
    result = _run("compile", str(path), "-o", str(out), "--dot", str(dot))
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit)
    line = _assert_one_line_error(result.stderr, path)
    assert result.stdout == ""
    if path.stem in BLOCK:
        assert f"block '{BLOCK[path.stem]}'" in line
    assert not out.exists() and not dot.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind either


@pytest.mark.parametrize("path", BAD_FILES, ids=lambda p: p.stem)
def test_lint_of_a_malformed_chart_exits_1_and_every_line_names_the_file(path):
    result = _run("lint", str(path))
    assert result.exit_code == 1
    errors = [ln for ln in result.stderr.splitlines() if "error[" in ln]
    assert errors, result.output
    for ln in result.output.splitlines()[:-1]:  # the last line is the summary
        assert re.match(re.escape(str(path)) + r"(:\d+)+: (error|warning)\[", ln), ln
    assert "Traceback" not in result.output


@pytest.mark.parametrize("name", ["k_call", "binary"])
def test_the_installed_command_fails_the_same_way(name, tmp_path):
    path = BAD / f"{name}.yaml"
    out = tmp_path / "net.json"
    script = shutil.which("sdnn")  # the console script; python -m when the package is not installed
    exe = [script] if script else [sys.executable, "-m", "flowchart2sdnn"]
    proc = subprocess.run([*exe, "compile", str(path), "-o", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 1
    _assert_one_line_error(proc.stderr, path)
    assert proc.stdout == "" and not out.exists()


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_lint_clean_and_compile_to_the_library_network(path, tmp_path):
    result = _run("lint", str(path))
    assert result.exit_code == 0 and "0 error(s)" in result.output
    out = tmp_path / "net.json"
    result = _run("compile", str(path), "-o", str(out))
    assert result.exit_code == 0, result.output
    assert Network.from_json(out.read_text()) == compile_file(path).network


def test_lint_json_is_valid_json_with_the_codes(tmp_path):
    chart = tmp_path / "wheel.yaml"
    chart.write_text("""\
sdnn: 1
name: wheel
sample_time: 0.001
inputs: {F: {}}
outputs: {w: {}}
parameters: {J: {init: 0.2}, r: {init: 0.1}}
blocks:
  acc:   {type: gain, in: F, k: 1/(J*r)}
  w:     {type: integrator, in: acc}
  spare: {type: gain, in: w, k: 2}
""")
    result = _run("lint", "--format", "json", str(chart))
    assert result.exit_code == 0
    data = json.loads(result.stdout)
    assert data["errors"] == 0 and data["file"] == str(chart)
    by_code = {d["code"]: d for d in data["diagnostics"]}
    assert set(by_code) == {"LINT002", "LINT007"}
    assert by_code["LINT002"]["block"] == "spare" and by_code["LINT002"]["line"] == 10
    assert "J, r" in by_code["LINT007"]["message"]
    bad = _run("lint", "--format", "json", str(BAD / "undefined_signal.yaml"))
    assert bad.exit_code == 1
    data = json.loads(bad.stdout)
    assert data["errors"] == 1 and data["diagnostics"][0]["code"] == "CHART009"
    assert data["diagnostics"][0]["hint"] == "did you mean 'w1'?"


def test_compile_explain_shows_equations_and_the_delayed_edges():
    result = _run("compile", str(ROOT / "tests" / "data" / "two_mass_euler.yaml"), "--explain")  # the paper's network
    assert result.exit_code == 0
    text = result.stdout
    assert re.search(r"LW\{2,1\}\(0\)\[1,1\]\s+= 0\.001\*\(1/J1\)", text)  # T/J1 into the w1 integrator
    for edge in ("MR1 -> MB1", "MC -> MB1", "MD -> MB1", "w2 -> dw", "MR2 -> MB2"):
        assert re.search(rf"{edge} delayed 1 sample\(s\); breaks loop ", text), edge
    assert "MR2.v1" in text and "learned" in text


def test_compile_dot_draws_numbered_neurons(tmp_path):
    dot = tmp_path / "net.dot"
    assert _run("compile", str(DIAGRAMS / "engine.yaml"), "--dot", str(dot)).exit_code == 0
    text = dot.read_text()
    assert text.startswith('digraph "engine"') and '"1.1"' in text and "z^-1" in text


def test_compile_does_not_overwrite_without_force(tmp_path):
    out = tmp_path / "net.json"
    out.write_text("precious")
    result = _run("compile", str(DIAGRAMS / "engine.yaml"), "-o", str(out))
    assert result.exit_code == 1 and out.read_text() == "precious"
    assert len(result.stderr.splitlines()) == 1
    assert _run("compile", str(DIAGRAMS / "engine.yaml"), "-o", str(out), "--force").exit_code == 0
    assert Network.from_json(out.read_text()).name == "engine"
    # and never over its own input
    chart = tmp_path / "engine.yaml"
    chart.write_text((DIAGRAMS / "engine.yaml").read_text())
    assert _run("compile", str(chart), "-o", str(chart), "--force").exit_code == 1
    assert chart.read_text() == (DIAGRAMS / "engine.yaml").read_text()


def test_compile_prints_warnings_but_succeeds(tmp_path):
    chart = tmp_path / "spare.yaml"
    text = (DIAGRAMS / "engine.yaml").read_text() + "  spare: {type: gain, in: w1, k: 2}\n"
    chart.write_text(text)
    result = _run("compile", str(chart), "-o", str(tmp_path / "n.json"))
    assert result.exit_code == 0
    assert "warning[LINT002] block 'spare'" in result.stderr


def test_simulate_and_simulate_continuous_agree(tmp_path):
    """The CLI route of acceptance 2 for the engine with a fixed friction curve: CSV in, CSV out."""
    doc = yaml.safe_load((DIAGRAMS / "engine.yaml").read_text())
    doc["parameters"]["J1"]["init"] = 0.1912
    doc["blocks"]["MR1"].update({"neurons": 2, "weights": {"a": [8.0, 0.5], "v": [0.6, 0.3]}})
    chart = tmp_path / "engine.yaml"
    chart.write_text(yaml.safe_dump(doc, sort_keys=False))
    rng = np.random.default_rng(4)
    q = 3000
    levels = rng.uniform(-7, 7, q // 100).repeat(100)
    levels -= levels.mean()
    data = tmp_path / "in.csv"
    data.write_text("time,M1\n" + "".join(f"{k * 1e-3:.6f},{v:.10g}\n" for k, v in enumerate(levels)))
    disc, cont = tmp_path / "d.csv", tmp_path / "c.csv"
    assert _run("simulate", str(chart), str(data), "-o", str(disc)).exit_code == 0
    assert _run("simulate", str(chart), str(data), "-o", str(cont), "--continuous").exit_code == 0
    yd = np.loadtxt(disc, delimiter=",", skiprows=1)
    yc = np.loadtxt(cont, delimiter=",", skiprows=1)
    assert yd.shape == yc.shape == (q, 2)
    np.testing.assert_allclose(yd[:, 0], np.arange(q) * 1e-3, atol=1e-9)
    assert yd[0, 1] == 0.0  # zoh: row 0 is the initial state
    assert np.linalg.norm(yd[:, 1] - yc[:, 1]) / np.linalg.norm(yc[:, 1]) < 0.02


def test_simulate_signals_all_starts_every_signal_at_its_initial_state(tmp_path):
    """zoh: row 0 is the state before the first input acts, for every neuron (the integrator at its init)."""
    chart = tmp_path / "c.yaml"
    chart.write_text("""\
sdnn: 1
name: c
sample_time: 0.001
inputs: {u: {}}
outputs: {y: {}}
blocks:
  s: {type: sum, in: [u, -y]}
  y: {type: integrator, in: s, init: 1.5}
""")
    data = tmp_path / "in.csv"
    data.write_text("time,u\n0,4\n0.001,4\n0.002,4\n0.003,4\n")
    out = tmp_path / "out.csv"
    result = _run("simulate", str(chart), str(data), "-o", str(out), "--signals", "all")
    assert result.exit_code == 0, result.output
    header = out.read_text().splitlines()[0].split(",")
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    col = {n: rows[:, i] for i, n in enumerate(header)}
    assert col["y"][0] == 1.5 and col["s"][0] == 0.0  # histories, not the first step's values
    # by hand: s(t) = u(t-1) - y(t-1) (delayed feedback), y(t) = y(t-1) + T s(t)
    y, expect_y, expect_s = 1.5, [1.5], [0.0]
    for _ in range(3):
        s = 4 - y
        y = y + 1e-3 * s
        expect_y.append(y)
        expect_s.append(s)
    np.testing.assert_allclose(col["y"], expect_y, rtol=1e-9)
    np.testing.assert_allclose(col["s"], expect_s, rtol=1e-9)


def test_dot_quotes_a_chart_name_with_quotes(tmp_path):
    chart = tmp_path / "q.yaml"
    chart.write_text((DIAGRAMS / "engine.yaml").read_text().replace("name: engine", 'name: \'my "best" engine\''))
    dot = tmp_path / "q.dot"
    assert _run("compile", str(chart), "--dot", str(dot)).exit_code == 0
    assert dot.read_text().startswith('digraph "my \\"best\\" engine" {')
