"""A fit is never silent about not converging: it stops when ten iterations together gain nothing the data could
show, reports `converged`, and a fit stopped by the iteration limit says so in RESULT.json, its warnings and
on stderr. The oracle is the cost history itself, read independently of the trainer's code."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.fit.effective import effective_samples
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.identify.settings import NEGLIGIBLE_GAIN

ROOT = Path(__file__).resolve().parent.parent
CHART = ROOT / "diagrams" / "engine.yaml"
CSV = ROOT / "examples" / "data" / "engine_idle.csv"


@pytest.fixture(scope="module")
def record():
    return sd.read_csv(CSV)


def test_the_bundled_example_stops_where_what_is_left_to_gain_is_negligible(record):
    """The oracle: at the returned point, the undamped Gauss-Newton step solved by numpy's lstsq on (J, e) from
    the problem itself, in units of -2 log-likelihood at the residual's variance over its effective samples;
    and a fit run on to a far tighter end (the rule off, 100 more iterations) moves J1 by less than 0.32 of its
    standard error, the rule's promise."""
    r = sd.identify(CHART, record, floor_bias=False)
    assert r.converged is True and r.status == "negligible_gain" and r.optimizer.iterations < 60
    p = r.problem
    e, J = p.fun(np.asarray(r.x))
    step, *_ = np.linalg.lstsq(J, e, rcond=None)
    predicted = float(np.sum((J @ step) ** 2))  # the SSE's fall the Gauss-Newton model predicts
    m = effective_samples(e, len(p.compiled.output_names))
    assert predicted / (float(e @ e) / m) < NEGLIGIBLE_GAIN
    c = np.array(r.optimizer.cost_history)
    assert (c[-2] - c[-1]) / (c[-1] / m) < NEGLIGIBLE_GAIN
    assert not any("not converged" in w for w in r.warnings)
    lo, hi = p.bounds()
    on = levenberg_marquardt(p.fun, np.asarray(r.x), p.names, lo, hi,
                             LMOptions(max_iter=100, min_grad=0.0, min_rel_step=0.0, scale="jac"))
    assert on.cost <= c[-1]
    j1 = p.names.index("J1")
    assert abs(on.x[j1] - r.parameters["J1"].value) < 0.32 * r.parameters["J1"].stderr


def test_a_fit_stopped_by_the_iteration_limit_is_not_a_minimum(record):
    """Three iterations from the chart's init (J1 0.6 against about 0.19): the status, the warning, and J1
    outside the converged fit's own interval."""
    early = sd.identify(CHART, record, max_iter=3)
    done = sd.identify(CHART, record)
    assert early.converged is False and early.status == "max_iter"
    assert any(w.startswith("not converged: the iteration limit") for w in early.warnings)
    lo, hi = done.parameters["J1"].ci95
    assert not lo <= early.parameters["J1"].value <= hi
    assert done.fit.train.cost < early.fit.train.cost


def test_an_unconverged_fit_says_so_in_the_file_and_on_stderr(tmp_path):
    out = tmp_path / "r.json"
    res = CliRunner().invoke(main, ["identify", str(CSV), "--diagram", str(CHART), "--max-iter", "5", "--quiet",
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "warning: not converged: the iteration limit" in res.stderr
    doc = json.loads(out.read_text())
    assert doc["converged"] is False and doc["status"] == "max_iter"
    assert any(w.startswith("not converged") for w in doc["warnings"])


def test_quasi_online_and_fixed_charts_make_no_convergence_claim(record, tmp_path):
    short = record.slice(0, 3000)
    online = sd.identify(CHART, short, online=True, window=1000, average=500)
    assert online.converged is None and json.loads(online.to_json())["converged"] is None
