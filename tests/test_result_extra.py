"""Identification.extra is typed (identify.extra.Extra) and still reads as the mapping of RESULT.json's further
keys it was: a plain dict is the oracle for every mapping operation, and a document reads back unchanged."""

from __future__ import annotations

import json

import pytest

from flowchart2sdnn.identify.document import from_document, to_document
from flowchart2sdnn.identify.extra import Extra

ITEMS = {"discretization": {"substeps": 4, "floor": {"rms": {"w1": 0.001}}}, "shooting": {"stages": []},
         "identified_chart": None, "future_key": [1, 2], "command": {"data": "a.csv"}}


def test_an_extra_reads_as_the_dict_it_came_from():
    extra = Extra.of(ITEMS)
    assert extra.discretization["substeps"] == 4 and extra.command == {"data": "a.csv"}
    assert extra.parameters_per_record is None and extra.other == {"identified_chart": None, "future_key": [1, 2]}
    assert dict(extra) == ITEMS and extra == ITEMS and len(extra) == len(ITEMS)
    for key in [*ITEMS, "curve_start", "other", "nothing"]:
        assert (key in extra) == (key in ITEMS)
        assert extra.get(key, "absent") == ITEMS.get(key, "absent")
    with pytest.raises(KeyError):
        extra["curve_start"]
    assert {**extra, "x": 1} == {**ITEMS, "x": 1}
    assert Extra.of(extra) is extra


def test_a_document_with_further_keys_reads_back_unchanged():
    from pathlib import Path

    import flowchart2sdnn as sd

    root = Path(__file__).resolve().parent.parent
    data = sd.read_csv(root / "examples" / "data" / "engine_idle.csv").slice(0, 500)
    result = sd.identify(root / "diagrams" / "engine.yaml", data, max_iter=1)
    assert isinstance(result.extra, Extra) and result.extra.discretization is not None
    doc = {**json.loads(result.to_json()), **{k: v for k, v in ITEMS.items() if k != "discretization"}}
    back = from_document(doc)
    assert back.extra.other["future_key"] == [1, 2] and back.extra.command == {"data": "a.csv"}
    assert json.loads(json.dumps(to_document(back))) == doc
