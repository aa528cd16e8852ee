"""Ctrl-C during diagnose keeps what was done: the report says 'interrupted' and holds the chart fitted so far."""

from __future__ import annotations

import json

import pytest
from diagnose_bench import chart, record

from flowchart2sdnn.diagnose import loop
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.strictjson import strict_json

EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}


@pytest.mark.parametrize("how", ["keyboard", "numba"])
def test_ctrl_c_in_the_screen_returns_the_nominal_fit_marked_interrupted(monkeypatch, how):
    plant = chart("one_mass_friction_plant")
    train = record(plant, 3.0, 5, 0.02, **EXCITATION)
    val = record(plant, 2.0, 6, 0.02, **EXCITATION)

    def interrupted_screen(*args, **kwargs):
        if how == "keyboard":
            raise KeyboardInterrupt
        # what a SIGINT inside a numba kernel looks like when it resurfaces in Python
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("error return without exception set") from exc

    monkeypatch.setattr(loop, "screen", interrupted_screen)
    d = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=2),
                 [BUILTIN_EFFECTS["friction"]])
    r = d.report
    assert r["stop"] == "interrupted" and r["interrupted"] is True
    assert r["accepted"] == [] and r["rounds"] == []
    assert r["after"] == r["before"]  # the chart fitted before the interrupt is what is reported
    json.dumps(strict_json(r), allow_nan=False)


def test_other_system_errors_are_not_taken_for_ctrl_c(monkeypatch):
    plant = chart("one_mass_friction_plant")
    train = record(plant, 2.0, 5, 0.02, **EXCITATION)

    def broken(*args, **kwargs):
        raise SystemError("a real bug")

    monkeypatch.setattr(loop, "screen", broken)
    with pytest.raises(SystemError, match="a real bug"):
        diagnose(chart("one_mass"), train, [], DiagnoseSettings(rounds=1), [BUILTIN_EFFECTS["friction"]])


def test_ctrl_c_in_the_final_bias_analysis_keeps_the_traced_result(monkeypatch):
    plant = chart("one_mass_friction_plant")
    train = record(plant, 3.0, 5, 0.02, **EXCITATION)
    val = record(plant, 2.0, 6, 0.02, **EXCITATION)

    def interrupted_bias(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(loop, "with_floor_bias", interrupted_bias)
    r = diagnose(chart("one_mass"), train, [val], DiagnoseSettings(rounds=1), [BUILTIN_EFFECTS["friction"]]).report
    assert r["interrupted"] is True and r["stop"] == "interrupted"
    assert [a["effect"] for a in r["accepted"]] == ["friction"]  # what was traced stands
    assert "bias" not in r["final"]["discretization"]
