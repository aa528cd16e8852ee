"""Quasi-online LM (paper section 3.1): one step by hand, the FIFO sums, memory, the offline LM as oracle.

Oracles: a hand-derived RTRL recursion and the LM formula in numpy; the runtime's own (Python) weight
evaluation and numpy/scipy linear algebra; fit/transforms.py for the bounds; central recomputation of the
window sums from the stored rows; CompiledNetwork.jacobian for the rows; fit/lm.py for the converged estimate.
"""

from __future__ import annotations

import dataclasses
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from feedback_neuron import feedback_neuron, hand_run
from randomnet import random_gdnn

from flowchart2sdnn.compiler import compile_diagram, compile_file
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.fit.transforms import Bounds
from flowchart2sdnn.identify.online import kernel as ok
from flowchart2sdnn.identify.online.run import OnlineOptions, OnlineRun, quasi_online
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parent.parent


def test_first_lm_step_equals_the_hand_computation():
    rng = np.random.default_rng(1)
    n = 40
    u = rng.uniform(-1, 1, n)
    target = hand_run(0.8, 0.6, u)[0] + 0.01 * rng.standard_normal(n)
    cn = feedback_neuron()
    assert cn.names == ("k", "w")
    lo_k, mu0 = 0.1, 0.05
    # the trial mode (tries=0) takes an LM step at every sample and exposes it as the trial
    opts = OnlineOptions(window=64, start=n - 1, block=10**6, mu0=mu0, record_every=1, average=10, tries=0)
    run = OnlineRun(cn, u[:, None], target[:, None], lower=[lo_k, -np.inf], options=opts)
    assert run.advance(n)

    # by hand: rows from the recursion, the min-only transform x = lo - 1 + sqrt(u^2 + 1), eq. (11)
    y, dk, dw = hand_run(0.5, 0.3, u)
    e = target - y
    uk = math.sqrt((0.5 - lo_k + 1.0) ** 2 - 1.0)
    Ju = np.column_stack([dk * uk / math.sqrt(uk * uk + 1.0), dw])
    du = np.linalg.solve(Ju.T @ Ju + mu0 * np.eye(2), Ju.T @ e)
    expected = np.array([lo_k - 1.0 + math.sqrt((uk + du[0]) ** 2 + 1.0), 0.3 + du[1]])
    np.testing.assert_allclose(run.trial_theta(), expected, rtol=1e-11)
    # the step is a trial: the model keeps the start values until a block accepts it
    np.testing.assert_allclose(run.theta(), [0.5, 0.3], rtol=1e-14)
    np.testing.assert_allclose(run.state.fs[ok.F_EE], e @ e, rtol=1e-12)
    result = run.result("completed")
    assert result.steps == 1
    np.testing.assert_allclose(result.cost[-1], 0.5 * e @ e, rtol=1e-12)


def small_gdnn_data(seed, n):
    """A small random GDNN as the model and a different one (other seed and size) as the data source."""
    cn = CompiledNetwork(random_gdnn(seed, layers=(3, 1)))
    truth = CompiledNetwork(random_gdnn(seed + 100, layers=(4, 1)))
    u = np.random.default_rng(seed).uniform(-1, 1, (n, 1))
    return cn, u, truth.simulate(truth.theta0(), u)


def window_rows(state):
    """The stored rows in FIFO order (oldest first)."""
    count, head, q = int(state.its[ok.I_COUNT]), int(state.its[ok.I_HEAD]), state.win_J.shape[0]
    order = (head - count + np.arange(count)) % q
    return state.win_J[order], state.win_c[order], state.win_e[order]


def test_window_holds_the_last_q_rows_of_the_offline_jacobian():
    cn, u, y = small_gdnn_data(3, 537)
    q = 50
    run = OnlineRun(cn, u, y, options=OnlineOptions(window=q, start=10**6, average=5))
    run.advance(537)
    J, c, e = window_rows(run.state)
    yhat, dy = cn.jacobian(cn.theta0(), u)
    np.testing.assert_allclose(J[:, 0, :], dy[-q:, 0, :], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(e[:, 0], (y - yhat)[-q:, 0], rtol=1e-12, atol=1e-14)
    A = dy[-q:, 0, :].T @ dy[-q:, 0, :]
    np.testing.assert_allclose(np.tril(run.state.A), np.tril(A), rtol=1e-9, atol=1e-12 * np.abs(A).max())


def test_fifo_running_sums_equal_a_recomputation_from_the_stored_rows():
    # 537 samples, Q = 50: the sums were last rebuilt 37 pushes ago, the rest is add/subtract updates,
    # and the parameters moved (accepted trials), so u_ref != u
    cn, u, y = small_gdnn_data(5, 537)
    run = OnlineRun(cn, u, y, options=OnlineOptions(window=50, start=20, block=25, average=5, mu0=1.0))
    run.advance(537)
    st = run.state
    assert st.its[ok.I_ACCEPTED] > 0 and st.its[ok.I_COUNT] == 50
    J, c, e = window_rows(st)
    J, c, e = J[:, 0, :], c[:, 0], e[:, 0]
    scale = np.abs(J).T @ np.abs(J)
    assert np.all(np.abs(np.tril(st.A) - np.tril(J.T @ J)) <= 1e-10 * np.tril(scale) + 1e-300)
    np.testing.assert_allclose(st.b, J.T @ c, rtol=1e-9, atol=1e-10 * (np.abs(J).T @ np.abs(c)).max())
    np.testing.assert_allclose(st.fs[ok.F_CC], c @ c, rtol=1e-10)
    np.testing.assert_allclose(st.fs[ok.F_EE], e @ e, rtol=1e-10)


def test_memory_does_not_depend_on_the_record_length():
    opts = OnlineOptions(window=400, average=300, start=100, record_every=100, block=200, chunk=1000)
    shapes, peaks = {}, {}
    for length in (3000, 12000):
        cn, u, y = small_gdnn_data(7, length)
        run = OnlineRun(cn, u, y, options=opts)
        run.advance(length)
        st = run.state
        assert st.win_J.shape == (400, cn.n_outputs, cn.n_theta) and st.avg_x.shape == (300, cn.n_theta)
        shapes[length] = {name: getattr(st, name).shape for name in st.__dataclass_fields__}
        result = run.result("completed")
        assert result.trajectory.shape == (length // 100, cn.n_theta)  # the only output that grows: decimated
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        quasi_online(cn, u, y, options=opts)
        peaks[length] = tracemalloc.get_traced_memory()[1] - base
        tracemalloc.stop()
    # every state array has a shape fixed by Q, K, P and the network ...
    assert shapes[3000] == shapes[12000]
    # ... and the whole run allocates no more for 4x the record than the extra decimated records
    # (90 rows of P + 2 values, about 12 kB) and some slack for Python objects
    assert peaks[12000] - peaks[3000] < 64 * 1024, peaks


@pytest.fixture(scope="module")
def engine_case():
    """60 s of the stationary engine bench (exact friction, RK4) and the engine SDNN with a fixed tanh basis.

    The friction neurons' input weights are fixed at 1 (Stribeck-like), 100 (Coulomb-like) and 0.05
    (viscous-like); J1 and the three output weights are identified. The plant is not in the model class.
    """
    data = excite(load_diagram(ROOT / "diagrams" / "engine_plant.yaml"), ExcitationSettings(seconds=60.0, seed=1))
    chart = dataclasses.replace(load_diagram(ROOT / "diagrams" / "engine.yaml"), substeps=1, delays=None)
    net = compile_diagram(chart).network  # the trainer's test, not the example's: one step per sample
    basis = {"MR1.a1": 1.0, "MR1.a2": 100.0, "MR1.a3": 0.05}
    net = dataclasses.replace(
        net, free_weights=tuple(dataclasses.replace(f, init=basis.get(f.name, 0.0)) for f in net.free_weights)
    )
    cn = CompiledNetwork(net, free=["J1", "MR1.v1", "MR1.v2", "MR1.v3"])
    return cn, data["M1"][:, None], data["w1"]


def test_quasi_online_converges_to_the_offline_lm_of_its_final_window(engine_case):
    cn, u, y = engine_case
    q = 5000
    lower = [0.0, -np.inf, -np.inf, -np.inf]
    opts = OnlineOptions(window=q, start=1000, average=q, block=500, record_every=100)
    res = quasi_online(cn, u, y, lower=lower, options=opts)
    assert res.status == "completed" and res.diverged == 0

    # The online fixed point minimises the errors of the last Q samples of the free run from t = 0 (rows come
    # from the run, not from a restarted one), so the offline oracle fits exactly that, from the same start.
    def window_fun(x):
        yhat, dy = cn.jacobian(x, u)
        return (y - yhat[:, 0])[-q:], dy[-q:, 0, :]

    off = levenberg_marquardt(window_fun, cn.theta0(), cn.names, lower=lower, options=LMOptions(max_iter=60))
    assert off.converged
    assert abs(res.theta_mean[0] - 0.6) > 0.3  # J1 really moved (start 0.6, optimum about 0.19)
    # Tolerance: the online estimate keeps moving within a band while the final window fills (each accepted
    # trial is one LM step on a sliding window); the mean over that window cannot be expected closer to the
    # offline optimum than the band's width, plus 0.1 % for J1's rounding-level spread.
    last = res.trajectory[-q // opts.record_every:]
    band = last.max(axis=0) - last.min(axis=0) + 1e-3 * np.abs(off.x)
    assert np.all(np.abs(res.theta_mean - off.x) <= band), (res.theta_mean, off.x, band)
    assert abs(res.theta_mean[0] - off.x[0]) <= 2e-3 * off.x[0]  # the inertia itself to 0.2 %
    # and the estimate fits the window nearly as well as the optimum does
    e_online = window_fun(res.theta_mean)[0]
    assert 0.5 * e_online @ e_online <= 1.25 * off.cost


def test_divergence_is_recovered_and_never_yields_nan():
    cn = feedback_neuron(w0=1.5, k0=1.0)  # unstable: |y| grows like 1.5^t and overflows near t = 1750
    rng = np.random.default_rng(2)
    u = rng.uniform(-1, 1, 6000)
    y = hand_run(1.0, 0.5, u)[0]
    frozen = OnlineOptions(window=500, start=0, block=10**6, mu0=1e10, mu_min=1e10, mu_max=1e10, average=50)
    res = quasi_online(cn, u[:, None], y[:, None], options=frozen)
    assert res.diverged >= 1 and res.status == "completed"
    assert np.all((res.divergence_time >= 0) & (res.divergence_time < 6000))
    for arr in (res.theta_mean, res.theta_final, res.trajectory, res.cost, res.mu_trajectory):
        assert np.all(np.isfinite(arr))
    assert np.isfinite(res.mean_cost)
    late = quasi_online(cn, u[:, None], y[:, None], options=dataclasses.replace(frozen, start=5999))
    assert late.status == "diverged_at_start" and late.steps == 0
    np.testing.assert_array_equal(late.theta_final, [1.0, 1.5])


def test_noise_free_data_of_the_model_class_are_fitted_exactly():
    # from w = 0.2 towards 0.95 the first Gauss-Newton steps overshoot (y depends on powers of w): the trials
    # are refused until mu is large enough, then the fit reaches the truth to rounding level
    cn = feedback_neuron(w0=0.2, k0=1.0)
    u = np.random.default_rng(4).uniform(-1, 1, 20000)
    y = hand_run(1.0, 0.95, u)[0]
    res = quasi_online(cn, u[:, None], y[:, None],
                       options=OnlineOptions(window=2000, start=200, block=300, average=2000, mu0=1e-6))
    assert res.status == "completed" and res.rejected_blocks > 0 and res.accepted_blocks > 0
    np.testing.assert_allclose(res.theta_mean, [1.0, 0.95], rtol=1e-7)
    assert res.mean_cost < 1e-9


def test_callback_stop_and_keyboard_interrupt_return_what_exists():
    cn, u, y = small_gdnn_data(9, 5000)
    opts = OnlineOptions(window=300, start=100, chunk=1000, record_every=10, average=100, block=100)
    seen = []
    res = quasi_online(cn, u, y, options=opts, callback=lambda f: seen.append(f) or len(seen) == 2)
    assert res.status == "callback_stop" and res.samples == 2000 and seen == [0.2, 0.4]
    assert res.trajectory.shape[0] == 200

    def interrupt(fraction):
        raise KeyboardInterrupt

    res = quasi_online(cn, u, y, options=opts, callback=interrupt)
    assert res.status == "interrupted" and res.samples == 1000
    assert np.all(np.isfinite(res.theta_mean)) and res.steps == 900


def test_bounds_hold_along_the_whole_run(engine_case):
    # the unbounded optimum is near J1 = 0.191, v1 = -0.4, v2 = 1.2: the bounds below are active there
    # (min-only on J1 and v1, max-only on v2)
    cn, u, y = engine_case
    lower, upper = np.array([0.195, -0.3, -np.inf, -np.inf]), np.array([np.inf, np.inf, 1.0, np.inf])
    res = quasi_online(cn, u, y, lower=lower, upper=upper,
                       options=OnlineOptions(window=5000, start=1000, block=500, average=5000, record_every=10))
    assert np.all(res.trajectory >= lower) and np.all(res.trajectory <= upper)
    assert np.all(res.theta_mean >= lower) and np.all(res.theta_mean <= upper)
    assert res.theta_mean[0] < 0.21  # it moved from 0.6 down to the neighbourhood of the bound


def test_weight_program_matches_the_runtime():
    cn = CompiledNetwork(compile_file(ROOT / "diagrams" / "two_mass.yaml").network)
    prog = ok.weight_program(cn)
    rng = np.random.default_rng(0)
    for _ in range(5):
        theta = cn.theta0() * rng.uniform(0.5, 1.5, cn.n_theta)
        conn, dval = np.zeros(prog.n_connections), np.zeros(prog.n_slots)
        assert ok.eval_weights(theta, prog.exprs, conn, dval, np.empty(prog.stack))
        ref_conn, ref_dval = cn.connection_values(theta, with_derivatives=True)
        np.testing.assert_allclose(conn, ref_conn, rtol=1e-15, atol=0)
        np.testing.assert_allclose(dval, ref_dval, rtol=1e-15, atol=0)
    theta = cn.theta0()
    theta[0] = 0.0  # J2 = 0: 1/J2 fails
    assert not ok.eval_weights(theta, prog.exprs, conn, dval, np.empty(prog.stack))


def test_transform_and_cholesky_kernels():
    names = ("a", "b", "c", "d")
    bounds = Bounds.make(names, [-np.inf, 0.5, -np.inf, -1.0], [np.inf, np.inf, 2.0, 3.0])
    kind = np.array([0, 1, 2, 3], dtype=np.int64)
    u = np.array([0.7, -1.3, 2.2, 0.4])
    x, dxdu = np.empty(4), np.empty(4)
    ok.external(u, kind, np.array(bounds.lower), np.array(bounds.upper), x, dxdu)
    np.testing.assert_allclose(x, bounds.to_external(u), rtol=1e-15)
    np.testing.assert_allclose(dxdu, bounds.dx_du(u), rtol=1e-15)

    rng = np.random.default_rng(3)
    B = rng.standard_normal((6, 6))
    M = B @ B.T + 0.1 * np.eye(6)
    rhs = rng.standard_normal(6)
    out, L = np.empty(6), np.empty((6, 6))
    assert ok.cholesky_solve(M, rhs, L, out)
    np.testing.assert_allclose(out, np.linalg.solve(M, rhs), rtol=1e-10)
    M[2, 2] = -1.0
    assert not ok.cholesky_solve(M, rhs, L, out)


@pytest.mark.parametrize(
    "kwargs",
    [dict(window=0), dict(every=0), dict(start=-1), dict(mu0=0.0), dict(mu_inc=1.0), dict(mu_dec=1.0),
     dict(mu_min=1.0, mu0=0.1), dict(record_every=0), dict(block=0), dict(average=1.5)],
)
def test_options_are_validated(kwargs):
    with pytest.raises(ValueError):
        OnlineOptions(**kwargs)


def test_arguments_are_validated():
    cn = feedback_neuron()
    u = np.zeros((10, 1))
    with pytest.raises(ValueError, match="targets"):
        quasi_online(cn, u, np.zeros((9, 1)))
    with pytest.raises(ValueError, match="non-finite"):
        quasi_online(cn, u, np.full(10, np.nan))
    with pytest.raises(ValueError, match="theta0"):
        quasi_online(cn, u, np.zeros(10), theta0=[1.0])
    with pytest.raises(ValueError, match="below its min"):
        quasi_online(cn, u, np.zeros(10), lower=[0.6, -np.inf])
