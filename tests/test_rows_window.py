"""--rows FROM:TO fits a window of a record: the same as the window written out as its own file (the oracle);
bad windows are usage errors (exit 2) or, when the file is shorter than the window needs, one line naming it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv

ROOT = Path(__file__).resolve().parent.parent
CHART = str(ROOT / "diagrams" / "engine.yaml")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("rows")
    raw = np.loadtxt(ROOT / "examples/data/engine_idle.csv", delimiter=",", skiprows=1)[:6000]
    write_csv(d / "all.csv", {"time": raw[:, 0], "M1": raw[:, 1], "w1": raw[:, 2]}, float_format="%.17g")
    part = raw[1000:4000]
    write_csv(d / "part.csv", {"time": part[:, 0], "M1": part[:, 1], "w1": part[:, 2]}, float_format="%.17g")
    return d


def _identify(files, *args):
    out = files / f"r{abs(hash(args))}.json"
    res = CliRunner().invoke(main, ["identify", *args, "--diagram", CHART, "--max-iter", "5", "--quiet", "-o",
                                    str(out), "--force"])
    assert res.exit_code == 0, res.output
    return json.loads(out.read_text())


def test_a_window_fits_exactly_what_the_window_as_a_file_fits(files):
    window = _identify(files, str(files / "all.csv"), "--rows", "1000:4000")
    alone = _identify(files, str(files / "part.csv"))
    assert window["parameters"] == alone["parameters"]
    assert window["fit"]["train"]["rows"] == alone["fit"]["train"]["rows"]
    assert window["data"]["train"]["rows"] == 3000


@pytest.mark.parametrize("value, words", [("10", "is not FROM:TO"), ("a:b", "is not FROM:TO"),
                                          ("5:6", "at least 3 rows"), ("-1:", "count from 0")])
def test_bad_windows_are_usage_errors(files, value, words):
    res = CliRunner().invoke(main, ["identify", str(files / "all.csv"), "--diagram", CHART, "--rows", value])
    assert res.exit_code == 2 and words in res.output


def test_a_window_past_the_end_of_a_file_names_the_file(files):
    res = CliRunner().invoke(main, ["compare", CHART, str(files / "all.csv"), "--rows", "5999:"])
    assert res.exit_code == 1
    assert "all.csv" in res.output and "DATA005" in res.output and "leaves 1 of the file's 6000 rows" in res.output
