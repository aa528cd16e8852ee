"""Quasi-online LM, window mode (identify/online/kernel.py module docstring): each iteration by hand.

Oracles: the hand-derived recursion y(t) = w y(t-1) + k u(t) and its sensitivities, the LM formula and the
trainlm accept test in numpy; the scaled first damping rule of fit/lm.py (LMOptions.tau) by hand; the
iteration schedule as stated in OnlineOptions, replayed in Python.
"""

from __future__ import annotations

import numpy as np
import pytest
from feedback_neuron import feedback_neuron, hand_run
from randomnet import random_gdnn

from flowchart2sdnn.identify.online import kernel as ok
from flowchart2sdnn.identify.online.run import OnlineOptions, OnlineRun, quasi_online
from flowchart2sdnn.network.runtime import CompiledNetwork


def fifo(state):
    """Row indices of the window, oldest first."""
    count, head, q = int(state.its[ok.I_COUNT]), int(state.its[ok.I_HEAD]), state.win_J.shape[0]
    return (head - count + np.arange(count)) % q


def test_scaled_mu_is_the_rule_of_lm_tau():
    A = np.array([[4.0, 0.0], [1.0, 9.0]])  # lower triangle of JᵀJ: max diag 9
    assert ok.scaled_mu(A, 1e-3, 0.1, 1e10) == pytest.approx(0.9, rel=1e-15)
    assert ok.scaled_mu(A, 2.0, 0.1, 1e10) == 2.0  # never below mu0
    assert ok.scaled_mu(A, 1e-3, 0.1, 0.5) == 0.5  # never above mu_max
    A[1, 1] = np.nan  # a non-finite diagonal does not poison the damping
    assert ok.scaled_mu(A, 1e-3, 0.1, 1e10) == pytest.approx(0.4, rel=1e-15)


@pytest.mark.parametrize(
    "truth, start, tau, mu0, accepted",
    [((0.8, 0.6), (0.5, 0.3), 0.5, 1e-3, True),  # a damped step towards the truth: the window cost falls
     ((1.0, 0.95), (1.0, 0.5), 0.0, 1e-9, False)],  # undamped Gauss-Newton overshoots to w = 1.06: refused
)
def test_one_window_iteration_equals_the_hand_computation(truth, start, tau, mu0, accepted):
    rng = np.random.default_rng(1)
    n = 40
    u = rng.uniform(-1, 1, n)
    target = hand_run(*truth, u)[0] + 0.01 * rng.standard_normal(n)
    cn = feedback_neuron(w0=start[1], k0=start[0])
    assert cn.names == ("k", "w")
    # one iteration with one trial at the last sample, the window holding the whole record
    opts = OnlineOptions(window=64, start=n - 1, block=1, min_block=1, tries=1, tau=tau, mu0=mu0, average=5)
    run = OnlineRun(cn, u[:, None], target[:, None], options=opts)
    assert run.advance(n)

    # by hand: the rows at the start, the scaled first damping, eq. (11), the trial's window cost
    y, dk, dw = hand_run(*start, u)
    J = np.column_stack([dk, dw])
    e = target - y
    mu = max(mu0, tau * np.max(np.diag(J.T @ J)))
    trial = np.array(start) + np.linalg.solve(J.T @ J + mu * np.eye(2), J.T @ e)
    y_tr, dk_tr, dw_tr = hand_run(*trial, u)
    e_tr = target - y_tr
    assert (e_tr @ e_tr < e @ e) == accepted  # the case exercises the branch it names

    st = run.state
    rows = fifo(st)
    if accepted:
        np.testing.assert_allclose(run.theta(), trial, rtol=1e-12)
        assert st.its[ok.I_ACCEPTED] == 1 and st.its[ok.I_REJECTED] == 0
        np.testing.assert_allclose(st.fs[ok.F_MU], 0.1 * mu, rtol=1e-12)
        # the window was relinearised at the trial: rows, errors, sums
        np.testing.assert_allclose(st.win_J[rows, 0, :], np.column_stack([dk_tr, dw_tr]), rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(st.win_e[rows, 0], e_tr, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(st.fs[ok.F_EE], e_tr @ e_tr, rtol=1e-11)
        Jt = np.column_stack([dk_tr, dw_tr])
        np.testing.assert_allclose(np.tril(st.A), np.tril(Jt.T @ Jt), rtol=1e-11)
        np.testing.assert_allclose(st.b, Jt.T @ e_tr, rtol=1e-10, atol=1e-13)
    else:
        np.testing.assert_array_equal(run.theta(), start)
        assert st.its[ok.I_ACCEPTED] == 0 and st.its[ok.I_REJECTED] == 1
        np.testing.assert_allclose(st.fs[ok.F_MU], 10.0 * mu, rtol=1e-12)
        np.testing.assert_allclose(st.win_e[rows, 0], e, rtol=1e-12, atol=1e-14)


def test_rows_are_a_free_run_at_the_accepted_parameters_from_the_stored_state():
    # Q = 50 of 300 samples, iterations from sample 100: the window slid past the replays; its rows must be
    # the errors of one free run at the accepted (k, w) from the state stored before the oldest row
    rng = np.random.default_rng(6)
    n, q = 300, 50
    u = rng.uniform(-1, 1, n)
    target = hand_run(0.8, 0.7, u)[0] + 0.01 * rng.standard_normal(n)
    run = OnlineRun(feedback_neuron(), u[:, None], target[:, None],
                    options=OnlineOptions(window=q, start=100, block=25, min_block=5, average=20))
    run.advance(n)
    st = run.state
    assert st.its[ok.I_ACCEPTED] > 0
    rows = fifo(st)
    np.testing.assert_array_equal(st.win_time[rows], np.arange(n - q, n))  # the last Q samples, past only
    ring = st.a_buf.shape[0]
    y_prev = st.win_state[rows[0]][(n - q - 1) % ring, 0]  # y(t0 - 1), stored before the oldest row
    k, w = run.theta()
    y = hand_run(k, w, u[n - q:], y_prev)[0]
    np.testing.assert_allclose(st.win_e[rows, 0], target[n - q:] - y, rtol=1e-10, atol=1e-12)

    # window_sim at another point, from the same stored state
    other = np.array([0.9, 0.5])
    conn, dval = np.zeros(run.program.n_connections), np.zeros(run.program.n_slots)
    assert ok.eval_weights(other, run.program.exprs, conn, dval, np.empty(run.program.stack))
    e_tr, tr_state, a_tr = np.zeros((q, 1)), np.zeros_like(st.win_state), np.zeros_like(st.a_buf)
    cost = ok.window_sim(run.inputs, run.targets, run.net, conn, st.win_state, st.win_time, st.its, a_tr,
                         np.empty(ring, dtype=np.int64), e_tr, tr_state)
    e_hand = target[n - q:] - hand_run(*other, u[n - q:], y_prev)[0]
    np.testing.assert_allclose(e_tr[rows, 0], e_hand, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(cost, 0.5 * e_hand @ e_hand, rtol=1e-12)


def test_iterations_follow_the_stated_schedule():
    cn = CompiledNetwork(random_gdnn(3, layers=(3, 1)))
    truth = CompiledNetwork(random_gdnn(103, layers=(4, 1)))
    n = 3000
    u = np.random.default_rng(3).uniform(-1, 1, (n, 1))
    y = truth.simulate(truth.theta0(), u)
    opts = OnlineOptions(window=400, block=100, min_block=10, start=50, tries=1, average=100)
    res = quasi_online(cn, u, y, options=opts)
    assert res.diverged == 0 and res.steps == n - opts.start  # window mode: every sample from start
    # OnlineOptions: an iteration when max(min_block, block * rows // window) samples have passed since the last
    pos = iterations = 0
    for t in range(opts.start, n):
        pos += 1
        if pos >= max(opts.min_block, opts.block * min(t + 1, opts.window) // opts.window):
            iterations, pos = iterations + 1, 0
    assert res.accepted_blocks + res.rejected_blocks + res.skipped_steps == iterations
    assert res.accepted_blocks > 0


@pytest.mark.parametrize("kwargs", [dict(tries=-1), dict(min_block=0), dict(tau=-1.0), dict(tau=float("nan"))])
def test_window_options_are_validated(kwargs):
    with pytest.raises(ValueError):
        OnlineOptions(**kwargs)
