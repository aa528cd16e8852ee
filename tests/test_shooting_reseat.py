"""Reseating an outlying segment's free start (identify.shooting.multiple.reseat).

Oracle: the driven pendulum from the continuous oracle (RK4), chaotic under a drive of 1.15 at 2/3 rad/s. With
the true parameters and every segment started from the oracle's own state at its boundary, each segment follows
the record to the noise; one start moved half a turn misses its segment by far more. reseat must put that start
back where the oracle passes at that boundary (within what the network's discretization and the noise allow)
and leave every other start alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.shooting.multiple import reseat
from flowchart2sdnn.identify.shooting.segmented import Segmented
from flowchart2sdnn.simulate.continuous import simulate_continuous

PENDULUM = Path(__file__).resolve().parent / "data" / "shooting" / "pendulum_plant.yaml"


def _segmented(length: int = 25, q: int = 400):
    plant = load_diagram(PENDULUM)
    t = np.arange(q) * plant.sample_time
    u = 1.15 * np.cos(2 / 3 * t)
    clean = simulate_continuous(plant, u[:, None])
    y = clean + 0.01 * np.random.default_rng(5).standard_normal((q, 2))
    data = sd.dataset_from_frame({"time": t, "u": u, "v": y[:, 0], "theta": y[:, 1]}, time="time",
                                 inputs=["u"], outputs=["v", "theta"])
    problem = build_problem(plant, data)
    seg = Segmented(problem, length, 1.0, starts="free")
    # every free start at the oracle's state after the sample before the segment (the state a segment starts
    # from is the one the sample before it ends in): v and theta are the plant's outputs
    order = {"v": 0, "theta": 1}
    x = np.zeros(seg.n_x)
    x[:seg.n_theta] = problem.compiled.theta0()
    for p in seg.pieces:
        if p.column >= 0:
            x[p.column:p.column + len(seg.free)] = [clean[p.a - 1, order[n]] for n in seg.free_names]
    return seg, x, clean, order


def test_the_oracle_starts_are_left_alone():
    seg, x, _, _ = _segmented()
    out, count = reseat(seg, x)
    assert count == 0 and np.array_equal(out, x)


def test_a_start_half_a_turn_off_is_put_back_where_the_oracle_passes():
    seg, x, clean, order = _segmented()
    p = seg.pieces[6]
    j = seg.free_names.index("theta")
    moved = x.copy()
    moved[p.column + j] += np.pi
    out, count = reseat(seg, moved)
    assert count == 1
    assert np.array_equal(np.delete(out, range(p.column, p.column + len(seg.free))),
                          np.delete(x, range(p.column, p.column + len(seg.free))))
    # the previous segment's end: the oracle's state at the boundary, to what a 25-sample free run of the network
    # (auto N = 11) keeps of it on this chaotic record (the unmoved segments' ends: median 0.08 rad/s and 0.12 rad
    # off the oracle), against the half turn (3.14 rad) the start was moved by
    for k, name in enumerate(seg.free_names):
        assert out[p.column + k] == pytest.approx(clean[p.a - 1, order[name]], abs=0.1)
