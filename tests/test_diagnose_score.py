"""The score test: the predicted cost decrease of one Gauss-Newton step, against independent oracles.

Oracles: scipy's least squares for the GN decrease; central finite differences of plain simulations for the
whole screen (patch -> compile -> RTRL -> Gram -> projection).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from diagnose_bench import chart, record
from scipy.linalg import lstsq

from flowchart2sdnn.diagnose.effects import Damping, DeadTime, Friction
from flowchart2sdnn.diagnose.graph import Place, speeds
from flowchart2sdnn.diagnose.score import Candidate, gauss_newton_decrease, new_quantities, screen, screened
from flowchart2sdnn.identify.offline.problem import build_problem


def _lstsq_decrease(J, e):
    d = lstsq(J, e)[0]
    r = e - J @ d
    return 0.5 * (e @ e - r @ r)


def test_gn_decrease_equals_the_least_squares_step():
    rng = np.random.default_rng(1)
    J = rng.standard_normal((400, 5)) * np.array([1e-3, 1.0, 50.0, 2.0, 1e4])  # badly scaled columns
    e = rng.standard_normal(400)
    dec, rank = gauss_newton_decrease(J, e)
    assert rank == 5
    assert dec == pytest.approx(_lstsq_decrease(J, e), rel=1e-9)


def test_gn_decrease_ignores_zero_and_repeated_columns():
    rng = np.random.default_rng(2)
    J = rng.standard_normal((300, 3))
    e = rng.standard_normal(300)
    Jx = np.column_stack([J, np.zeros(300), 2.5 * J[:, 1]])
    dec, rank = gauss_newton_decrease(Jx, e)
    assert rank == 3
    assert dec == pytest.approx(_lstsq_decrease(J, e), rel=1e-9)


def test_a_quantity_on_its_lower_bound_cannot_step_down():
    rng = np.random.default_rng(3)
    J = rng.standard_normal((500, 2))
    e = J @ np.array([1.0, -2.0]) + 0.01 * rng.standard_normal(500)  # the second quantity wants to go down
    free, _ = gauss_newton_decrease(J, e)
    held, rank = gauss_newton_decrease(J, e, sign=np.array([0.0, 1.0]))
    assert rank == 1 and held == pytest.approx(_lstsq_decrease(J[:, :1], e), rel=1e-9) and held < free
    up, _ = gauss_newton_decrease(J, -e, sign=np.array([0.0, 1.0]))  # now it wants to go up: allowed
    assert up == pytest.approx(free, rel=1e-9)


# ------------------------------------------------------------------------------------------------ screen
@pytest.fixture(scope="module")
def setup():
    data = record(chart("one_mass_friction_plant"), 2.0, seed=4, noise=0.02)
    base = chart("one_mass")  # at its (wrong) initial values: the score does not need a converged fit
    problem = build_problem(base, data)
    (speed,) = speeds(base)
    cands = [Candidate(Friction(), speed, 0.3, base), Candidate(Damping(), speed, None, base),
             Candidate(DeadTime(), Place("F", "input"), 2, base), Candidate(DeadTime(), Place("F", "input"), 5, base)]
    return data, base, problem, cands


def _fd_jacobian(problem, x):
    cols = []
    for i in range(x.size):
        h = 1e-6 * max(1.0, abs(x[i]))
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        cols.append(-(problem.residual(xp) - problem.residual(xm)) / (2 * h))  # d yhat = -d e
    return np.column_stack(cols)


def _oracle_predicted_cost(diagram, data):
    p = build_problem(diagram, data)
    x = p.compiled.theta0()
    e = p.residual(x)
    J = _fd_jacobian(p, x)
    keep = np.linalg.norm(J, axis=0) > 0
    return 0.5 * e @ e - _lstsq_decrease(J[:, keep], e)


def test_every_score_matches_finite_differences_and_least_squares(setup):
    data, base, problem, cands = setup
    scr = screen(cands, problem, data)
    base_gn = _oracle_predicted_cost(base, data)
    by = {(s.candidate.name, s.candidate.label): s for s in scr.scores}
    assert set(by) == {("friction", ""), ("damping", ""), ("dead_time", "n=2"), ("dead_time", "n=5")}
    for (name, label), s in by.items():
        if name == "damping":
            continue  # on its lower bound: checked below
        # the chart the candidate is scored on (a dead time's tau held at its n samples: score.screened)
        oracle = base_gn - _oracle_predicted_cost(screened(s.candidate), data)
        assert s.score == pytest.approx(oracle, rel=2e-4, abs=1e-6 * scr.baseline.cost), (name, label)


def test_a_candidate_the_chart_already_has_scores_zero(setup):
    # the chart has viscous friction b*v: a second viscous gain adds nothing beyond it (restricted to the
    # new column alone, a GN step would predict a large decrease - the look-alike the full step rules out)
    data, base, problem, cands = setup

    @dataclasses.dataclass(frozen=True)
    class FreeDamping(Damping):  # without the lower bound, so that only the collinearity can make it zero
        def patch(self, diagram, place, option=None):
            d = Damping.patch(self, diagram, place, option)
            return dataclasses.replace(d, parameters=tuple(dataclasses.replace(p, min=None)
                                                           for p in d.parameters))

    scr = screen([Candidate(FreeDamping(), cands[1].place, None, base)], problem, data)
    (s,) = scr.scores
    assert s.scored and s.dof == 0 and abs(s.score) < 1e-8 * scr.baseline.cost
    # the new column alone would promise a large decrease
    p = build_problem(s.candidate.diagram, data)
    e, J = p.fun(p.compiled.theta0())
    alone, _ = gauss_newton_decrease(J[:, [p.names.index("b_v")]], e)
    assert alone > 1e-3 * scr.baseline.cost


def test_the_joint_pass_gives_each_candidate_its_own_score(setup):
    data, base, problem, cands = setup
    together = {s.candidate.title(): s.score for s in screen(cands, problem, data).scores}
    for c in cands:
        (alone,) = screen([c], problem, data).scores
        assert alone.score == pytest.approx(together[c.title()], rel=1e-8, abs=1e-9)


def test_scores_are_ranked_and_significance_reported(setup):
    data, base, problem, cands = setup
    scr = screen(cands, problem, data)
    scored = [s.score for s in scr.scores if s.scored]
    assert scored == sorted(scored, reverse=True)
    best = scr.scores[0]
    assert best.candidate.name == "friction" and best.p_value < 1e-6 and best.dof >= 1
    assert scr.passes["jacobian"] >= 2


def test_new_quantities_lists_parameters_and_curve_weights(setup):
    data, base, problem, cands = setup
    assert new_quantities(base, cands[1].diagram) == ("b_v",)
    names = new_quantities(base, cands[0].diagram)
    # the friction curve is the tanh basis: its output weights are learned, its fixed slopes are not
    assert {f"fric_v.v{i}" for i in range(1, 8)} <= set(names) and not any(".a" in n or ".b" in n for n in names)
    p = build_problem(cands[0].diagram, data)
    assert set(names) == set(p.names) - set(problem.names)


def test_the_score_carries_its_least_squares_step(setup):
    """The step a score stands for (Score.step, what choice.one_step_relevant simulates) is the least-squares step
    of the patched chart's finite-difference Jacobian (minimum norm where two columns are one: damping's b_v
    beside the chart's b)."""
    data, _, problem, cands = setup
    (s,) = screen([cands[1]], problem, data).scores
    p = build_problem(s.candidate.diagram, data)
    x = p.compiled.theta0()
    J = _fd_jacobian(p, x)
    oracle = dict(zip(p.names, lstsq(J, p.residual(x), lapack_driver="gelsd")[0], strict=True))
    step = dict(s.step)
    assert set(step) == set(oracle)
    for name, value in oracle.items():
        assert step[name] == pytest.approx(value, rel=1e-4, abs=1e-9), name


def test_one_step_point_simulates_the_step(setup):
    """one_step_point moves the patched chart by the step and free-runs it: on the training record itself both its
    training cost and its validation RMS are the problem's own residual at theta0 + step, and the step lowers it."""
    from flowchart2sdnn.diagnose.fitting import DiagnoseSettings, one_step_point

    data, _, problem, cands = setup
    (s,) = screen([cands[1]], problem, data).scores
    cost, rms = one_step_point(s.candidate.diagram, s.step, [data], [(data, 0)], DiagnoseSettings())
    p = build_problem(s.candidate.diagram, data)
    x = p.compiled.theta0() + np.array([dict(s.step)[n] for n in p.names])
    e = p.residual(x)
    assert cost == pytest.approx(0.5 * e @ e, rel=1e-12)
    assert rms == pytest.approx(np.sqrt(e @ e / e.size), rel=1e-12)
    e0 = p.residual(p.compiled.theta0())
    assert rms < 0.5 * np.sqrt(e0 @ e0 / e0.size)


def test_a_column_the_chart_already_has_is_not_significant(setup):
    """Damping at v adds b_v beside the chart's own b: the same column. Its score is 0, and so must its statistic
    be (what is left of the column beyond b is round-off, whose own variance must not normalise it)."""
    data, _, problem, cands = setup
    (s,) = screen([cands[1]], problem, data).scores
    assert s.score == pytest.approx(0.0, abs=1e-9 * problem.n_residuals)
    assert s.statistic == 0.0 and s.p_value == 1.0
