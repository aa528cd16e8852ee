"""One argument order for every command, `sdnn COMMAND CHART [DATA...]`: the old spellings still work and say
how to write them, on stderr; the documentation writes the one order."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.cli.order import MODEL_SUFFIXES, chart_first
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
MSD = str(ROOT / "diagrams" / "mass_spring_damper.yaml")
FAST = ["--max-iter", "2", "--no-floor-bias", "--shooting", "off"]


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("order") / "msd.csv"
    columns = excite(load_diagram(MSD), ExcitationSettings(seconds=0.3, seed=3, amplitude=(-50.0, 50.0),
                                                           noise_std=1e-5))
    write_csv(path, columns, float_format="%.17g")
    return str(path)


def _fit(tmp_path, name, *args):
    out = tmp_path / f"{name}.json"
    res = _run("identify", *args, *FAST, "-o", out, "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text(encoding="utf-8"))
    return res, doc


def test_identify_reads_chart_first_and_the_old_orders_alike(record, tmp_path):
    new, doc = _fit(tmp_path, "new", MSD, record)
    old, old_doc = _fit(tmp_path, "old", record, "--diagram", MSD)
    swapped, swapped_doc = _fit(tmp_path, "swapped", record, MSD)
    assert "note:" not in new.stderr
    assert "old argument order" in old.stderr and "sdnn identify CHART DATA..." in old.stderr
    assert f"'{MSD}' read as the chart" in swapped.stderr
    for d in (old_doc, swapped_doc):  # the same fit of the same chart on the same record
        assert d["command"]["diagram"] == doc["command"]["diagram"] == MSD
        assert d["command"]["data"] == doc["command"]["data"] == record
        assert {n: p["value"] for n, p in d["parameters"].items()} == \
            {n: p["value"] for n, p in doc["parameters"].items()}


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_chart_without_data_is_a_usage_error(command):
    res = _run(command, MSD)
    assert res.exit_code == 2
    assert f"sdnn {command} CHART DATA..." in res.stderr and "Traceback" not in res.output


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_two_charts_are_a_usage_error(command, record):
    res = _run(command, MSD, record, "--diagram", MSD)
    assert res.exit_code == 2
    assert "two charts" in res.stderr


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_diagnose_and_identify_read_the_data_from_after_the_chart(command, tmp_path):
    """No run needed: a missing record is refused naming that record, in both orders (exit 1)."""
    missing = tmp_path / "no_such.csv"
    new = _run(command, MSD, missing)
    old = _run(command, missing, "--diagram", MSD)
    for res in (new, old):
        assert res.exit_code == 1, res.output
        errors = [line for line in res.stderr.splitlines() if not line.startswith("note:")]
        assert len(errors) == 1 and str(missing) in errors[0]
    assert "note:" not in new.stderr and "old argument order" in old.stderr


def test_simulate_with_the_chart_written_last_says_so_and_runs_the_same(record):
    new = _run("simulate", MSD, record)
    swapped = _run("simulate", record, MSD)
    assert new.exit_code == swapped.exit_code == 0
    assert swapped.stdout == new.stdout and new.stdout.startswith("time,")
    assert "the chart comes first (sdnn simulate CHART DATA)" in swapped.stderr and new.stderr == ""


@pytest.mark.parametrize(("args", "expected", "noted"), [
    (("c.yaml", ("a.csv", "b.csv")), ("c.yaml", ("a.csv", "b.csv")), False),
    (("a.csv", ("c.yaml", "b.csv")), ("c.yaml", ("a.csv", "b.csv")), True),
    (("a.csv", ("b.csv", "c.YML")), ("c.YML", ("a.csv", "b.csv")), True),
    (("a.csv", ("b.csv",)), ("a.csv", ("b.csv",)), False),  # no chart to recognise: read as written
    (("a.csv", ("c.yaml", "d.yaml")), ("a.csv", ("c.yaml", "d.yaml")), False),  # two: not guessed
    (("logs", ("c.yaml",)), ("c.yaml", ("logs",)), True),  # a directory of records (batch)
])
def test_chart_first_puts_back_only_a_chart_it_recognises(capsys, args, expected, noted):
    assert chart_first("sdnn x CHART DATA...", *args) == expected
    assert ("read as the chart" in capsys.readouterr().err) == noted


def test_a_result_document_is_a_model_for_compare_and_linearize():
    assert chart_first("sdnn compare MODEL DATA...", "a.csv", ("fit.json",), MODEL_SUFFIXES) == \
        ("fit.json", ("a.csv",))
    assert chart_first("sdnn x CHART DATA...", "a.csv", ("fit.json",)) == ("a.csv", ("fit.json",))


#: an `sdnn identify|diagnose ...` command line in the documentation, to the end of its line or code span
DOC_COMMAND = re.compile(r"sdnn (identify|diagnose) [^`\n|]*")


def test_the_documentation_writes_the_chart_first():
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    old = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in pages for m in DOC_COMMAND.finditer(
        p.read_text(encoding="utf-8")) if "--diagram" in m.group(0)]
    assert old == []
