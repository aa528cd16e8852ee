"""The overflow effect (issue 16): a state held at a learned level, checked against the continuous oracle and
hand values, and found by diagnose on a virtual test bench whose upper tank overflows.

The bench plant (tests/data/diagnose/tanks_overflow_plant.yaml) spills above 6 through its own stiff
spillway written with `abs` (20 1/s, not the patch's clip) and is simulated continuously by `excite`.
"""

from __future__ import annotations

import numpy as np
import pytest
from diagnose_bench import chart, record, rough_chart

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, Scales
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.diagnose.overflow import Level, Overflow, downstream
from flowchart2sdnn.diagram.model import Block, Diagram, Signal, Term
from flowchart2sdnn.expr import parse_expr
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous

NOISE = 0.01
EXCITATION = {"amplitude": (0.0, 2.0), "hold": (20.0, 80.0), "relay_level": 0.0}


def _filling_tank(substeps: int | None = None) -> Diagram:
    """x' = u, x measured: a tank filled at the rate u."""
    return Diagram("fill", 0.5, (Signal("u"),), (Signal("x"),), (),
                   (Block("gain_u", "gain", (Term("u"),), k=parse_expr("1")),
                    Block("x", "integrator", (Term("gain_u"),), init=0.0)), substeps=substeps)


@pytest.mark.parametrize("substeps", [None, 4])
def test_the_state_is_held_at_the_limit_in_the_network_and_the_oracle(substeps):
    plain = _filling_tank(substeps)
    patched = Overflow().patch(plain, Overflow().places(plain)[0], Level(1, 2.0, None, 3.0))
    u = np.full((40, 1), 0.5)  # fills 0.25 per sample: reaches 2 at t = 4 s (sample 8)
    cn = CompiledNetwork(compile_diagram(patched).network)
    net = run_aligned(cn, cn.theta0(), u, "zoh", {"x": 0.0})[:, 0]
    oracle = simulate_continuous(patched, u, substeps=50)[:, 0]
    h = 0.5 / (substeps or 1)
    # hand values: below the limit x = 0.5 t; above it the stiff outflow K = 1/h holds x at 2 + u/K
    t = np.arange(40) * 0.5
    assert net[:6] == pytest.approx(0.5 * t[:6], abs=1e-9)
    assert oracle[:6] == pytest.approx(0.5 * t[:6], abs=1e-6)
    assert net[20:] == pytest.approx(2 + 0.5 * h, rel=1e-6)
    assert oracle[20:] == pytest.approx(2 + 0.5 * h, rel=1e-4)


def test_a_lower_limit_holds_a_draining_state_from_below():
    plain = _filling_tank()
    patched = Overflow().patch(plain, Overflow().places(plain)[0], Level(-1, -1.0, None, 3.0))
    u = np.full((40, 1), -0.5)
    oracle = simulate_continuous(patched, u, substeps=50)[:, 0]
    assert oracle[20:] == pytest.approx(-1 - 0.5 * 0.5, rel=1e-4)


def test_places_options_and_routing_follow_the_chart():
    tanks = chart("tanks")
    eff = Overflow()
    assert [p.at for p in eff.places(tanks)] == ["x1dev", "y"]
    assert downstream(tanks, "x1dev") == ("y",) and downstream(tanks, "y") == ()
    opts = eff.options(tanks, eff.places(tanks)[0], Scales(lo={"x1dev": 0.0}, hi={"x1dev": 10.0}))
    uppers = [o for o in opts if o.side > 0]
    assert {o.into for o in uppers} == {None, "y"} and max(o.limit for o in uppers) == pytest.approx(9.8)
    routed = eff.patch(tanks, eff.places(tanks)[0], Level(1, 5.0, "y", 10.0))
    g = next(p for p in routed.parameters if p.name.startswith("ovf_x1dev_to_y"))
    assert g.init == 0 and (g.min, g.max) == (0.0, 1.0)
    assert any(t.signal.startswith("ovf_x1dev_in_y") for t in routed.block("dx2").inputs)
    assert tanks.block("x1dev").inputs == (Term("dx1"),)  # the chart given is not modified
    assert "overflow" in BUILTIN_EFFECTS


def test_diagnose_finds_the_overflow_of_the_upper_tank_first():
    plant = chart("tanks_overflow_plant")
    train = record(plant, 1200.0, 1, NOISE, **EXCITATION)
    val = record(plant, 600.0, 2, NOISE, **EXCITATION)
    assert train.columns["y"].max() > 6  # the bench does overflow
    r = diagnose(chart("tanks"), train, [val], DiagnoseSettings(rounds=1)).report
    first = r["rounds"][0]
    assert first["accepted"] and (first["effect"], first["at"]) == ("overflow", "x1dev")
    assert first["label"].startswith("max=")
    assert first["second_look"] == []  # its refit reached the noise: no more places refitted
    assert first["validation_rms_after"] < first["validation_rms_before"] / 3
    p = {k: v["value"] for k, v in r["final"]["parameters"].items()}
    # the upper level's limit (x10 + L) near the plant's spill level 6 (the plant's spillway lets it rise
    # by inflow/20, the patch's by inflow/K: a few %)
    assert p["x10"] + p["x1dev_max"] == pytest.approx(6.0, rel=0.05)
    for name, truth in (("k1", 0.5), ("k3", 0.4), ("k4", 1.0)):
        assert p[name] == pytest.approx(truth, rel=0.05)


def test_the_overflow_is_found_from_a_rough_chart_with_or_without_the_second_look():
    """Rough chart (x/÷2, seed 2), one-missing bench's level case. The first fit used to stop with the upper tank
    below its start, the spill's place 6th and the top 5 refits at 19x the noise, which the second look (the next
    places refitted) repaired; a first fit that runs to its minimum finds the spill among the first places."""
    plant = chart("tanks_overflow_plant")
    truth = {k: v for k, v in plant.parameter_values().items() if k in ("k1", "k3", "k4")}
    rough, _ = rough_chart(chart("tanks"), 2, truth)
    train = record(plant, 1200.0, 2, NOISE, **EXCITATION)
    val = record(plant, 600.0, 102, NOISE, **EXCITATION)
    without = diagnose(rough, train, [val], DiagnoseSettings(rounds=1, second_look=False)).report
    first = without["rounds"][0]
    assert first["accepted"] and (first["effect"], first["at"]) == ("overflow", "x1dev")
    r = diagnose(rough, train, [val], DiagnoseSettings(rounds=1)).report
    first = r["rounds"][0]
    assert first["accepted"] and (first["effect"], first["at"]) == ("overflow", "x1dev")
    assert first["validation_rms_after"] < first["validation_rms_before"] / 3
    p = {k: v["value"] for k, v in r["final"]["parameters"].items()}
    for name, value in truth.items():
        assert p[name] == pytest.approx(value, rel=0.05)

