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

ROOT = Path(__file__).resolve().parent.parent
CHART = ROOT / "diagrams" / "engine.yaml"
CSV = ROOT / "examples" / "data" / "engine_idle.csv"


@pytest.fixture(scope="module")
def record():
    return sd.read_csv(CSV)


def test_the_bundled_example_converges_where_ten_iterations_stop_gaining(record):
    r = sd.identify(CHART, record)
    assert r.converged is True and r.status == "small_cost_change" and r.optimizer.iterations < 1000
    c = np.array(r.optimizer.cost_history)
    limit = r.settings.converged_decrease / r.problem.n_residuals
    gained = (c[:-10] - c[10:]) / c[10:]  # the gain of the ten iterations ending at each iteration
    assert r.optimizer.iterations == int(np.argmax(gained < limit)) + 10
    assert not any("not converged" in w for w in r.warnings)


@pytest.mark.parametrize("limit, geodesic", [(100, 0.0), (10, None)])
def test_the_old_iteration_limit_was_not_a_minimum(record, limit, geodesic):
    """The README's first command used to stop at 100 iterations (plain LM steps): J1 was then outside the
    converged fit's own interval, and nothing but the status word said so. With geodesic acceleration 100
    iterations come close enough; 10 do not."""
    extra = {} if geodesic is None else {"lm_geodesic": geodesic}
    early = sd.identify(CHART, record, max_iter=limit, **extra)
    done = sd.identify(CHART, record)
    assert early.converged is False and early.status == "max_iter"
    assert any(w.startswith("not converged: the iteration limit") for w in early.warnings)
    lo, hi = done.parameters["J1"].ci95_noise  # the noise's interval: ci95 also carries the step's bias (N = 1)
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
