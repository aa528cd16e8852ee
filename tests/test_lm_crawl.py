"""The crawl rule: a fit at the noise floor that gains less than one unit of -2 log-likelihood over 100 iterations
has converged (fit.lm.LMOptions.crawl_*, identify.settings.CRAWL_*).

Oracles: the cost history of the same fit run without the rule, read independently of the trainer's code (the
rule must stop exactly where that history first meets it, at the same iterates), and the known noise of a
synthetic record from the continuous plant (the rule's cost ceiling)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.api import dataset_from_frame
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.identify.offline.optimize import lm_options
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.settings import CRAWL_DECREASE, CRAWL_ITERATIONS, CRAWL_NOISE, IdentifySettings
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parent.parent
NOISE = np.random.default_rng(7).normal(0.0, 0.1, 50)  # residuals no quantity can explain: the floor


def rosenbrock_on_a_floor(p):
    """Rosenbrock's valley (a crawl for plain LM) beside 50 fixed residuals."""
    e = np.concatenate([[10 * (p[1] - p[0] ** 2), 1 - p[0]], NOISE])
    J = np.zeros((e.size, 2))
    J[0] = [20 * p[0], -10.0]  # J = d yhat / dx = -de/dx
    J[1] = [1.0, 0.0]
    return e, J


WINDOW = 4


def _fit(**crawl):
    return levenberg_marquardt(rosenbrock_on_a_floor, [-1.2, 1.0], ["x1", "x2"],
                               options=LMOptions(max_iter=200, crawl_iterations=WINDOW, **crawl))


def _first_crawl(costs: np.ndarray, fraction: float, ceiling: float) -> int | None:
    for k in range(WINDOW, len(costs)):
        if costs[k] <= ceiling and (costs[k - WINDOW] - costs[k]) / costs[k] < fraction:
            return k
    return None


@pytest.mark.parametrize("fraction", [0.3, 0.2, 0.1])
def test_the_rule_stops_where_the_plain_fit_first_crawls(fraction):
    plain = _fit()
    costs = np.array(plain.cost_history)
    k = _first_crawl(costs, fraction, np.inf)
    assert k is not None and k < plain.iterations, "the bench must reach the rule before the plain fit stops"
    ruled = _fit(crawl_decrease=fraction)
    assert ruled.converged and ruled.status == "small_cost_change"
    assert "a crawl at the noise floor" in ruled.message
    assert ruled.iterations == k
    np.testing.assert_array_equal(ruled.cost_history, costs[:k + 1])  # the same iterates up to the stop


def test_above_the_ceiling_the_rule_waits():
    plain = _fit()
    costs = np.array(plain.cost_history)
    first = _first_crawl(costs, 0.3, np.inf)
    ceiling = float(costs[first + 1])  # the first window that crawls lies above it
    k = _first_crawl(costs, 0.3, ceiling)
    assert k is not None and first < k < plain.iterations
    ruled = _fit(crawl_decrease=0.3, crawl_cost=ceiling)
    assert ruled.iterations == k
    below_all = _fit(crawl_decrease=0.3, crawl_cost=0.5 * float(costs.min()))
    assert below_all.iterations == plain.iterations and below_all.status == plain.status


@pytest.mark.parametrize("bad", [{"crawl_decrease": -1.0}, {"crawl_iterations": 0}, {"crawl_cost": float("nan")}])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError, match="crawl"):
        LMOptions(**bad)


def test_identify_puts_the_ceiling_at_the_records_noise():
    """The ceiling is the cost of CRAWL_NOISE x the noise RMS over the record, the noise being the one the
    continuous plant's record was drawn with (0.01 rad/s)."""
    plant = load_diagram(ROOT / "diagrams" / "two_mass_coulomb_plant.yaml")
    chart = load_diagram(ROOT / "diagrams" / "two_mass_coulomb.yaml")
    frame = excite(plant, ExcitationSettings(seconds=5.0, seed=3, noise_std=0.01))
    data = dataset_from_frame(frame, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names))
    problem = build_problem(chart, data, seed=1)
    opts = lm_options(IdentifySettings(seed=1), problem)
    m = sum(s.targets.size for s in problem.segments)
    assert opts.crawl_cost == pytest.approx(0.5 * CRAWL_NOISE ** 2 * 0.01 ** 2 * m, rel=0.1)
    assert opts.crawl_iterations == CRAWL_ITERATIONS
    assert opts.crawl_decrease * problem.n_residuals == pytest.approx(CRAWL_DECREASE)


def test_identify_says_when_the_crawl_rule_stopped_it(monkeypatch):
    """The rule made to fire as soon as the fit is at the floor (3 iterations, any gain): the result says so."""
    import importlib

    identify = importlib.import_module("flowchart2sdnn.identify.offline.run").identify
    optimize = importlib.import_module("flowchart2sdnn.identify.offline.optimize")  # where lm_options reads the rule

    plant = load_diagram(ROOT / "diagrams" / "two_mass_coulomb_plant.yaml")
    chart = load_diagram(ROOT / "diagrams" / "two_mass_coulomb.yaml")
    frame = excite(plant, ExcitationSettings(seconds=5.0, seed=3, noise_std=0.01))
    data = dataset_from_frame(frame, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names))
    plain = identify(chart, data, settings=IdentifySettings(seed=1))
    assert plain.converged and not any("creeping" in w for w in plain.warnings)
    monkeypatch.setattr(optimize, "CRAWL_ITERATIONS", 3)
    monkeypatch.setattr(optimize, "CRAWL_DECREASE", 1e9)
    ruled = identify(chart, data, settings=IdentifySettings(seed=1))
    assert ruled.converged and ruled.status == "small_cost_change"
    assert [w for w in ruled.warnings if w.startswith("converged at the noise floor while still creeping (")]
    assert ruled.optimizer.iterations < plain.optimizer.iterations
