"""The public Python API: records from DataFrames equal records from CSV, bad input is a one-line error naming
the place, settings are checked in library words, and RESULT.json reads back to the same document."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.identify.document import from_document, to_document

ROOT = Path(__file__).resolve().parent.parent
CHART = ROOT / "diagrams" / "engine.yaml"
CSV = ROOT / "examples" / "data" / "engine_idle.csv"


@pytest.fixture(scope="module")
def record():
    return sd.read_csv(CSV).slice(0, 4000)


def test_a_frame_gives_the_record_the_csv_reader_gives(record):
    frame = {"time": record.time, "M1": record.columns["M1"], "w1": record.columns["w1"]}
    ds = sd.dataset_from_frame(frame, time="time")
    assert ds.n_rows == record.n_rows and set(ds.columns) == {"M1", "w1"}
    for name in ("M1", "w1"):
        np.testing.assert_array_equal(ds.columns[name], record.columns[name])
    assert ds.sample_time == pytest.approx(record.sample_time, rel=1e-12)
    a = sd.identify(CHART, ds, max_iter=5)
    b = sd.identify(CHART, record, max_iter=5)
    assert a.values == b.values


@pytest.mark.parametrize("frame, code, words", [
    ({"time": [0.0, 0.001, 0.002], "M1": [1.0, 2.0, 3.0]}, "CSV012", "column 'w1' is missing"),
    ({"time": [0.0, 0.001, 0.002], "M1": [1.0, np.nan, 3.0], "w1": [0.0, 0.0, 0.0]}, "CSV005", "row 1"),
    ({"time": [0.0, 0.002, 0.002], "M1": [1.0, 2.0, 3.0], "w1": [0.0, 0.0, 0.0]}, "CSV019", "repeats"),
    ({"time": [0.0, 0.001], "M1": [1.0, 2.0], "w1": [0.0, 0.0]}, "CSV009", "at least 3"),
    ({"time": [0.0, 0.001, 0.002], "M1": ["a", "b", "c"], "w1": [0.0, 0.0, 0.0]}, "CSV004", "not numeric"),
])
def test_bad_frames_are_one_line_errors_naming_the_place(frame, code, words):
    with pytest.raises(sd.SdnnError) as info:
        sd.dataset_from_frame(frame, time="time", inputs=["M1"], outputs=["w1"], name="bench frame")
    line = info.value.diagnostics[0].one_line()
    assert code in line and words in line and "bench frame" in line and "\n" not in line


def test_settings_are_checked_in_library_words(record):
    with pytest.raises(ValueError, match="^starts must be at least 1"):
        sd.identify(CHART, record, starts=0)
    with pytest.raises(TypeError, match="unknown settings: strats"):
        sd.identify(CHART, record, strats=2)


def test_a_result_document_reads_back_unchanged(record, tmp_path):
    result = sd.identify(CHART, record, max_iter=5, starts=2)
    doc = json.loads(result.to_json())
    doc["command"] = {"data": "x.csv"}  # keys a writer adds beside the result are kept
    path = tmp_path / "r.json"
    path.write_text(json.dumps(doc))
    back = sd.read_result(path)
    assert to_document(back) == doc
    assert back.parameters["J1"].value == result.parameters["J1"].value
    assert back.multistart.n == 2 and back.multistart.names == tuple(result.problem.names)


def test_non_finite_values_become_null_with_a_warning_and_read_back(record):
    result = sd.identify(CHART, record, max_iter=2)
    from dataclasses import replace

    broken = replace(result, parameters={**result.parameters,
                                         "J1": replace(result.parameters["J1"], value=float("nan"))})
    doc = to_document(broken)
    assert doc["parameters"]["J1"]["value"] is None
    assert doc["warnings"][-1] == "non-finite values stored as null: parameters.J1.value"
    assert to_document(from_document(doc)) == doc
