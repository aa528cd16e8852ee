"""Quasi-online identification on the paper's experiment (docs/paper_experiment.md, issue 4), slow: about 2 min.

``sdnn identify --online --window 25000 --average 25000`` on the 100 s records of the virtual test bench, both
stages, all four starts, scored against the plant chart's truth by examples/paper_experiment.py (the friction
curve error, the acceptance limits). The paper met its targets quasi-online from three of its four starts;
with ``--starts 16`` ours meets them from both Table 2 starts.
"""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from paper_example import paper_example

from flowchart2sdnn.diagram.dump import with_values
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.document import fix_from_result
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify


@pytest.mark.slow
def test_quasi_online_meets_the_acceptance_from_three_of_four_starts(tmp_path):
    passed = _quasi_online(tmp_path, stage2_starts=1)
    assert passed[(1, 1)] and passed[(1, 2)], passed
    assert sum(passed.values()) >= 3, passed


@pytest.mark.slow
def test_quasi_online_multistart_meets_the_acceptance_from_both_table2_starts(tmp_path):
    passed = _quasi_online(tmp_path, stage2_starts=16)
    assert all(passed.values()), passed


def _quasi_online(tmp_path, stage2_starts: int) -> dict:
    """{(stage, start): passes} of quasi-online runs from the paper's starts; stage 2 with `stage2_starts`."""
    ex = paper_example()
    paths = ex.make_data(tmp_path, 100.0)
    plant = load_diagram(ex.CHARTS / "plant.yaml")
    truth = ex.truth_values(plant)
    settings = IdentifySettings(online=True, window=25000, average=25000)
    passed = {}
    best = None
    for stage, chart_name, starts in ((1, "engine.yaml", [{"J1": j} for j in ex.TABLE1_STARTS]),
                                      (2, "two_mass.yaml", [dict(zip(("J2", "d", "c"), s, strict=True))
                                                            for s in ex.TABLE2_STARTS])):
        chart = load_diagram(ex.CHARTS / chart_name)
        if stage == 2:
            chart, _ = fix_from_result(chart, best[1])
        data = ex.read_record(paths["engine" if stage == 1 else "plant"], chart)
        for k, init in enumerate(starts):
            n_starts = stage2_starts if stage == 2 else 1
            out = identify(with_values(chart, init, {}), data, None, replace(settings, starts=n_starts))
            r = out.result
            run = ex.Run(stage, ex.ONLINE, k + 1, init)
            run.values = {n: v["value"] for n, v in r["parameters"].items()}
            rms, peak = ex.curve_error(r["nonlinear"][f"MR{stage}"], ex.true_friction(plant, stage),
                                       data.columns[f"w{stage}"])
            run.curve_rms = 100.0 * rms / peak
            passed[(stage, k + 1)] = ex.acceptance(run, truth)
            if stage == 1:
                path = tmp_path / f"stage1_{k + 1}.json"
                path.write_text(json.dumps(r, allow_nan=False), encoding="utf-8")
                cost = r["online"]["mean_cost"]
                if best is None or cost < best[0]:  # stage 2 from the stage-1 run with the lowest error
                    best = (cost, path)
    return passed
