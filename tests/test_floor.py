"""The discretization floor `identify` reports: the fitted network against the continuous chart it stands for.

Oracle: the continuous simulation itself (`simulate_continuous` of the identified chart at 200 RK4 steps per
sample, ten times finer than the floor's own), against the identified network's free run (`result.simulate`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.compiler.substeps import AUTO_CAP
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.assess.floor import FLOOR_WARN
from flowchart2sdnn.identify.document import from_document
from flowchart2sdnn.report.identify_text import format_result
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"


@pytest.fixture(scope="module")
def bench():
    """Two-mass Coulomb plant (c 477 N*m/rad: a 10 Hz shaft mode), 3 s, sensor noise 0.01 rad/s."""
    plant = load_diagram(DIAGRAMS / "two_mass_coulomb_plant.yaml")
    data = excite(plant, ExcitationSettings(seconds=3, seed=2, noise_std=0.01))
    ds = sd.dataset_from_frame(pd.DataFrame(data), time="time", inputs=["M1"], outputs=["w1", "w2"])
    return plant, ds


def _fit(chart, ds, **options):
    return sd.identify(chart, ds, max_iter=20, **options)


def _oracle_floor(result, ds, alignment="zoh"):
    """RMS of the identified network's free run against the identified chart simulated continuously."""
    net = result.simulate(ds, alignment)
    u = np.asarray(ds.columns["M1"], dtype=float)[:, None]
    if alignment == "zoh":
        cont = simulate_continuous(result.chart, u, substeps=200)
        rows = slice(1, None)
    else:  # direct: network row k has seen input k for a whole sample, the continuous chart's row k + 1
        cont = simulate_continuous(result.chart, np.vstack([u, u[-1:]]), substeps=200)[1:]
        rows = slice(0, None)
    return {n: float(np.sqrt(np.mean((net[n][rows] - cont[rows, i]) ** 2)))
            for i, n in enumerate(result.chart.output_names)}


def _floor_warnings(result):
    return [n for n in result.notices if n.code == "FLOOR001"]


def test_floor_at_one_step_warns_and_auto_does_not(bench):
    plant, ds = bench
    paper = _fit(dataclasses.replace(plant, substeps=1, delays="search"), ds)
    fine = _fit(plant, ds)  # substeps: auto, delays: torques
    for result in (paper, fine):
        floor = result.extra["discretization"]["floor"]["rms"]
        oracle = _oracle_floor(result, ds)
        for name in ("w1", "w2"):
            assert floor[name] == pytest.approx(oracle[name], rel=0.02, abs=1e-5)
    floor, rms = paper.extra["discretization"]["floor"]["rms"], paper.fit.train.rms
    assert max(floor[n] / rms[n] for n in rms) > FLOOR_WARN
    (warning,) = _floor_warnings(paper)
    n = warning.numbers["suggested_substeps"]
    assert n > 1 and f"`substeps: {n}`" in warning.message and "delays: torques" in warning.message
    # the outputs it names are those over the line, each at the share the result's own floor and RMS give
    over = {k for k in rms if floor[k] > FLOOR_WARN * rms[k]}
    assert set(warning.numbers["outputs"]) == over
    for k in over:
        assert warning.numbers["outputs"][k]["share"] == pytest.approx(floor[k] / rms[k])
    floor, rms = fine.extra["discretization"]["floor"]["rms"], fine.fit.train.rms
    assert max(floor[n] / rms[n] for n in rms) < FLOOR_WARN
    assert not _floor_warnings(fine)


def test_floor_is_in_the_result_file_and_the_summary(bench):
    plant, ds = bench
    result = _fit(dataclasses.replace(plant, substeps=1, delays="search"), ds)
    doc = json.loads(result.to_json())
    floor = doc["discretization"]["floor"]
    assert set(floor["rms"]) == {"w1", "w2"} and floor["rows"] == ds.n_rows - 1
    assert "RK4" in floor["oracle"]
    assert from_document(doc).to_document()["discretization"]["floor"] == floor  # read back unchanged
    text = format_result(result)
    line = next(ln for ln in text.splitlines() if ln.startswith("discretization floor"))
    assert f"w2 {floor['rms']['w2']:.3g}" in line and "% of RMS" in line


def test_floor_with_direct_alignment_compares_the_same_instants(bench):
    """With `direct` the network's row k follows input k; a floor taken one sample off would be ~0.1 rad/s."""
    plant, ds = bench
    result = _fit(plant, ds, alignment="direct")
    floor = result.extra["discretization"]["floor"]["rms"]
    oracle = _oracle_floor(result, ds, "direct")
    for name in ("w1", "w2"):
        assert floor[name] == pytest.approx(oracle[name], rel=0.02, abs=1e-5)
        assert floor[name] < 0.003


def test_floor_skips_cleanly_where_the_oracle_cannot_run(bench, monkeypatch):
    plant, ds = bench

    def refuse(*args, **kwargs):
        raise ValueError("algebraic loop (no integrator or delay on it): a -> b -> a")

    monkeypatch.setattr("flowchart2sdnn.simulate.continuous.simulate_continuous", refuse)
    result = _fit(plant, ds)
    floor = result.extra["discretization"]["floor"]
    assert floor["rms"] is None and "cannot run this chart" in floor["skipped"]
    assert not _floor_warnings(result)
    assert "discretization floor: not measured (the continuous oracle cannot run" in format_result(result)
    assert result.status != "error" and result.parameters["J1"].value > 0


# ------------------------------------------------------------------------------------------------ diagnose
def test_diagnose_credits_no_effect_with_the_floor():
    """A complete chart (the three-mass plant itself, at the truth) at one step per sample with the search rule:
    its residual is noise plus the network's own step error. A one-sample dead time imitates that error (without
    the floor rule diagnose accepted it: validation RMS 0.0083 -> 0.0076, BIC down; the floor is 0.0085, the
    whole validation RMS); the rule refuses it."""
    from flowchart2sdnn.diagnose import DiagnoseSettings, diagnose
    from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS

    plant = load_diagram(DIAGRAMS / "three_mass_plant.yaml")
    data = excite(plant, ExcitationSettings(seconds=4, seed=2, noise_std=0.003))
    ds = sd.dataset_from_frame(pd.DataFrame(data), time="time", inputs=["M1"], outputs=["w1", "w2", "w3"])
    chart = dataclasses.replace(plant, substeps=1, delays="search")
    settings = DiagnoseSettings(rounds=1, max_iter=50)
    result = diagnose(chart, ds, settings=settings, effects=[BUILTIN_EFFECTS["dead_time"]])
    report = result.report
    assert report["accepted"] == []
    (entry,) = report["rounds"]
    assert "discretization floor" in entry["reason"]
    # the validation RMS fell by more than min_gain: the floor alone refused it
    assert entry["validation_rms_after"] < entry["validation_rms_before"] * (1 - settings.min_gain)
    # the floor diagnose used, against the oracle: the nominal fit's network vs its chart run continuously,
    # over the validation part (the last 30 % of the record), every output pooled
    ident = result.nominal.identification
    net = ident.simulate(ds)
    cont = simulate_continuous(ident.chart, np.asarray(ds.columns["M1"], dtype=float)[:, None], substeps=200)
    first = int(round(0.7 * ds.n_rows))
    diff = np.column_stack([net[n][first:] - cont[first:, i] for i, n in enumerate(ident.chart.output_names)])
    assert report["before"]["validation_floor"] == pytest.approx(float(np.sqrt(np.mean(diff**2))), rel=0.02)


def test_floor_never_writes_a_non_finite_number(monkeypatch):
    """A run whose values are finite but whose squares overflow (the chart fuzzer's gain -23183) skips the floor."""
    from flowchart2sdnn.identify.assess import floor as F

    monkeypatch.setattr(F, "_one", lambda *a, **k: np.array([[1e200, 0.0]]))
    out = F.measure_floor(None, type("C", (), {"net": type("N", (), {"substeps": 1})(),
                                               "output_names": ("w1", "w2")})(), None, [(None, 0)], "zoh")
    assert out["rms"] is None and "too large" in out["skipped"]


def test_the_advised_substeps_remove_the_warning_on_the_bundled_example():
    """At the paper's one step per sample the bundled example warns; following its advice (a concrete N) removes
    the warning. The oracle is the continuous chart itself, through a second fit."""
    root = Path(__file__).resolve().parent.parent
    chart, data = sd.load_chart(root / "diagrams/engine.yaml"), sd.read_csv(root / "examples/data/engine_idle.csv")
    chart = dataclasses.replace(chart, delays=None)  # the default first-order rule (the chart states midpoint)
    first = sd.identify(dataclasses.replace(chart, substeps=1), data)
    (warning,) = _floor_warnings(first)
    n = warning.numbers["suggested_substeps"]
    again = sd.identify(dataclasses.replace(chart, substeps=n), data)
    assert not _floor_warnings(again)
    assert again.to_document()["discretization"]["floor"]["rms"]["w1"] < first.to_document()["discretization"]["floor"]["rms"]["w1"] / (n / 2)


def test_auto_substeps_refit_finer_when_the_fitted_curve_outgrows_them():
    """With `substeps: auto` (N read at the flat curve of the init) the fit is redone at 4x N from its own values
    when the floor, measured against the continuous chart, exceeds the warning's share of the residual: the result
    then carries no floor warning and says what it did."""
    root = Path(__file__).resolve().parent.parent
    chart, data = sd.load_chart(root / "diagrams/engine.yaml"), sd.read_csv(root / "examples/data/engine_idle.csv")
    chart = dataclasses.replace(chart, substeps=None, delays=None)  # the defaults (the chart states its own N)
    out = sd.identify(chart, data, floor_bias=False)
    doc = out.to_document()
    refit = doc["substeps_refit"]
    assert refit["substeps"] < doc["discretization"]["substeps"] and doc["discretization"]["requested"] is None
    note = next(n for n in out.notices if n.code == "FLOOR002")  # the first refit's (a second one adds its own)
    assert note.numbers["substeps"] == refit["substeps"]
    assert note.numbers["refitted_at"] == min(AUTO_CAP, 4 * refit["substeps"])
    assert note.numbers["refitted_at"] == doc["discretization"]["substeps"] or "then" in refit
    assert not _floor_warnings(out)
    assert doc["discretization"]["floor"]["rms"]["w1"] < FLOOR_WARN * doc["fit"]["train"]["rms"]["w1"]
    assert out.parameters["J1"].init == chart.parameter("J1").init  # the user's start, not the first fit's
