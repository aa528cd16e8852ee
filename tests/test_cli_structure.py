"""The shape of the command line: every command answers --help, the shared options are declared once, the
library never imports the cli/ layer, and a library settings error is a usage error naming the flag."""

from __future__ import annotations

import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.cli.options import flag_words, settings_usage

PACKAGE = Path(__file__).resolve().parents[1] / "flowchart2sdnn"
CLI = PACKAGE / "cli"
LAG = Path(__file__).parent / "data" / "bad_identify" / "lag.yaml"

COMMANDS = ["lint", "compile", "simulate", "excite", "identify", "diagnose", "batch", "report", "compare", "linearize"]


def test_the_group_has_every_command():
    assert sorted(main.commands) == sorted(COMMANDS)


@pytest.mark.parametrize("command", [[], *([c] for c in COMMANDS)])
def test_every_command_answers_help(command):
    for flag in ("--help", "-h"):
        res = CliRunner().invoke(main, [*command, flag])
        assert res.exit_code == 0, res.output
        assert res.output.startswith("Usage: ")


@pytest.mark.parametrize("flag", ["--force", "--seed", "--map", "--max-iter", "--alignment", "--workers",
                                  "--scheduler"])
def test_shared_options_are_declared_once(flag):
    """The flag is spelled in one place of cli/ (options.py), yet every command that has it gets it from there."""
    places = {p.name: len(re.findall(rf"""["']{re.escape(flag)}["']""", p.read_text(encoding="utf-8")))
              for p in CLI.glob("*.py")}
    assert {name: n for name, n in places.items() if n} == {"options.py": 1}
    using = [name for name, command in main.commands.items()
             if any(flag in p.opts for p in command.params)]
    assert using, flag


def test_force_seed_map_max_iter_are_where_they_were():
    has = {name: {o for p in command.params for o in p.opts} for name, command in main.commands.items()}
    assert {n for n in has if "--force" in has[n]} == {"compile", "simulate", "excite", "identify", "diagnose",
                                                       "batch", "compare", "linearize"}
    assert {n for n in has if "--seed" in has[n]} == {"compile", "excite", "identify", "diagnose", "batch"}
    assert {n for n in has if "--map" in has[n]} == {"simulate", "identify", "diagnose", "batch", "compare",
                                                     "linearize"}
    assert {n for n in has if "--max-iter" in has[n]} == {"identify", "diagnose", "batch"}


def test_library_never_imports_the_cli_layer_or_click():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if CLI in path.parents or path.name == "__main__.py":
            continue
        text = path.read_text(encoding="utf-8")
        if re.search(r"^\s*(from|import)\s+(click|flowchart2sdnn\.cli|\.+cli)\b|[\"']flowchart2sdnn\.cli", text, re.M):
            offenders.append(str(path.relative_to(PACKAGE)))
    assert offenders == []


def test_flag_words_names_the_flags():
    flags = {"starts": "--starts", "max_iter": "--max-iter", "split": "--split"}
    assert flag_words("starts must be at least 1", flags) == "--starts must be at least 1"
    assert flag_words("--starts must be at least 1", flags) == "--starts must be at least 1"
    assert flag_words("max_iter must not be negative", flags) == "--max-iter must not be negative"
    assert flag_words("split must lie strictly between 0 and 1", flags) == "--split must lie strictly between 0 and 1"
    assert flag_words("restarts are fine", flags) == "restarts are fine"


def test_a_settings_error_is_a_usage_error_naming_the_flag():
    @click.command()
    @click.option("--max-iter", type=int, default=1)
    def cmd(max_iter):
        with settings_usage():
            raise ValueError("max_iter must not be negative")

    res = CliRunner().invoke(cmd, [])
    assert res.exit_code == 2
    assert "--max-iter must not be negative" in res.output


def test_identify_maps_its_settings_errors_to_its_flags(tmp_path, monkeypatch):
    import importlib

    face = importlib.import_module("flowchart2sdnn.identify")  # where the command takes IdentifySettings from

    def refuse(**kwargs):
        raise ValueError("starts must be at least 1")

    monkeypatch.setattr(face, "IdentifySettings", refuse)
    data = tmp_path / "d.csv"
    data.write_text("time,w1,w2\n" + "".join(f"{k * 0.001:.3f},{k % 3},{k % 5}\n" for k in range(20)))
    res = CliRunner().invoke(main, ["identify", str(data), "--diagram", str(LAG), "--quiet"])
    assert res.exit_code == 2, res.output
    assert "--starts must be at least 1" in res.output and "Traceback" not in res.output


def test_simulate_chart_is_what_sdnn_simulate_writes(tmp_path):
    """The library function behind `sdnn simulate`: the same columns, no click needed."""
    import numpy as np

    from flowchart2sdnn.data.csvdata import read_csv
    from flowchart2sdnn.diagram.validate import load_diagram
    from flowchart2sdnn.simulate.run import simulate_chart, simulation_columns

    data = tmp_path / "d.csv"
    data.write_text("time,w1\n" + "".join(f"{k * 0.001:.3f},{np.sin(k / 5):.6f}\n" for k in range(50)))
    diagram = load_diagram(LAG)
    assert simulation_columns(diagram) == ["w1"]
    ds = read_csv(data, simulation_columns(diagram), {}, diagram.sample_time)
    for extra, kwargs in (([], {}), (["--signals", "all"], {"all_signals": True}),
                          (["--continuous"], {"continuous": True}), (["--alignment", "direct"], {"alignment": "direct"})):
        columns = simulate_chart(diagram, ds, **kwargs)
        assert list(columns)[:2] == ["time", "w2"] and all(len(v) == 50 for v in columns.values())
        assert (len(columns) > 2) == bool(kwargs.get("all_signals"))
        res = CliRunner().invoke(main, ["simulate", str(LAG), str(data), *extra])
        assert res.exit_code == 0, res.output
        lines = res.output.splitlines()
        assert lines[0] == ",".join(columns)
        written = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
        np.testing.assert_allclose(written, np.column_stack(list(columns.values())), rtol=1e-9, atol=1e-12)
