"""Cascaded Tanks (real measurements, ../shared/data/real/cascaded_tanks): the plain Torricelli chart with
`f: sqrt`, identified on estimation.csv, scored on validation.csv from sample 5 (the benchmark's protocol).

Oracles: the validation record itself (a constant predictor scores its standard deviation, 2.10 V; the published
linear model 0.588 V), and the continuous RK4 simulation of the identified chart. Skipped when the data are absent.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from example_module import load_example
from realdata import real_dataset

import flowchart2sdnn as sd
from flowchart2sdnn.simulate.continuous import simulate_continuous

ROOT = Path(__file__).resolve().parents[1]
DATA, pytestmark = real_dataset("cascaded_tanks", "estimation.csv", "cascaded tanks data not present")



@pytest.fixture(scope="module")
def fitted():
    chart = sd.load_chart(ROOT / "diagrams" / "real" / "cascaded_tanks.yaml")
    result = sd.identify(chart, sd.read_csv(DATA / "estimation.csv"), starts=16, seed=0)
    return result


def test_plain_torricelli_model_scores_as_reported_in_the_readme(fitted):
    ex = load_example("cascaded_tanks")
    test = sd.read_csv(DATA / "validation.csv")
    assert fitted.converged
    x10, tested = ex.validation_start(fitted.chart, test)
    rmse = ex.rmse_from(tested, test)
    spread = float(np.std(test.columns["y_V"][5:]))
    assert rmse < 0.35 * spread  # far better than a constant ...
    assert 0.6 < rmse < 0.75  # ... and the README's 0.67 V: the plain model lacks the overflow (linear: 0.588)
    assert not any(math.isnan(e.value) for e in fitted.parameters.values())


def test_identified_network_follows_the_continuous_chart_on_the_validation_input(fitted):
    """The identified chart's network (substeps 4, h = 1 s) against its RK4 simulation: the discretization is
    not what limits the model."""
    ex = load_example("cascaded_tanks")
    test = sd.read_csv(DATA / "validation.csv")
    y_net = ex.chart_simulation(fitted.chart, test)
    y_ode = simulate_continuous(fitted.chart, test.columns["u_V"][:, None], init={"y_V": test.columns["y_V"][0]},
                                substeps=20)[:, 0]
    assert np.linalg.norm(y_net - y_ode) / np.linalg.norm(y_ode) < 0.005


def test_diagnose_from_the_plain_chart_finds_the_overflow_and_the_linear_outflow():
    """The official protocol through diagnose (both levels' start fitted on the first 5 validation samples,
    scored from sample 5), three rounds: the upper tank's overflow routed into the lower one, the lower
    Torricelli outflow's linear term (`linear_term`) and the lower level's limit; the test RMSE falls below
    0.30 V (measured 0.271 V; 0.259 V after a fourth round, the upper outflow's linear term). Without the
    linear_term effect the three rounds take the pump's zero (`input_offset`) second and stop at 0.341 V,
    without both new effects the sensor offset and 0.357 V; 0.683 V before. Published: 0.306 V (CT-SUBNET), 0.191 V (physical grey-box with overflow)."""
    d = sd.diagnose(ROOT / "diagrams" / "real" / "cascaded_tanks.yaml", sd.read_csv(DATA / "estimation.csv"),
                    [sd.read_csv(DATA / "validation.csv")], init_window=5)
    report = d.report
    accepted = [(a["effect"], a["at"]) for a in report["accepted"]]
    assert ("overflow", "x1dev") in accepted and ("linear_term", "r2") in accepted, accepted
    assert next(a["label"] for a in report["accepted"] if a["effect"] == "overflow").endswith("->y_V")  # routed
    last = [r for r in report["rounds"] if r["accepted"]][-1]
    assert last["validation_rms_after"] < 0.30
    assert report["rounds"][0]["validation_rms_before"] > 0.6


def test_the_hand_written_physical_chart_beats_ct_subnet():
    """diagrams/real/cascaded_tanks_physical.yaml (both overflows, the share of the upper one that reaches the
    lower tank, sensor zero and 10 V limit, linear + Torricelli outflows, pump zero, one-sample dead time),
    identified from its init by the same protocol: test RMSE below 0.25 V (published CT-SUBNET 0.306 V, physical
    grey-box 0.191 V). Measured: 0.242 V with the default bounds in the box and a trust radius, which reach a lower
    estimation cost (10.76, RMSE 0.145 V) than the bound transform's geodesic steps (11.42, 0.149 V; test 0.215 V,
    `lm_bounds="transform"`): a deeper minimum of the estimation record that validates worse. Without the pump's
    zero offset the same fit gives 0.38 V (benchmarks/cascaded_tanks_ablation.py)."""
    result = sd.identify(ROOT / "diagrams" / "real" / "cascaded_tanks_physical.yaml",
                         sd.read_csv(DATA / "estimation.csv"), sd.read_csv(DATA / "validation.csv"),
                         init_window=5, starts=1, seed=0)
    assert result.fit.validation.rms["y_V"] < 0.25
    assert 0.0 < result.parameters["g1"].value < 1.0  # part of the overflow reaches the lower tank, not all
