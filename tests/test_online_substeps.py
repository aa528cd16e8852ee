"""Quasi-online LM with sub-steps (issue 13): N network steps per sample, RTRL through all of them.

Oracles: the offline Runtime (``CompiledNetwork.simulate``, itself tested against the continuous RK4 oracle in
tests/test_substeps.py and tests/test_compile_vs_continuous.py) for the free run and the window replays, central
finite differences of that offline simulation for the window's Jacobian rows, and the continuous two-mass
Coulomb plant (`sdnn excite`, diagrams/two_mass_coulomb_plant.yaml) with known parameters end to end.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from randomnet import random_gdnn

import flowchart2sdnn as sd
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.online import kernel as ok
from flowchart2sdnn.identify.online.run import OnlineOptions, OnlineRun
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"


def window_rows(state):
    """The stored rows in FIFO order (oldest first)."""
    count, head, q = int(state.its[ok.I_COUNT]), int(state.its[ok.I_HEAD]), state.win_J.shape[0]
    order = (head - count + np.arange(count)) % q
    return state.win_J[order], state.win_e[order]


def gdnn(seed: int, substeps: int) -> CompiledNetwork:
    """A random GDNN (input delays 0/1, feedback delays 1/2, an internal delay: ring 3) stepped N times per
    sample; N does not divide the ring, so the slots of a sample's last step wander through the ring."""
    return CompiledNetwork(dataclasses.replace(random_gdnn(seed, layers=(3, 1)), substeps=substeps))


def coulomb_chart(substeps: int, delays: str | None = None) -> CompiledNetwork:
    """The two-mass Coulomb chart (tanh friction, delayed shaft torques) compiled at N sub-steps (and another
    delay rule: `midpoint` adds delay-2 edges)."""
    chart = load_diagram(DIAGRAMS / "two_mass_coulomb.yaml")
    if delays:
        chart = dataclasses.replace(chart, delays=delays)
    return CompiledNetwork(compile_diagram(chart, substeps=substeps).network)


def free_run(cn: CompiledNetwork, u: np.ndarray, y: np.ndarray) -> OnlineRun:
    """The online model over the whole record with updates switched off (no LM step: start after the end)."""
    n = u.shape[0]
    run = OnlineRun(cn, u, y, options=OnlineOptions(window=n, start=n + 1, average=5))
    assert run.advance(n) and run.done == n
    return run


@pytest.mark.parametrize("n_sub", [2, 4])
@pytest.mark.parametrize("model", ["gdnn", "coulomb", "midpoint"])
def test_free_run_equals_the_offline_simulation(n_sub, model):
    rng = np.random.default_rng(5)
    n = 400
    if model == "gdnn":
        cn = gdnn(7, n_sub)
        u = rng.uniform(-1, 1, (n, 1))
    else:
        cn = coulomb_chart(n_sub, "midpoint" if model == "midpoint" else None)
        if model == "midpoint":
            assert any(w.delay == 2 for w in cn.net.weights)
        u = np.repeat(rng.uniform(-5, 5, n // 20), 20)[:, None]  # a staircase torque: the shaft rings
    assert cn.substeps == n_sub
    y = rng.standard_normal((n, cn.n_outputs))  # any targets: the rows' errors are y - yhat
    run = free_run(cn, u, y)
    _, e = window_rows(run.state)
    yhat = cn.simulate(cn.theta0(), u)
    assert np.ptp(yhat) > 0.03  # the run moves
    # the online kernel keeps strict IEEE order, the offline one contracts to FMA: rounding only
    np.testing.assert_allclose(y - e, yhat, rtol=1e-10, atol=1e-10 * np.abs(yhat).max())
    # at one step per sample the same network gives another output: the sub-steps are really run
    one = CompiledNetwork(dataclasses.replace(cn.net, substeps=1)).simulate(cn.theta0(), u)
    assert np.abs(one - yhat).max() > 1e-3 * np.abs(yhat).max()

    # the window mode's trial simulation replays the window from its stored sample-boundary states: at the
    # model's own parameters it reproduces the rows, at other parameters the offline run there
    st = run.state
    ring = st.a_buf.shape[0]
    theta = cn.theta0() * 1.05
    conn, dval = np.zeros(run.program.n_connections), np.zeros(run.program.n_slots)
    assert ok.eval_weights(theta, run.program.exprs, conn, dval, np.empty(run.program.stack))
    e_tr, tr_state, a_tr = np.zeros((n, cn.n_outputs)), np.zeros_like(st.win_state), np.zeros_like(st.a_buf)
    cost = ok.window_sim(run.step_inputs, run.targets, run.net, conn, st.win_state, st.win_time, st.its, a_tr,
                         np.empty(ring, dtype=np.int64), e_tr, tr_state)
    y_other = cn.simulate(theta, u)
    np.testing.assert_allclose(y - e_tr, y_other, rtol=1e-10, atol=1e-10 * np.abs(y_other).max())
    np.testing.assert_allclose(cost, 0.5 * np.sum((y - y_other) ** 2), rtol=1e-9)


def central_differences(cn, theta, u, step=1e-6):
    cols = []
    for i in range(theta.size):
        h = step * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        cols.append((cn.simulate(up, u) - cn.simulate(down, u)) / (2 * h))
    return np.stack(cols, axis=-1)


def assert_rows_match(J, reference, rtol):
    total = np.linalg.norm(reference)
    for i in range(reference.shape[-1]):  # per column: a wrong small column cannot hide behind a large one
        scale = max(np.linalg.norm(reference[..., i]), 1e-6 * total)
        err = np.linalg.norm(J[..., i] - reference[..., i])
        assert err <= rtol * scale, f"column {i}: relative error {err / scale:.2e}"


@pytest.mark.parametrize("model", ["gdnn", "coulomb"])
def test_window_rows_are_the_jacobian_through_all_substeps(model):
    rng = np.random.default_rng(11)
    n = 300
    if model == "gdnn":
        cn = gdnn(4, 3)
        u = rng.uniform(-1, 1, (n, 1))
    else:
        cn = coulomb_chart(3)
        u = np.repeat(rng.uniform(-5, 5, n // 15), 15)[:, None]
    y = rng.standard_normal((n, cn.n_outputs))
    run = free_run(cn, u, y)
    J, _ = window_rows(run.state)
    theta = cn.theta0()
    assert_rows_match(J, central_differences(cn, theta, u), rtol=1e-6)
    assert_rows_match(J, cn.jacobian(theta, u)[1], rtol=1e-9)


def test_an_accepted_iteration_relinearises_the_window_through_all_substeps():
    # window = the whole record: the relinearisation replays it from the history (sensitivities zero), so every
    # row afterwards is the offline Jacobian at the new parameters, and the rows pushed after it continue there
    n_sub, n = 3, 600
    cn = gdnn(4, n_sub)
    truth = gdnn(104, n_sub)
    u = np.random.default_rng(2).uniform(-1, 1, (n, 1))
    y = truth.simulate(truth.theta0(), u)
    opts = OnlineOptions(window=n, start=n - 8, block=5, min_block=5, tries=1, average=5)
    run = OnlineRun(cn, u, y, options=opts)
    assert run.advance(n)
    st = run.state
    assert st.its[ok.I_ACCEPTED] == 1 and st.its[ok.I_REJECTED] == 0
    theta = run.theta()
    assert np.abs(theta - cn.theta0()).max() > 1e-6
    J, e = window_rows(st)
    yhat, dy = cn.jacobian(theta, u)
    np.testing.assert_allclose(y - e, yhat, rtol=1e-10, atol=1e-10)
    assert_rows_match(J, dy, rtol=1e-9)


def test_trial_mode_runs_substeps():
    # the trial mode (tries = 0) simulates its trial network N steps per sample too: with a never-accepted trial
    # (block longer than the record) the model's rows are still the offline run at the start values
    n = 300
    cn = gdnn(9, 4)
    u = np.random.default_rng(4).uniform(-1, 1, (n, 1))
    truth = gdnn(109, 4)
    y = truth.simulate(truth.theta0(), u)
    run = OnlineRun(cn, u, y, options=OnlineOptions(window=n, start=10, block=10**6, tries=0, average=5))
    assert run.advance(n)
    assert run.state.its[ok.I_DIVERGED] == 0
    J, e = window_rows(run.state)
    yhat, dy = cn.jacobian(cn.theta0(), u)
    np.testing.assert_allclose(y - e, yhat, rtol=1e-10, atol=1e-10)
    assert_rows_match(J, dy, rtol=1e-9)


def test_quasi_online_with_auto_finds_the_shaft_damping():
    """End to end (identify --online): noise-free data of the continuous two-mass Coulomb plant, 20 s at 1 kHz,
    the chart started at the plant's own parameters. Each run moves to the optimum of its discretization: at
    one step per sample the half-step error of symplectic Euler is absorbed into the damping (measured: the
    online d +1.4 %, c -0.07 %; an offline fit on the same data: d +0.8 %), with `auto` (N = 7 here) d stays
    within 0.1 % (measured 0.08 %). The bounds leave room for the estimator's scatter (0.1-0.3 % over seeds
    1-3 and 10-20 s records) and would fail if the online run ignored the sub-steps (both errors equal)."""
    plant = load_diagram(DIAGRAMS / "two_mass_coulomb_plant.yaml")
    data = excite(plant, ExcitationSettings(seconds=20.0, seed=1))
    ds = sd.dataset_from_frame(pd.DataFrame(data), time="time", inputs=["M1"], outputs=["w1", "w2"])
    truth = {p.name: p.init for p in plant.parameters}
    error, steps = {}, {}
    for substeps in (1, "auto"):
        result = sd.identify(dataclasses.replace(plant, substeps=substeps), ds, online=True, window=10000,
                             average=5000)
        assert result.status == "completed", result.message
        error[substeps] = result.parameters["d"].value / truth["d"] - 1.0
        steps[substeps] = json.loads(result.to_json())["discretization"]["substeps"]
    assert steps[1] == 1 and steps["auto"] == compile_diagram(plant).network.substeps > 1
    assert abs(error["auto"]) < 0.005, error
    assert abs(error[1]) > 2 * abs(error["auto"]), error


def test_cli_online_with_substeps_auto(tmp_path):
    # `identify --online --substeps auto` resolves N as offline does (it used to refuse N > 1)
    from click.testing import CliRunner

    from flowchart2sdnn.cli.main import main
    from flowchart2sdnn.data.csvdata import write_csv

    plant = load_diagram(DIAGRAMS / "two_mass_coulomb_plant.yaml")
    write_csv(tmp_path / "d.csv", excite(plant, ExcitationSettings(seconds=2.0, seed=2, noise_std=0.003)),
              float_format="%.17g")
    out = tmp_path / "r.json"
    res = CliRunner().invoke(main, ["identify", str(tmp_path / "d.csv"), "--diagram",
                                    str(DIAGRAMS / "two_mass_coulomb.yaml"), "--online", "--substeps", "auto",
                                    "--window", "1000", "--average", "500", "-o", str(out), "--quiet"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    n = compile_diagram(load_diagram(DIAGRAMS / "two_mass_coulomb.yaml"), substeps="auto").network.substeps
    assert n > 1 and doc["discretization"]["substeps"] == n and doc["discretization"]["requested"] == "auto"
    assert doc["status"] == "completed" and doc["online"]["steps"] > 1900
