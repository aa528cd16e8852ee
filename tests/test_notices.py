"""Warnings as records (flowchart2sdnn.notices): every code the package can emit is registered and in the docs
table; a record's numbers are the values its message states; RESULT.json keeps `warnings` as the messages and
adds `notices` beside them, read back unchanged."""

from __future__ import annotations

import ast
import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.identify.document import from_document
from flowchart2sdnn.notices import CODES, Notice

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "flowchart2sdnn"


def _emitted() -> tuple[set[str], list[str]]:
    """(the codes of every `Notice(...)` call in the package, the places of calls whose code is not a literal)."""
    codes, loose = set(), []
    for path in PACKAGE.rglob("*.py"):
        if path.name == "notices.py":  # the record's own constructors copy a code they were given
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Notice":
                first = node.args[0] if node.args else None
                if isinstance(first, ast.Constant) and isinstance(first.value, str):
                    codes.add(first.value)
                else:
                    loose.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return codes, loose


def test_every_code_the_package_emits_is_registered_and_every_registered_code_is_emitted():
    codes, loose = _emitted()
    assert not loose, f"a notice's code must be a literal (the docs table is checked against them): {loose}"
    assert codes == set(CODES)


def test_the_docs_table_lists_every_code_once():
    text = (ROOT / "docs/guide/warnings.md").read_text()
    rows = re.findall(r"^\| ([A-Z]+[0-9]{3}) \| ([^|]+?) \|", text, re.MULTILINE)
    codes = [code for code, _ in rows]
    assert sorted(codes) == sorted(set(codes)), "a code listed twice"
    assert dict(rows) == dict(CODES)  # each with the meaning the registry gives it


def test_a_record_refuses_an_unknown_code_and_stores_strict_json():
    with pytest.raises(ValueError, match="unknown notice code"):
        Notice("NOPE001", "x")
    n = Notice("FLOOR001", "m", {"outputs": {"w1": {"share": math.inf, "floor": 0.5}}, "ratio": math.nan,
                                 "substeps": np.int64(4), "rows": [np.float32(-np.inf)]})
    d = n.to_dict()
    assert d["numbers"] == {"outputs": {"w1": {"share": None, "floor": 0.5}}, "ratio": None, "substeps": 4,
                            "rows": [None]}
    json.dumps(d, allow_nan=False)
    assert n.one_line() == "warning[FLOOR001] m" and Notice(None, "m").one_line("note") == "note: m"
    finite = Notice("IDENT002", "a and b", {"parameters": ["a", "b"], "correlation": -0.9999}, "fix one")
    assert Notice.from_dict(json.loads(json.dumps(finite.to_dict()))) == finite


@pytest.fixture(scope="module")
def on_bound(tmp_path_factory):
    """The bundled example with J1 started on its upper bound and two LM iterations: two warnings whose numbers
    the test knows from what it asked for."""
    text = (ROOT / "diagrams/engine.yaml").read_text()
    old = "J1: {init: 0.6, unit: kg*m^2, min: 0,"
    assert old in text
    chart = tmp_path_factory.mktemp("notices") / "engine.yaml"
    chart.write_text(text.replace(old, "J1: {init: 0.6, unit: kg*m^2, min: 0.05, max: 0.6,"))
    data = sd.read_csv(ROOT / "examples/data/engine_idle.csv")
    return sd.identify(str(chart), data, max_iter=2, floor_bias=False)


def test_the_numbers_are_what_the_run_was_given(on_bound):
    by_code = {n.code: n for n in on_bound.notices}
    start = by_code["START002"]
    assert start.numbers == {"parameter": "J1", "side": "upper", "value": 0.6}
    assert start.message.startswith("J1 starts on its upper bound (0.6)")
    stop = by_code["CONV001"]
    assert stop.numbers["max_iter"] == 2 and stop.numbers["status"] == on_bound.status
    assert all(n.advice for n in on_bound.notices)


def test_the_result_file_keeps_its_warnings_and_adds_the_records_beside_them(on_bound):
    doc = json.loads(on_bound.to_json())
    assert doc["warnings"] == list(on_bound.warnings) == [n.message for n in on_bound.notices]
    assert doc["notices"] == [n.to_dict() for n in on_bound.notices]
    again = from_document(doc)
    assert again.warnings == on_bound.warnings and again.notices == on_bound.notices
    # a document written before the codes: the same warnings, as records without a code
    old = from_document({k: v for k, v in doc.items() if k != "notices"})
    assert [(n.code, n.message) for n in old.notices] == [(None, w) for w in on_bound.warnings]


def test_editing_the_warnings_alone_keeps_a_record_per_warning(on_bound):
    fewer = dataclasses.replace(on_bound, warnings=on_bound.warnings[1:] + ("a note of the caller",))
    assert [n.message for n in fewer.notices] == list(fewer.warnings)
    assert fewer.notices[:-1] == on_bound.notices[1:] and fewer.notices[-1].code is None
    # records given as the warnings: kept, their sentences the warnings
    given = dataclasses.replace(on_bound, warnings=on_bound.notices[::-1], notices=())
    assert given.notices == on_bound.notices[::-1] and given.warnings == on_bound.warnings[::-1]


def test_the_summary_prints_each_warning_with_its_code(on_bound):
    from flowchart2sdnn.report.identify_text import format_result

    printed, text = format_result(on_bound), on_bound.summary()  # the command's text, the notebook's
    for n in on_bound.notices:
        assert f"warning[{n.code}] {n.message}" in printed
        assert f"[{n.code}]" in text
