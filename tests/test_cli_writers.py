"""Every writer says what it wrote: each file a command leaves behind is named on a 'wrote' line, each
'wrote' line names a file that is there; on stderr where stdout carries data (a network, a CSV, JSON).

The oracle is the directory itself, listed before and after each command. (diagnose and report say so too;
they are left out here for their run time and their fleet input.)"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main

ROOT = Path(__file__).resolve().parents[1]
MSD = str(ROOT / "diagrams" / "mass_spring_damper.yaml")
FAST = ["--max-iter", "3", "--no-floor-bias", "--shooting", "off"]


def _run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


def _said(text: str) -> list[str]:
    """The paths on 'wrote ...' lines ('wrote A and B', 'wrote A: 300 rows', 'wrote N figure(s) to DIR')."""
    out = []
    for line in text.splitlines():
        m = re.match(r"wrote (?:\d+ (?:figure|file)\(s\) to )?(.*?)(?::| \(|$)", line)
        if m:
            out += m.group(1).split(" and ")
    return out


def _check(workdir: Path, before: set[Path], res, stream: str) -> None:
    """Every new file (or directory of figures) is named on a 'wrote' line of `stream`; each named one exists."""
    text = getattr(res, stream)
    said = {Path(p).resolve() for p in _said(text)}
    new = {p.resolve() for p in workdir.iterdir()} - before
    assert said == new, (text, sorted(map(str, new)))
    other = res.stderr if stream == "stdout" else res.stdout
    assert _said(other) == [], other


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A record and a fit of the mass-spring-damper, in a directory of their own."""
    d = tmp_path_factory.mktemp("writers")
    _run("excite", MSD, "--seconds", "0.3", "--amplitude", "-50", "50", "-o", d / "msd.csv")
    _run("identify", MSD, d / "msd.csv", *FAST, "-o", d / "fit.json")
    return d


def _fresh(tmp_path: Path) -> tuple[Path, set[Path]]:
    return tmp_path, {p.resolve() for p in tmp_path.iterdir()}


def test_compile_names_each_file_on_stderr(tmp_path):
    d, before = _fresh(tmp_path)
    res = _run("compile", MSD, "-o", d / "net.json", "--dot", d / "net.dot", "--svg", d / "chart.svg")
    _check(d, before, res, "stderr")
    assert res.stdout == ""


def test_simulate_and_excite_name_their_csv_on_stderr(tmp_path, work):
    d, before = _fresh(tmp_path)
    res = _run("simulate", MSD, work / "msd.csv", "-o", d / "sim.csv")
    _check(d, before, res, "stderr")
    before = {p.resolve() for p in d.iterdir()}
    res = _run("excite", MSD, "--seconds", "0.1", "-o", d / "e.csv")
    _check(d, before, res, "stderr")


def test_identify_names_the_result_the_chart_the_page_and_the_figures(tmp_path, work):
    d, before = _fresh(tmp_path)
    res = _run("identify", MSD, work / "msd.csv", *FAST, "-o", d / "r.json", "--html", d / "r.html",
               "--plots", d / "figures")
    _check(d, before, res, "stdout")
    n = len(list((d / "figures").iterdir()))
    assert n > 0 and f"wrote {n} figure(s) to {d / 'figures'}" in res.stdout


@pytest.mark.parametrize("fmt", ["text", "json"])
def test_compare_and_linearize_name_their_files_on_stderr_under_json(tmp_path, work, fmt):
    d, before = _fresh(tmp_path)
    stream = "stderr" if fmt == "json" else "stdout"
    res = _run("compare", work / "fit.json", work / "msd.csv", "-o", d / "c.png", "--format", fmt)
    _check(d, before, res, stream)
    before = {p.resolve() for p in d.iterdir()}
    res = _run("linearize", work / "fit.json", "--control", d / "ss.npz", "--format", fmt)
    _check(d, before, res, stream)


def test_batch_names_its_table(tmp_path, work):
    d, before = _fresh(tmp_path)
    res = _run("batch", MSD, work / "msd.csv", "--max-iter", "3", "-o", d / "fleet.csv")
    _check(d, before, res, "stdout")
