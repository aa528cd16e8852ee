"""--shooting L: multiple shooting, then single shooting over the whole record (identify.shooting.multiple).

Oracles: central finite differences of the multiple-shooting residual (the Jacobian, including the columns of
the free segment starts that the RTRL kernel differentiates through the history), scipy's least_squares on
the same residual, and a continuous plant (RK4) whose parameters the fit must find.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import sparse
from scipy.optimize import least_squares

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.steps import gram
from flowchart2sdnn.identify.offline.initstate import state_neurons
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.identify.shooting import segmented
from flowchart2sdnn.identify.shooting.multiple import stage_lengths
from flowchart2sdnn.identify.shooting.segmented import Segmented
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

ROOT = Path(__file__).resolve().parent.parent

COULOMB = ROOT / "diagrams" / "two_mass_coulomb.yaml"
COULOMB_PLANT = ROOT / "diagrams" / "two_mass_coulomb_plant.yaml"
LEARNED = ROOT / "tests" / "data" / "two_mass_euler.yaml"  # diagrams/two_mass.yaml at N = 1
LEARNED_PLANT = ROOT / "diagrams" / "two_mass_plant.yaml"


def _data(plant_path, q: int, seed: int, outputs, noise: float = 0.0):
    plant = load_diagram(plant_path)
    rng = np.random.default_rng(seed)
    u = aprbs(q, plant.sample_time, rng, (-3.0, 3.0))
    y = simulate_continuous(plant, u[:, None]) + noise * rng.standard_normal((q, len(plant.output_names)))
    frame = {"time": np.arange(q) * plant.sample_time, "M1": u}
    frame.update({n: y[:, i] for i, n in enumerate(plant.output_names)})
    return sd.dataset_from_frame(frame, time="time", inputs=["M1"], outputs=list(outputs))


def _fd(fun, x):
    cols = []
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(x[i]))
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        cols.append((fun(down) - fun(up)) / (2 * h))  # d yhat = -d e
    return np.column_stack(cols)


def test_history_sensitivities_match_finite_differences():
    c = CompiledNetwork(compile_diagram(load_diagram(COULOMB)).network)
    states = np.array([k for k, _ in state_neurons(c)], dtype=np.int64)
    rng = np.random.default_rng(0)
    u = rng.standard_normal((40, 1))
    theta = c.theta0()
    h = c.initial_history(None) + 0.1 * rng.standard_normal(c.flat.n_neurons)
    y, dy = c.jacobian(theta, u, history=h, states=states)
    y0, dy0 = c.jacobian(theta, u, history=h)
    assert np.array_equal(y[:, :2], y0) and np.array_equal(dy[:, :2, :len(theta)], dy0)  # theta part unchanged
    assert np.array_equal(c.simulate(theta, u, history=h, states=states), y)
    for j, k in enumerate(states):
        up, down = h.copy(), h.copy()
        up[k] += 1e-6
        down[k] -= 1e-6
        fd = (c.simulate(theta, u, history=up, states=states) - c.simulate(theta, u, history=down, states=states))
        np.testing.assert_allclose(dy[:, :, len(theta) + j], fd / 2e-6, atol=1e-7 * np.abs(fd / 2e-6).max())


@pytest.mark.parametrize("chart, plant, outputs, free, tol", [
    (COULOMB, COULOMB_PLANT, ["w1", "w2"], ("dphi",), 1e-6),
    (LEARNED, LEARNED_PLANT, ["w2"], ("w1", "dphi"), 1e-4),  # steep tanh curves: the differences' own error
])
@pytest.mark.parametrize("dense_fraction", [0.25, 2.0])  # the trainer gets J dense / sparse (CSR)
def test_the_combined_jacobian_matches_central_differences(chart, plant, outputs, free, tol, dense_fraction,
                                                             monkeypatch):
    monkeypatch.setattr(segmented, "DENSE_FRACTION", dense_fraction)
    problem = build_problem(load_diagram(chart), _data(plant, 120, 1, outputs))
    seg = Segmented(problem, 25, 3.0)
    assert seg.free_names == free and len(seg.pieces) == 5 and seg.n_x == seg.n_theta + 4 * len(free)
    rng = np.random.default_rng(1)
    x = seg.start(problem.compiled.theta0() * 1.1)
    x[seg.n_theta:] += 0.01 * rng.standard_normal(seg.n_x - seg.n_theta)
    e, J = seg.fun(x)
    assert sparse.issparse(J) == (dense_fraction > 1)
    J = J.toarray() if sparse.issparse(J) else J
    np.testing.assert_array_equal(e, seg.residual(x))
    assert e.size == 119 * len(outputs) + 4 * len(free)  # zoh: row 0 is the initial state

    Jfd = _fd(seg.residual, x)
    scale = np.maximum(np.abs(J).max(axis=0), 1e-12)
    assert (np.abs(J - Jfd).max(axis=0) / scale).max() < tol


def test_segments_on_threads_give_the_same_residual_and_jacobian():
    problem = build_problem(load_diagram(COULOMB), _data(COULOMB_PLANT, 400, 4, ["w1", "w2"], noise=0.01))
    one, two = Segmented(problem, 50, 1.0), Segmented(problem, 50, 1.0, threads=2)
    x = one.start(problem.compiled.theta0())
    (e1, J1), (e2, J2) = one.fun(x), two.fun(x)
    np.testing.assert_array_equal(e1, e2)
    np.testing.assert_array_equal(J1.toarray() if sparse.issparse(J1) else J1,
                                  J2.toarray() if sparse.issparse(J2) else J2)
    np.testing.assert_array_equal(one.residual(x), two.residual(x))


def test_pieces_in_one_kernel_call_equal_one_call_per_piece():
    c = CompiledNetwork(compile_diagram(load_diagram(COULOMB)).network)
    states = np.array([k for k, _ in state_neurons(c)], dtype=np.int64)
    rng = np.random.default_rng(2)
    u = rng.standard_normal((90, 1))
    theta = c.theta0() * 1.05
    first, last = np.array([0, 30, 55, 60]), np.array([30, 55, 60, 90])
    hist = c.initial_history(None) + 0.1 * rng.standard_normal((4, c.flat.n_neurons))
    y, dy = c.run_pieces(theta, u, first, last, hist, states, with_jac=True)
    ys, _ = c.run_pieces(theta, u, first, last, hist, states)
    for a, b, h in zip(first, last, hist, strict=True):
        y1, dy1 = c.jacobian(theta, u[a:b], history=h, states=states)
        np.testing.assert_array_equal(y[a:b], y1)
        np.testing.assert_array_equal(dy[a:b], dy1)
        np.testing.assert_array_equal(ys[a:b], c.simulate(theta, u[a:b], history=h, states=states))
    with pytest.raises(ValueError, match="pieces must be"):
        c.run_pieces(theta, u, [0, 50], [50, 91], hist[:2])
    with pytest.raises(ValueError, match="histories must be"):
        c.run_pieces(theta, u, first, last, hist[:3])


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("dense_fraction", [0.25, 2.0])  # the trainer gets J dense / sparse (CSR)
def test_two_records_jacobian_matches_central_differences(threads, dense_fraction, monkeypatch):
    monkeypatch.setattr(segmented, "DENSE_FRACTION", dense_fraction)
    chart = load_diagram(COULOMB)
    problem = build_problem(chart, _data(COULOMB_PLANT, 130, 5, ["w1", "w2"]),
                            more=[_data(COULOMB_PLANT, 70, 6, ["w1", "w2"])])
    seg = Segmented(problem, 30, 2.0, threads=threads)
    # 129 rows: 30, 30, 30, 30, 9; 69 rows: 30, 30, 9; a record's first segment starts from its own start
    assert [(p.record, p.b - p.a) for p in seg.pieces] == [(0, 30)] * 4 + [(0, 9), (1, 30), (1, 30), (1, 9)]
    assert seg.n_x == seg.n_theta + 6
    rng = np.random.default_rng(3)
    x = seg.start(problem.compiled.theta0() * 0.9)
    x[seg.n_theta:] += 0.01 * rng.standard_normal(seg.n_x - seg.n_theta)
    e, J = seg.fun(x)
    assert sparse.issparse(J) == (dense_fraction > 1)
    if sparse.issparse(J):  # the blocks handed to the trainer's JᵀJ are J's own columns (scipy's slices)
        P = seg.n_theta
        np.testing.assert_array_equal(J.wide, J[:, :P].toarray())
        np.testing.assert_array_equal(J.rest.toarray(), J[:, P:].toarray())
        dense = J.toarray()
        np.testing.assert_allclose(gram(J), dense.T @ dense, rtol=1e-12, atol=1e-12 * np.abs(dense).max() ** 2)
    J = J.toarray() if sparse.issparse(J) else J
    np.testing.assert_array_equal(e, seg.residual(x))
    assert e.size == (129 + 69) * 2 + 6
    Jfd = _fd(seg.residual, x)
    scale = np.maximum(np.abs(J).max(axis=0), 1e-12)
    assert (np.abs(J - Jfd).max(axis=0) / scale).max() < 1e-6


def test_our_lm_and_scipy_reach_the_same_multiple_shooting_minimum():
    problem = build_problem(load_diagram(COULOMB), _data(COULOMB_PLANT, 400, 4, ["w1", "w2"], noise=0.01))
    seg = Segmented(problem, 100, 1.0)
    x0 = seg.start(problem.compiled.theta0())
    ours = levenberg_marquardt(seg.fun, x0, seg.names, options=LMOptions(max_iter=300, scale="jac", tau=1e-3,
                                                                         min_rel_cost_change=1e-12))
    theirs = least_squares(seg.residual, x0, jac=lambda x: -seg.fun(x)[1], method="trf", x_scale="jac",
                           xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert ours.cost == pytest.approx(theirs.cost, rel=1e-5)
    np.testing.assert_allclose(ours.x[:seg.n_theta], theirs.x[:seg.n_theta], rtol=1e-3, atol=1e-6)


def test_identify_with_shooting_finds_the_plant_and_ends_in_single_shooting():
    data = _data(COULOMB_PLANT, 1200, 2, ["w1", "w2"], noise=0.0)
    chart = load_diagram(COULOMB)
    r = identify(chart, data, shooting=100)
    stages = r.extra["shooting"]["stages"]
    assert [s["length"] for s in stages] == [100, 400, 1199] and stages[-1]["free_states"] == 0
    assert [s["weight"] for s in stages[:-1]] == [1.0, 10.0]
    # the result is the ordinary simulation error of the whole record at the reported point
    assert r.fit.train.cost == pytest.approx(stages[-1]["cost"], rel=1e-9)
    assert r.converged
    truth = {p.name: p.init for p in load_diagram(COULOMB_PLANT).parameters}
    for name in ("J2", "c"):
        assert r.parameters[name].value == pytest.approx(truth[name], rel=0.02)
    assert "shooting" not in identify(chart, data, max_iter=3, shooting="off").extra  # off: no new key
    # the default is auto, which leaves this stable chart single shooting (a moved start decays) and says so
    auto = identify(chart, data, max_iter=3).extra["shooting"]
    assert auto["requested"] == "auto" and auto["auto"]["chose"] == "off" and auto["stages"] == []


def test_segments_on_two_threads_give_the_same_fit():
    data = _data(COULOMB_PLANT, 1200, 2, ["w1", "w2"], noise=0.01)
    chart = load_diagram(COULOMB)
    one, two = (identify(chart, data, shooting=100, max_iter=30, floor_bias=False, threads=t) for t in (1, 2))
    assert [p.value for p in one.parameters.values()] == [p.value for p in two.parameters.values()]
    assert one.extra["shooting"]["stages"] == two.extra["shooting"]["stages"]
    with pytest.raises(ValueError, match="threads must be a whole number >= 1"):
        IdentifySettings(threads=0)


def test_stage_lengths():
    assert stage_lengths(100, 30000) == [100, 400, 1600, 6400, 25600]
    assert stage_lengths(500, 400) == []  # one segment per record: single shooting only


@pytest.mark.parametrize("value", [1, 0, True, "Auto", "10", 2.5])  # "auto" itself is a value (shootauto)
def test_bad_settings_are_refused(value):
    with pytest.raises(ValueError, match="shooting must be"):
        IdentifySettings(shooting=value)


def test_too_many_segments_is_one_error():
    problem = build_problem(load_diagram(COULOMB), _data(COULOMB_PLANT, 600, 1, ["w1", "w2"]))
    with pytest.raises(SdnnError, match="at most 256"):
        Segmented(problem, 2, 1.0)


def test_cli(tmp_path):
    data = _data(COULOMB_PLANT, 400, 3, ["w1", "w2"])
    csv = tmp_path / "d.csv"
    table = np.column_stack([np.arange(data.n_rows) * load_diagram(COULOMB).sample_time]
                            + [data.columns[c] for c in ("M1", "w1", "w2")])
    np.savetxt(csv, table, delimiter=",", header="time,M1,w1,w2", comments="", fmt="%.17g")
    runner = CliRunner()
    for bad in (["--shooting", "x"], ["--shooting", "1"], ["--shooting", "50", "--online"]):
        r = runner.invoke(main, ["identify", str(csv), "--diagram", str(COULOMB), *bad])
        assert r.exit_code == 2, r.output
        assert "shooting" in r.output
    out = tmp_path / "r.json"
    r = runner.invoke(main, ["identify", str(csv), "--diagram", str(COULOMB), "--shooting", "100", "-o", str(out),
                             "--quiet"])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["shooting"]["length"] == 100 and doc["shooting"]["stages"][-1]["length"] == 399
    # --threads: the segments on two threads, the same result
    out2 = tmp_path / "r2.json"
    r = runner.invoke(main, ["identify", str(csv), "--diagram", str(COULOMB), "--shooting", "100", "--threads", "2",
                             "-o", str(out2), "--quiet"])
    assert r.exit_code == 0, r.output
    assert json.loads(out2.read_text())["parameters"] == doc["parameters"]
    r = runner.invoke(main, ["identify", str(csv), "--diagram", str(COULOMB), "--threads", "0"])
    assert r.exit_code == 2 and "--threads" in r.output


def test_batch_takes_shooting_and_finds_what_identify_finds(tmp_path):
    import csv as csvmod

    data = _data(COULOMB_PLANT, 400, 3, ["w1", "w2"])
    files = tmp_path / "runs"
    files.mkdir()
    table = np.column_stack([np.arange(data.n_rows) * load_diagram(COULOMB).sample_time]
                            + [data.columns[c] for c in ("M1", "w1", "w2")])
    np.savetxt(files / "d.csv", table, delimiter=",", header="time,M1,w1,w2", comments="", fmt="%.17g")
    runner = CliRunner()
    r = runner.invoke(main, ["batch", str(COULOMB), str(files / "d.csv"), "--shooting", "1"])
    assert r.exit_code == 2 and "shooting" in r.output
    out = tmp_path / "results.csv"
    r = runner.invoke(main, ["batch", str(COULOMB), str(files / "d.csv"), "--shooting", "100", "-o", str(out),
                             "--quiet"])
    assert r.exit_code == 0, r.output
    row = next(csvmod.DictReader(out.open()))
    single = runner.invoke(main, ["identify", str(files / "d.csv"), "--diagram", str(COULOMB), "--shooting", "100",
                                  "-o", str(tmp_path / "r.json"), "--quiet"])
    assert single.exit_code == 0, single.output
    doc = json.loads((tmp_path / "r.json").read_text())
    for name in ("J2", "c", "d"):
        assert float(row[name]) == pytest.approx(doc["parameters"][name]["value"], rel=1e-9), name
    # the setting reached the batch's fit: its last stage starts at the shooting stages' point, so it takes
    # the shooting run's iterations, not the single-shooting fit's (4 against 9 here)
    assert int(row["iterations"]) == doc["optimizer"]["iterations"]
    plain = runner.invoke(main, ["identify", str(files / "d.csv"), "--diagram", str(COULOMB), "-o",
                                 str(tmp_path / "p.json"), "--quiet"])
    assert plain.exit_code == 0
    # single shooting ends elsewhere at the 1e-9 level: the batch's agreement with the shooting run is the setting's
    other = json.loads((tmp_path / "p.json").read_text())["parameters"]
    assert any(float(row[n]) != pytest.approx(other[n]["value"], rel=1e-9) for n in ("J2", "c", "d"))
