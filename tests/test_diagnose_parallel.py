"""diagnose's candidate refits on an executor: the same report serially, in local processes and on Dask."""

from __future__ import annotations

import json

import pytest
from diagnose_bench import chart, record

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose, refit_unit
from flowchart2sdnn.diagnose.score import scan_unit, score_unit
from flowchart2sdnn.executors import DaskExecutor, ProcessExecutor, SerialExecutor
from flowchart2sdnn.strictjson import strict_json

EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
EFFECTS = [BUILTIN_EFFECTS[n] for n in ("friction", "damping", "saturation")]
SETTINGS = DiagnoseSettings(rounds=1, top=3, refit_iter=15, max_iter=30)


def _without_timing(report: dict) -> str:
    return json.dumps(strict_json({k: v for k, v in report.items() if k != "timing"}), sort_keys=True)


@pytest.fixture(scope="module")
def case():
    plant = chart("one_mass_friction_plant")
    train = record(plant, 3.0, 5, 0.02, **EXCITATION)
    val = record(plant, 2.0, 105, 0.02, **EXCITATION)
    serial = diagnose(chart("one_mass"), train, [val], SETTINGS, EFFECTS)
    return {"train": train, "val": val, "serial": serial}


def test_serial_run_refits_several_candidates_and_accepts_friction(case):
    report = case["serial"].report
    assert sum(1 for c in report["candidates"] if c.get("refitted")) >= 2  # something for the workers to share
    assert [a["effect"] for a in report["accepted"]] == ["friction"]
    assert len(report["timing"]["refit"]) == sum(1 for c in report["candidates"] if c.get("refitted"))


class _Recording(SerialExecutor):
    """A serial executor that records what it is asked to run."""

    def __init__(self):
        self.calls = []

    def map(self, fn, items):
        items = list(items)
        self.calls.append((fn, len(items)))
        return super().map(fn, items)


def test_the_refits_go_through_the_executor(case):
    """Every brief refit is a work unit handed to the executor: one map per refitted candidate (from the current
    fit, and far above the noise also from the chart as given), and a round's control (the chart refitted without
    any effect, from the same starts) in a last map. The screen's options that change the model go to it too:
    their simulations in one map a round, their full scores in another."""
    ex = _Recording()
    par = diagnose(chart("one_mass"), case["train"], [case["val"]], SETTINGS, EFFECTS, executor=ex)
    refitted = sum(1 for c in par.report["candidates"] if c.get("refitted"))
    assert len(par.report["rounds"]) == SETTINGS.rounds
    controls = sum(1 for r in par.report["rounds"] if r["control"] is not None)
    assert controls >= 1
    refits = [n for fn, n in ex.calls if fn is refit_unit]
    assert len(refits) == refitted + controls
    assert all(n in (1, 2) for n in refits) and 2 in refits
    scans = [n for fn, n in ex.calls if fn is scan_unit]
    scored = sum(1 for c in par.report["candidates"] if c["effect"] == "saturation" and c["score"] is not None)
    assert len(scans) == SETTINGS.rounds and sum(n for fn, n in ex.calls if fn is score_unit) == scored
    assert {fn for fn, _ in ex.calls} == {refit_unit, scan_unit, score_unit}
    assert _without_timing(par.report) == _without_timing(case["serial"].report)


def test_local_processes_give_the_same_report(case):
    with ProcessExecutor(2) as ex:
        par = diagnose(chart("one_mass"), case["train"], [case["val"]], SETTINGS, EFFECTS, executor=ex)
    assert _without_timing(par.report) == _without_timing(case["serial"].report)


def test_dask_local_cluster_gives_the_same_report(case):
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None)
    client = distributed.Client(cluster)
    try:
        par = diagnose(chart("one_mass"), case["train"], [case["val"]], SETTINGS, EFFECTS,
                       executor=DaskExecutor(client=client))
    finally:
        client.close()
        cluster.close()
    assert _without_timing(par.report) == _without_timing(case["serial"].report)
