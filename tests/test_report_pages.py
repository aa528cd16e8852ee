"""Pages that never contradict themselves: every figure of a record shows the fit % of its table row, and every
warning the command line printed is on the page (identify and diagnose), with the command line that ran.

The oracles are independent of the page: the fit table's numbers are identify's own scoring (identify.offline.run),
the figure's come from a separate simulation (identify.compare.compare_fit), read back from the DOM a headless
Chromium built; the warnings are the lines the command printed on the terminal.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from diagnose_bench import DATA, chart, record
from html_check import read_page
from test_per_record import CHART as PER_RECORD_CHART

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

pytest.importorskip("matplotlib")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

# an offset per record (the HSM150 recipe in small): the mean offset fits none of the records
CHART = PER_RECORD_CHART.replace("PR", "true")
OFFSETS = {"r1.csv": 0.03, "r2.csv": -0.02, "r3.csv": 0.01, "val.csv": -0.04}


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    d = tmp_path_factory.mktemp("pages")
    (d / "motor_offset.yaml").write_text(CHART)
    plant = load_diagram(d / "motor_offset.yaml")
    for seed, (name, off) in enumerate(OFFSETS.items(), start=1):
        rng = np.random.default_rng(seed)
        u = aprbs(400, plant.sample_time, rng, (-0.1, 0.1))
        y = simulate_continuous(plant, u[:, None], parameters={"J": 0.025, "b": 0.012, "off": off},
                                init={"w": 0.0})[:, 0] + 0.002 * rng.standard_normal(400)
        write_csv(d / name, {"time": np.arange(400) * plant.sample_time, "M": u, "w": y}, float_format="%.17g")
    return d


def _run(args: list[str], monkeypatch) -> tuple[int, list[str]]:
    """Run `sdnn args` as a shell would (sys.argv too): (exit code, every line printed, stdout and stderr)."""
    monkeypatch.setattr(sys, "argv", ["sdnn", *args])
    res = CliRunner().invoke(main, args)
    return res.exit_code, (res.stdout + res.stderr).splitlines()


def _identify(records, monkeypatch, *extra) -> tuple[Path, list[str], list[str]]:
    d = records
    args = [str(d / "motor_offset.yaml"), str(d / "r1.csv"), str(d / "r2.csv"), str(d / "r3.csv"),
            "--validate", str(d / "val.csv"), "--init-window", "150", "--html", str(d / "page.html"), "--force",
            *extra]
    code, printed = _run(["identify", *args], monkeypatch)
    assert code == 0, "\n".join(printed)
    return d / "page.html", ["identify", *args], printed


class _Dom(HTMLParser):
    """Tables (rows of cell texts) and figure captions of a page."""

    def __init__(self):
        super().__init__()
        self.tables, self.captions, self._cell, self._where = [], [], None, None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "figcaption":
            self._where = []

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None
        elif tag == "figcaption":
            self.captions.append(" ".join("".join(self._where).split()))
            self._where = None

    def handle_data(self, data):
        for part in (self._cell, self._where):
            if part is not None:
                part.append(data)


def _said(printed: list[str], kind: str) -> list[str]:
    """The messages of the lines the command printed as `kind` ("warning: ..." or, with a code, "warning[CODE] ...")."""
    said = (re.match(rf"\s*{kind}(?:: |\[[A-Z]+[0-9]+\] )(.*)", line) for line in printed)
    return [m.group(1) for m in said if m]


def _fit_table(dom: _Dom) -> list[list[str]]:
    return next(t for t in dom.tables if t and t[0][:5] == ["record", "output", "cost E", "RMS", "fit %"])


def _table_fits(dom: _Dom) -> dict:
    """{(record, output): fit %} of the fit table, one row per record (the pooled row left out)."""
    return {(row[0], row[1]): row[4] for row in _fit_table(dom)[1:] if row[6] != "pooled"}


def _figure_fits(dom: _Dom) -> dict:
    """{(record, output): fit %} as the compare figure's caption gives them (the numbers its legend draws)."""
    compare = next(c for c in dom.captions if c.startswith("Every training and validation record"))
    return {(label, output): value
            for label, output, value in re.findall(r"(?:\(|; )([^;()]+?), (\w+): fit (\S+) %", compare)}


def _rendered(page: Path) -> _Dom:
    """The page's DOM as headless Chromium built it."""
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--dump-dom", page.as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "<html" in done.stdout, done.stderr[-2000:]
    dom = _Dom()
    dom.feed(done.stdout)
    return dom


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)")
def test_each_records_figure_shows_the_fit_of_its_table_row(records, monkeypatch):
    page, _, _ = _identify(records, monkeypatch)
    dom = _rendered(page)
    table = _table_fits(dom)
    assert set(table) == {(f"training: r{k}.csv", "w") for k in (1, 2, 3)} | {("validation: val.csv", "w")}
    assert _figure_fits(dom) == table
    # the validation row is scored after its fitted initial-state window
    assert [row[5] for row in _fit_table(dom)[1:] if row[0] == "validation: val.csv"] == ["250"]


def test_the_page_shows_every_warning_the_identify_command_printed(records, monkeypatch):
    page, args, printed = _identify(records, monkeypatch, "--max-iter", "2", "--lags", "40")
    warnings = _said(printed, "warning")
    assert any(w.startswith("not converged") for w in warnings)  # the test sees warnings, or it proves nothing
    _, text = read_page(page)
    for w in warnings:
        assert " ".join(w.split()) in text, w
    status = next(line for line in printed if line.startswith("status: "))
    assert status in text and "(not converged)" in text
    assert f"command: {shlex.join(['sdnn', *args])}" in text  # the whole command line, options and all
    assert "40 lags (set with --lags)" in text


def test_the_page_shows_every_warning_and_note_the_diagnose_command_printed(tmp_path, monkeypatch):
    plant = chart("one_mass_friction_plant")
    excitation = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
    for name, seconds, seed in (("train", 5.0, 3), ("val", 2.0, 101)):
        ds = record(plant, seconds, seed, 0.02, **excitation)
        write_csv(tmp_path / f"{name}.csv", {"time": ds.time, "F": ds.columns["F"], "v": ds.columns["v"]})
    # semicolons in the training record: the command notes the delimiter it detected
    (tmp_path / "train.csv").write_text((tmp_path / "train.csv").read_text().replace(",", ";"))
    args = ["diagnose", str(DATA / "one_mass.yaml"), str(tmp_path / "train.csv"), "--validate",
            str(tmp_path / "val.csv"), "--effects", "friction,damping", "--rounds", "1", "--max-iter", "3",
            "--allow-unconverged", "--init-window", "100", "--html", str(tmp_path / "d.html")]
    code, printed = _run(args, monkeypatch)
    assert code == 0, "\n".join(printed)
    said = _said(printed, "warning") + _said(printed, "note")
    assert _said(printed, "warning") and any("delimiter ';'" in w for w in said), printed
    _, text = read_page(tmp_path / "d.html")
    for w in said:
        assert " ".join(w.split()) in text, w
    final = next(line for line in printed if line.startswith("status: "))
    assert final in text
    assert "the first fit of the chart as given did not converge: max_iter" in text  # --max-iter 3 stopped it
    assert "stopped: " in text and f"command: {shlex.join(['sdnn', *args])}" in text
    # the final chart's figures show the fit % of its table, the validation as diagnose scored it (init window)
    dom = _Dom()
    dom.feed((tmp_path / "d.html").read_text())
    assert _figure_fits(dom) == _table_fits(dom) and ("validation: val.csv", "v") in _table_fits(dom)


def test_the_lags_span_the_slowest_mode():
    """A shaft ringing at a 103 ms period sampled at 1 kHz needs 103 lags, not MATLAB's 25 (25 ms); a drive
    with only a 0.5 s time constant at 10 ms, 50; never fewer than 25 nor more than a fifth of the record."""
    from flowchart2sdnn.analysis.response import lags_for

    wd = 2 * np.pi / 0.103
    ringing = [{"pole": complex(-3.0, wd), "damped_hz": wd / (2 * np.pi)}, {"pole": complex(-40.0, 0.0),
                                                                            "damped_hz": 0.0}]
    assert lags_for(ringing, 0.001, 20000)[0] == 103
    assert lags_for([{"pole": complex(-2.0, 0.0), "damped_hz": 0.0}], 0.01, 20000)[0] == 50
    assert lags_for([{"pole": complex(-2.0, 0.0), "damped_hz": 0.0}], 0.01, 200)[0] == 40  # a fifth of 200
    assert lags_for([{"pole": complex(-500.0, 0.0), "damped_hz": 0.0}], 0.01, 20000)[0] == 25
    assert lags_for([{"pole": complex(0.0, 0.0), "damped_hz": 0.0}], 0.01, 20000)[0] == 25  # nothing stable


def test_the_verdict_in_words_follows_the_residual():
    """The words count the lags outside the band as the textbook formula does (r(k) = Σ ẽ(t) ẽ(t-k) / (N var e),
    band 2.576/√N) and say "white" only when none is; a residual that is the input one sample late reads
    "correlated with" it at lag 1; a random walk is "not white" at every lag."""
    from flowchart2sdnn.report.figures import verdict

    rng = np.random.default_rng(4)
    u = rng.standard_normal(4000)
    for seed in range(5):
        e = np.random.default_rng(10 + seed).standard_normal(4000)
        d = e - e.mean()
        outside = sum(abs(d[k:] @ d[:-k] / (d @ d)) > 2.5758293 / np.sqrt(4000) for k in range(1, 26))
        said = verdict(e, u, "w", ["M"], 25)
        assert said.startswith(("white" if outside == 0 else "not white") + f" ({outside} of 25 lags outside"), said
    e = rng.standard_normal(4000)
    late = np.concatenate([[0.0], u[:-1]]) + 0.1 * e
    said = verdict(late, u, "w", ["M"], 25)
    assert "correlated with M" in said and "largest at lag 1)" in said
    assert verdict(np.cumsum(e), u, "w", ["M"], 25).startswith("not white (25 of 25 lags outside")
