"""REPORT.json through diagnose.document: the typed Diagnosis writes the document the loop always wrote, reads
back to the same document, and a file that is not a report is a one-line error naming it.

Data: a continuous simulation of a one-mass plant with Coulomb friction and measurement noise, traced with the
chart that lacks the friction (tests/data/diagnose); one round, two effects, so the run takes a few seconds.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner
from diagnose_bench import DATA, chart, record

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagnose.document import dumps, from_document, read_report, to_document
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagnose.result import Diagnosis
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.notices import Notice

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "diagnose.md"
EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
EFFECTS = [BUILTIN_EFFECTS[n] for n in ("friction", "damping")]


@pytest.fixture(scope="module")
def records():
    plant = chart("one_mass_friction_plant")
    return record(plant, 2.0, 3, 0.02, **EXCITATION), record(plant, 1.0, 101, 0.02, **EXCITATION)


@pytest.fixture(scope="module")
def traced(records):
    train, val = records
    return diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=1), EFFECTS)


def test_the_typed_parts_are_the_documents_keys(traced):
    d, doc = traced, traced.report
    assert isinstance(d, Diagnosis) and d.accepted, "the plant's friction is missing from the chart"
    # each typed part against the document's own mapping, key by key
    assert d.stop == doc["stop"] and d.n_accepted == doc["n_accepted"] == len(doc["accepted"])
    assert [a.title for a in d.accepted] == [f"{a['effect']} at {a['at']}" + (f" ({a['label']})" if a["label"]
                                                                              else "") for a in doc["accepted"]]
    assert [(c.round, c.rank, c.effect, c.at, c.score) for c in d.candidates] == \
        [(c["round"], c["rank"], c["effect"], c["at"], c["score"]) for c in doc["candidates"]]
    refitted = [c for c in d.candidates if c.refit is not None]
    assert len(refitted) == sum(1 for c in doc["candidates"] if c.get("refitted"))
    assert all(c.refit.criterion == "bic" for c in refitted)
    assert d.rounds[0].accepted is doc["rounds"][0]["accepted"] is True
    assert d.before.validation_rms == doc["before"]["validation_rms"] > d.after.validation_rms
    assert d.identification.values == {k: v["value"] for k, v in doc["final"]["parameters"].items()}
    assert d.whiteness[0].white is doc["whiteness"]["before"]["white"]


def _documented() -> str:
    text = GUIDE.read_text(encoding="utf-8")
    return text[text.index("## REPORT.json"):text.index("How well diagnose finds")]


def _braced(section: str, key: str) -> set[str]:
    """The names the guide lists in braces after `key` (``first_fit` `{converged, status, ...}``)."""
    found = re.search(rf"`{key}`\s*\(?\[?`?\{{([^}}]*)\}}", section)
    assert found, f"the guide no longer lists the keys of {key}"
    listed = re.sub(r"\([^)]*\)", "", found.group(1))  # a name's explanation in parentheses is not a name
    return {w.strip(" `\n") for w in listed.split(",")}


def test_the_document_has_the_keys_the_guide_documents(traced):
    # the user guide is the contract users' scripts were written against: every key it names is written
    section = _documented()
    doc = traced.report
    top = {"candidates", "rounds", "accepted", "final", "before", "after", "whiteness", "stop", "last_round",
           "n_accepted", "first_fit", "settings", "timing"}
    assert all(f"`{k}`" in section for k in top)
    # beside them: the format tag, the interrupted flag (the `interrupted` stop), the notes and the command line
    assert top <= set(doc) and set(doc) - top <= {"format", "version", "interrupted", "data_notes",
                                                      "data_notices", "command"}
    assert set(doc["first_fit"]) == _braced(section, "first_fit")
    assert all(set(a) == _braced(section, "accepted") for a in doc["accepted"])
    rounds = {k.split("/")[0] for k in _braced(section, "rounds")} | {"after"}
    assert all(rounds <= set(r) for r in doc["rounds"]), rounds - set(doc["rounds"][0])


def test_a_document_reads_back_unchanged(traced):
    doc = json.loads(traced.to_json())
    again = from_document(doc)
    assert json.loads(dumps(to_document(again))) == doc
    assert list(to_document(again)) == list(doc)  # the keys in the order they were written


def test_the_data_notes_read_back_as_records_with_their_codes(traced):
    note = Notice("READ001", "train.csv: delimiter ';' (detected from the header; --delimiter to set it)",
                  {"delimiter": ";"}, "--delimiter to set it")
    noted = dataclasses.replace(traced, data_notes=(note.message,), data_notices=(note,))
    doc = json.loads(noted.to_json())
    assert doc["data_notes"] == [note.message] and doc["data_notices"] == [note.to_dict()]
    again = from_document(doc)
    assert again.data_notices == (note,) and again.notices[0] == note
    assert again.warnings == tuple(n.message for n in again.notices)
    assert again.notices[1:] == again.identification.notices  # a traced run: nothing of its own to say


def test_the_command_line_writes_the_document_and_it_reads_back(records, tmp_path):
    train, val = records
    for name, ds in (("train", train), ("val", val)):
        write_csv(tmp_path / f"{name}.csv", {"time": ds.time, **ds.columns}, "%.17g")
    out = CliRunner().invoke(main, ["diagnose", str(tmp_path / "train.csv"), "--diagram",
                                    str(DATA / "one_mass.yaml"), "--validate", str(tmp_path / "val.csv"),
                                    "--rounds", "1", "--effects", "friction,damping", "--quiet",
                                    "--report", str(tmp_path / "r.json"), "-o", str(tmp_path / "a.yaml")])
    assert out.exit_code == 0, out.output
    text = (tmp_path / "r.json").read_text()
    d = read_report(tmp_path / "r.json", tmp_path / "a.yaml")
    assert dumps(d.to_document()) == text
    assert d.command["validate"] == [str(tmp_path / "val.csv")]
    assert d.diagram is not None and d.identification.chart is d.diagram
    assert [a.title for a in d.accepted] == [a.title for a in read_report(tmp_path / "r.json").accepted]


@pytest.mark.parametrize("text, words", [
    (None, "no such file"),
    ("{", "not JSON"),
    ('{"format": "sdnn-result"}', 'expected "format": "sdnn-diagnose"'),
    ('{"format": "sdnn-diagnose", "stop": "rounds"}', "lacks 'first_fit'"),
])
def test_a_file_that_is_not_a_report_is_a_one_line_error(tmp_path, text, words):
    path = tmp_path / "REPORT.json"
    if text is not None:
        path.write_text(text)
    with pytest.raises(SdnnError) as info:
        read_report(path)
    line = str(info.value)
    assert words in line and str(path) in line and "\n" not in line
