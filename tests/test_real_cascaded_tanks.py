"""Cascaded Tanks (real measurements, ../shared/data/real/cascaded_tanks): the plain Torricelli chart with
`f: sqrt`, identified on estimation.csv, scored on validation.csv from sample 5 (the benchmark's protocol).

Oracles: the validation record itself (a constant predictor scores its standard deviation, 2.10 V; the published
linear model 0.588 V), and the continuous RK4 simulation of the identified chart. Skipped when the data are absent.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.simulate.continuous import simulate_continuous

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "cascaded_tanks"

pytestmark = [
    pytest.mark.realdata,
    pytest.mark.skipif(not (DATA / "estimation.csv").exists(), reason="cascaded tanks data not present"),
]


def _example():
    spec = importlib.util.spec_from_file_location("cascaded_tanks_example", ROOT / "examples" / "cascaded_tanks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fitted():
    chart = sd.load_chart(ROOT / "diagrams" / "real" / "cascaded_tanks.yaml")
    result = sd.identify(chart, sd.read_csv(DATA / "estimation.csv"), starts=16, seed=0)
    return result


def test_plain_torricelli_model_scores_as_reported_in_the_readme(fitted):
    ex = _example()
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
    ex = _example()
    test = sd.read_csv(DATA / "validation.csv")
    y_net = ex.chart_simulation(fitted.chart, test)
    y_ode = simulate_continuous(fitted.chart, test.columns["u_V"][:, None], init={"y_V": test.columns["y_V"][0]},
                                substeps=20)[:, 0]
    assert np.linalg.norm(y_net - y_ode) / np.linalg.norm(y_ode) < 0.005


def test_diagnose_from_the_plain_chart_finds_the_overflow_and_the_sensor_offset():
    """The official protocol through diagnose (both levels' start fitted on the first 5 validation samples,
    scored from sample 5): the upper tank's overflow and the level sensor's zero offset are accepted, and the
    test RMSE falls below 0.40 V (measured 0.358 V; 0.490 V without the offset effect, 0.683 V before)."""
    d = sd.diagnose(ROOT / "diagrams" / "real" / "cascaded_tanks.yaml", sd.read_csv(DATA / "estimation.csv"),
                    [sd.read_csv(DATA / "validation.csv")], init_window=5)
    report = d.report
    accepted = [(a["effect"], a["at"]) for a in report["accepted"]]
    assert ("overflow", "x1dev") in accepted and ("sensor_offset", "y_V") in accepted, accepted
    last = [r for r in report["rounds"] if r["accepted"]][-1]
    assert last["validation_rms_after"] < 0.40
    assert report["rounds"][0]["validation_rms_before"] > 0.6
