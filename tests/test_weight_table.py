"""The public weight table of CompiledNetwork and the shared RTRL step on the quasi-online path.

Oracles: the weights evaluated by hand from the table's own description against the runtime's connection
values; central finite differences of the runtime's simulation against the quasi-online kernel's rows.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from randomnet import random_gdnn

from flowchart2sdnn.compiler import compile_file
from flowchart2sdnn.identify.online import kernel as ok
from flowchart2sdnn.identify.online.run import OnlineOptions, OnlineRun
from flowchart2sdnn.network.runtime import CompiledNetwork

ROOT = Path(__file__).resolve().parent.parent


def test_the_weight_table_is_frozen_and_says_how_the_connections_are_made():
    cn = CompiledNetwork(compile_file(ROOT / "diagrams" / "two_mass.yaml").network)
    table = cn.weights
    with pytest.raises(dataclasses.FrozenInstanceError):
        table.coefs = ()
    for name in ("weight_coef", "weight_conn", "term_slot", "slot_theta", "conn_slots"):
        with pytest.raises(ValueError):
            getattr(table, name)[0] = 1
    theta = cn.theta0() * np.random.default_rng(0).uniform(0.5, 1.5, cn.n_theta)
    params, free = cn.values(theta)
    conn = np.zeros(table.n_connections)
    for j, f in enumerate(table.weight_free):
        w = float(table.coefs[table.weight_coef[j]].evaluate(params))
        conn[table.weight_conn[j]] += w * (free[f] if f is not None else 1.0)
    dconn = np.zeros(table.n_slots)
    for i, f in enumerate(table.term_free):
        dconn[table.term_slot[i]] += float(table.term_expr[i].evaluate(params)) * (free[f] if f is not None else 1.0)
    ref_conn, ref_dval = cn.connection_values(theta, with_derivatives=True)
    np.testing.assert_allclose(conn, ref_conn, rtol=1e-14)
    np.testing.assert_allclose(dconn, ref_dval, rtol=1e-14)
    assert table.conn_slots[-1] == table.n_slots and np.all(np.diff(table.conn_slots) >= 0)
    assert sum(table.theta_is_param) == sum(n in {p.name for p in cn.net.parameters} for n in cn.names)


def test_quasi_online_rows_equal_central_differences_of_the_simulation():
    cn = CompiledNetwork(random_gdnn(11, layers=(3, 1)))
    n, q = 300, 120
    u = np.random.default_rng(2).uniform(-1, 1, (n, 1))
    theta = cn.theta0()
    y = np.zeros((n, 1))
    run = OnlineRun(cn, u, y, theta, options=OnlineOptions(window=q, start=10**6, average=5))  # no LM step
    assert run.advance(n)
    order = (int(run.state.its[ok.I_HEAD]) - q + np.arange(q)) % q
    rows = run.state.win_J[order, 0, :]  # no bounds: d yhat / d theta of the last q samples
    fd = np.empty((q, cn.n_theta))
    for i in range(cn.n_theta):
        h = 1e-6 * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        fd[:, i] = (cn.simulate(up, u)[-q:, 0] - cn.simulate(down, u)[-q:, 0]) / (2 * h)
    assert np.abs(fd).max() > 1e-3
    np.testing.assert_allclose(rows, fd, rtol=1e-5, atol=1e-7 * np.abs(fd).max())
    np.testing.assert_allclose(run.state.win_e[order, 0], -cn.simulate(theta, u)[-q:, 0], rtol=1e-12)
