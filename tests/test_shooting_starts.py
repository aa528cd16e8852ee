"""--shooting-starts free: multiple shooting fits the measured states' segment starts too (identify.shooting.multiple).

Oracles: central finite differences of the multiple-shooting residual (the measured starts' columns are
differentiated through the history like the unmeasured ones'), and the default `data` starts: where the free
measured starts sit on the data's samples the two residuals' output rows agree exactly.
"""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from flowchart2sdnn.cli import main
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.shooting.segmented import Segmented
from tests.test_shooting import COULOMB, COULOMB_PLANT, _data, _fd


def _problem(noise=0.01):
    return build_problem(load_diagram(COULOMB), _data(COULOMB_PLANT, 120, 1, ["w1", "w2"], noise=noise))


def test_free_starts_include_the_measured_states_and_their_jacobian_matches_differences():
    problem = _problem()
    seg = Segmented(problem, 25, 3.0, starts="free")
    assert set(seg.free_names) == {"w1", "dphi", "w2"} and not seg.measured
    assert seg.n_x == seg.n_theta + 4 * 3
    rng = np.random.default_rng(2)
    x = seg.start(problem.compiled.theta0() * 1.1)
    x[seg.n_theta:] += 0.01 * rng.standard_normal(seg.n_x - seg.n_theta)
    e, J = seg.fun(x)
    J = J.toarray() if hasattr(J, "toarray") else J
    np.testing.assert_array_equal(e, seg.residual(x))
    Jfd = _fd(seg.residual, x)
    scale = np.maximum(np.abs(J).max(axis=0), 1e-12)
    assert (np.abs(J - Jfd).max(axis=0) / scale).max() < 1e-6


def test_free_measured_starts_begin_on_the_data():
    problem = _problem()
    data, free = Segmented(problem, 25, 1.0), Segmented(problem, 25, 1.0, starts="free")
    theta = problem.compiled.theta0()
    xd, xf = data.start(theta), free.start(theta)
    assert free.output_cost(xf) == data.output_cost(xd)
    targets = problem.segments[0].targets
    j = free.free_names.index("w2")
    assert xf[free.n_theta + j] == targets[24, list(problem.compiled.output_names).index("w2")]


def test_cli_records_the_starts(tmp_path):
    problem_csv = tmp_path / "d.csv"
    q, plant = 600, load_diagram(COULOMB_PLANT)
    rng = np.random.default_rng(3)
    from flowchart2sdnn.simulate.continuous import simulate_continuous
    from flowchart2sdnn.simulate.excitation import aprbs
    u = aprbs(q, plant.sample_time, rng, (-3.0, 3.0))
    y = simulate_continuous(plant, u[:, None]) + 0.01 * rng.standard_normal((q, 2))
    np.savetxt(problem_csv, np.column_stack([np.arange(q) * plant.sample_time, u, y]), delimiter=",",
               header="time,M1,w1,w2", comments="")
    out = tmp_path / "r.json"
    res = CliRunner().invoke(main, ["identify", str(problem_csv), "--diagram", str(COULOMB), "-o", str(out),
                                    "--shooting", "100", "--shooting-starts", "free", "--no-floor-bias", "--quiet"])
    assert res.exit_code == 0, res.output
    result = json.loads(out.read_text())
    assert result["shooting"]["starts"] == "free"
    bad = CliRunner().invoke(main, ["identify", str(problem_csv), "--diagram", str(COULOMB), "-o", str(out),
                                    "--shooting-starts", "both", "--force"])
    assert bad.exit_code == 2
