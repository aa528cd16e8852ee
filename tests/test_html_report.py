"""`identify --html` and `diagnose --html`: one self-contained page per run (the README tour checks both pages on
the two-mass bench; here the engine record, the warnings, the missing extra, and a real browser)."""

from __future__ import annotations

import importlib
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from html_check import read_page

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.errors import SdnnError

pytest.importorskip("matplotlib")

ROOT = Path(__file__).resolve().parents[1]
ENGINE = ROOT / "diagrams" / "engine.yaml"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    d = tmp_path_factory.mktemp("html")
    raw = np.loadtxt(ROOT / "examples/data/engine_idle.csv", delimiter=",", skiprows=1)[:4000]
    write_csv(d / "idle.csv", {"time": raw[:, 0], "M1": raw[:, 1], "w1": raw[:, 2]}, float_format="%.17g")
    res = CliRunner().invoke(main, ["identify", str(d / "idle.csv"), "--diagram", str(ENGINE), "--split", "0.7",
                                    "--max-iter", "3", "--html", str(d / "report.html"), "--quiet"])
    assert res.exit_code == 0, res.output
    return d / "report.html"


def test_the_page_holds_the_tables_every_figure_and_the_warning(page):
    figures, text = read_page(page)
    assert figures == ["curve MR1", "compare", "residual over time", "resid w1 training: idle.csv",
                       "resid w1 validation: idle.csv after the split", "Bode plot"]
    assert "engine: identification" in text
    assert "J1" in text and "kg*m^2" in text and "95 % interval" in text and "MR1" in text
    assert "warning: not converged" in text  # --max-iter 3 stops early, and the page says so
    assert "training: idle.csv w1" in text and "validation: idle.csv after the split w1" in text  # the fit rows
    assert page.stat().st_size < 2_000_000


def test_no_matplotlib_is_one_line_naming_html_before_any_work(tmp_path, monkeypatch):
    plots = importlib.import_module("flowchart2sdnn.report.canvas")

    def missing(option="--plots"):
        raise SdnnError.at("PLOT001", f"{option} needs matplotlib, which is not installed", option)

    monkeypatch.setattr(plots, "require_matplotlib", missing)
    for command in (["identify", str(ENGINE), str(ROOT / "examples/data/engine_idle.csv")],
                    ["diagnose", str(ENGINE), str(ROOT / "examples/data/engine_idle.csv")]):
        res = CliRunner().invoke(main, [*command, "-o", str(tmp_path / "out"), "--html", str(tmp_path / "r.html")])
        assert res.exit_code == 1
        assert res.stderr.startswith("--html: error[PLOT001] --html needs matplotlib"), res.stderr
        assert list(tmp_path.iterdir()) == []


def test_an_existing_page_is_kept_without_force(page, tmp_path):
    target = tmp_path / "r.html"
    target.write_text("old")
    res = CliRunner().invoke(main, ["identify", str(ROOT / "examples/data/engine_idle.csv"), "--diagram",
                                    str(ENGINE), "--html", str(target)])
    assert res.exit_code == 1 and target.read_text() == "old"


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install chromium)")
def test_chromium_renders_the_page_and_nothing_overflows(page, tmp_path):
    from PIL import Image

    shot = tmp_path / "page.png"
    width = 1000
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           f"--screenshot={shot}", f"--window-size={width},5000", page.as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    image = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert image.shape[1] == width
    assert image[:, -12:].min() == 255  # the right margin is blank: no table or figure runs off the page
    ink = np.flatnonzero(image.min(axis=1) < 128)
    assert ink.size and ink[-1] > 2000  # the figures were drawn (the page is long), not a blank or error page


def test_the_page_draws_the_chart_inline(page):
    """The block diagram is inline SVG (the page stays one file): one box per block and input of the chart."""
    import re

    from flowchart2sdnn.diagram.validate import load_diagram

    html = page.read_text()
    svg = re.search(r"<svg .*?</svg>", html, re.S)
    assert svg and "http" not in svg.group(0).replace("http://www.w3.org/2000/svg", "")
    d = load_diagram(ENGINE)
    assert svg.group(0).count("<rect ") == len(d.blocks) + len(d.inputs)
