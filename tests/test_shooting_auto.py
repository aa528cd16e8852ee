"""--shooting auto and the chaotic long-record rule (identify.shooting.auto, identify.shooting.multiple's MERGE_RISE).

Oracles: hand computations of how a moved start grows in a linear chart (x' = a x: e^{a t}, so the
thousandfold horizon is ln(1000) / a and one Lyapunov time 1 / a), and a driven pendulum from the continuous
oracle (RK4), chaotic under a drive of 1.15 at 2/3 rad/s (Baker and Gollub) and periodic under 0.2.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import flowchart2sdnn as sd
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.identify.assess.noise import noise_level
from flowchart2sdnn.identify.offline.problem import build_problem
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.identify.shooting.auto import GROWTH_BOUND, choose_shooting
from flowchart2sdnn.simulate.continuous import simulate_continuous

ROOT = Path(__file__).resolve().parent
PENDULUM = ROOT / "data" / "shooting" / "pendulum_plant.yaml"

LINEAR = """\
sdnn: 1
name: linear_growth
sample_time: 0.001
substeps: 1
inputs:
  u: {{unit: 1/s}}
outputs:
  x: {{unit: 1}}
parameters:
  a: {{init: {a}, unit: 1/s}}
blocks:
  dx: {{type: sum, in: [u, ax], unit: 1/s}}
  x:  {{type: integrator, in: dx, unit: 1, init: 1}}
  ax: {{type: gain, in: x, k: a}}
"""


def _linear_problem(tmp_path, a: float, q: int = 10000):
    path = tmp_path / "linear.yaml"
    path.write_text(LINEAR.format(a=a))
    chart = load_diagram(path)
    t = np.arange(q) * chart.sample_time
    frame = {"time": t, "u": np.zeros(q), "x": np.exp(a * t)}
    return build_problem(chart, sd.dataset_from_frame(frame, time="time", inputs=["u"], outputs=["x"]))


def test_auto_on_a_growing_linear_chart_matches_the_hand_computation(tmp_path):
    # x' = a x: a moved start grows as e^{a t} exactly (in units of the state's RMS), so it reaches 1000-fold
    # at t = ln(1000) / a = 3.454 s (3454 samples) and one Lyapunov time is 1 / a = 0.5 s = 500 samples; the
    # first stage is 16x shorter, 31 samples (5000 samples in at most 256 segments need only 20)
    a = 2.0
    choice = choose_shooting(_linear_problem(tmp_path, a, q=5000), np.array([a]))
    horizon = math.log(GROWTH_BOUND) / a / 0.001
    assert choice.horizon == pytest.approx(horizon, rel=0.01)
    assert choice.lyapunov == pytest.approx(1 / a / 0.001, rel=0.01)
    assert choice.length == pytest.approx(1 / a / 0.001 / 16, abs=1)
    # 10 000 samples need segments of at least 40 to stay within 256: the first stage is raised to that
    assert choose_shooting(_linear_problem(tmp_path, a), np.array([a])).length == 40


def test_auto_is_off_when_a_moved_start_decays(tmp_path):
    # x' = -a x forgets a moved start: e^{-a t} <= 1 throughout
    choice = choose_shooting(_linear_problem(tmp_path, -2.0), np.array([-2.0]))
    assert choice.length is None and choice.horizon is None
    assert choice.peak <= 1.0 + 1e-6


def test_auto_is_off_when_the_horizon_is_longer_than_the_record(tmp_path):
    # a = 0.1: the 1000-fold horizon is 69 s, longer than the 10 s record
    choice = choose_shooting(_linear_problem(tmp_path, 0.1), np.array([0.1]))
    assert choice.length is None
    assert choice.peak == pytest.approx(math.exp(0.1 * 9.999), rel=0.01)


def _pendulum(drive: float, seed: int = 3, q: int = 1000):
    plant = load_diagram(PENDULUM)
    t = np.arange(q) * plant.sample_time
    u = drive * np.cos(2 / 3 * t)
    y = simulate_continuous(plant, u[:, None]) + 0.01 * np.random.default_rng(seed).standard_normal((q, 2))
    data = sd.dataset_from_frame({"time": t, "u": u, "v": y[:, 0], "theta": y[:, 1]}, time="time", inputs=["u"],
                                 outputs=["v", "theta"])
    chart = load_diagram(PENDULUM)
    from dataclasses import replace

    rough = {"b": 0.52, "k": 0.98}  # at b 0.55, k 0.95 the chart is not chaotic on this record: auto is off
    chart = replace(chart, parameters=tuple(replace(p, init=rough[p.name]) for p in chart.parameters))
    return chart, data


def test_auto_sees_the_chaotic_pendulum_and_not_the_periodic_one():
    for drive, chaotic in ((1.15, True), (0.2, False)):
        chart, data = _pendulum(drive)
        problem = build_problem(chart, data)
        choice = choose_shooting(problem, problem.compiled.theta0())
        assert (choice.length is not None) is chaotic, choice.reason


def test_a_chaotic_record_keeps_a_segmented_stage_and_says_so():
    chart, data = _pendulum(1.15)
    res = identify(chart, data, settings=IdentifySettings(shooting=25, floor_bias=False))
    shooting = res.extra["shooting"]
    assert shooting["predictable"] is False and shooting["final_length"] == 25
    # every longer stage, single shooting included, was tried from the kept one and refused
    assert shooting["stages"][0].get("kept") and all(s.get("refused") for s in shooting["stages"][1:])
    assert [s["length"] for s in shooting["stages"]] == [25, 100, 400, data.n_rows - 1]
    assert any("does not follow the whole records" in w for w in res.warnings)
    (said,) = [n for n in res.notices if n.code == "SHOOT001"]
    assert said.numbers["final_length"] == res.extra["shooting"]["final_length"]
    # the parameters come from the segmented stage, and it found the pendulum
    assert res.parameters["b"].value == pytest.approx(0.5, rel=0.02)
    assert res.parameters["k"].value == pytest.approx(1.0, rel=0.02)


def test_the_noise_estimate_from_second_differences():
    # white noise of 0.01 on a slow sine: the estimate finds 0.01 within 5 %
    _, data = _pendulum(0.2, q=4000)
    problem = build_problem(load_diagram(PENDULUM), data)
    assert math.sqrt(noise_level(problem)) == pytest.approx(0.01, rel=0.05)


def test_a_smooth_record_ends_in_single_shooting():
    chart, data = _pendulum(0.2)
    res = identify(chart, data, settings=IdentifySettings(shooting=25, floor_bias=False))
    shooting = res.extra["shooting"]
    assert shooting["predictable"] is True
    assert shooting["stages"][-1].get("kept") and not any(s.get("refused") for s in shooting["stages"])
    assert not any("does not follow" in w for w in res.warnings)
    assert res.parameters["b"].value == pytest.approx(0.5, rel=0.03)


def test_cli_auto_writes_its_choice_and_refuses_a_bad_value(tmp_path):
    from click.testing import CliRunner

    from flowchart2sdnn.cli import main

    chart, data = _pendulum(0.2)
    csv = tmp_path / "p.csv"
    c = data.columns
    csv.write_text("time,u,v,theta\n" + "\n".join(
        f"{k * 0.1:.4f},{float(u)!r},{float(v)!r},{float(th)!r}"
        for k, (u, v, th) in enumerate(zip(c["u"], c["v"], c["theta"], strict=True))))
    out = tmp_path / "r.json"
    r = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(PENDULUM), "-o", str(out),
                                  "--shooting", "auto", "--no-floor-bias"])
    assert r.exit_code == 0, r.output
    import json

    shooting = json.loads(out.read_text())["shooting"]
    assert shooting["requested"] == "auto" and shooting["auto"]["chose"] == "off"
    bad = CliRunner().invoke(main, ["identify", str(csv), "--diagram", str(PENDULUM), "--shooting", "sometimes"])
    assert bad.exit_code == 2 and "'off', 'auto' or a segment length" in bad.output



def test_auto_fits_the_chaotic_pendulum_with_free_starts_and_reports_its_horizon():
    # the default (shooting and starts auto) on the chaotic record: a length is chosen, the measured states
    # start each segment free, and the kept stage finds the oracle's pendulum (b 0.5, k 1.0)
    chart, data = _pendulum(1.15)
    res = identify(chart, data, settings=IdentifySettings(floor_bias=False))
    shooting = res.extra["shooting"]
    assert shooting["requested"] == "auto" and shooting["auto"]["chose"] != "off"
    assert shooting["starts"] == "free"
    assert shooting["auto"]["lyapunov_samples"] >= shooting["length"]
    assert res.parameters["b"].value == pytest.approx(0.5, rel=0.02)
    assert res.parameters["k"].value == pytest.approx(1.0, rel=0.02)
    # a length given by hand keeps the data's starts; the periodic record keeps single shooting
    assert identify(chart, data, settings=IdentifySettings(shooting=25, floor_bias=False, max_iter=3)
                    ).extra["shooting"]["starts"] == "data"
    chart, data = _pendulum(0.2)
    assert identify(chart, data, settings=IdentifySettings(floor_bias=False)).extra["shooting"]["auto"]["chose"] == "off"


def test_auto_takes_a_second_look_when_single_shooting_misses_a_chaotic_record():
    # at b 0.55, k 0.95 the chart forgets a moved start on the chaotic record (growth 5.3, under the 1000 bound but
    # above the stable charts' 4): auto chooses off, single shooting ends far off the noise floor, and the retry in
    # the shortest segments (999 samples in 256: 4) is kept and finds the oracle's pendulum (b 0.5, k 1.0; k to
    # 3 % from 0.4 s segments). On the periodic record single shooting reaches the floor: no second look.
    from dataclasses import replace

    for drive, chaotic in ((1.15, True), (0.2, False)):
        chart, data = _pendulum(drive)
        rough = {"b": 0.55, "k": 0.95}
        chart = replace(chart, parameters=tuple(replace(p, init=rough[p.name]) for p in chart.parameters))
        res = identify(chart, data, settings=IdentifySettings(floor_bias=False))
        auto = res.extra["shooting"]["auto"]
        assert auto["chose"] == "off"
        if not chaotic:
            assert "second_look" not in auto and res.extra["shooting"]["stages"] == []
            continue
        look = auto["second_look"]
        assert look["kept"] == "multiple shooting" and look["length"] == 4 and look["starts"] == "free"
        assert look["cost_per_sample"] < look["single_shooting_cost_per_sample"]
        assert res.extra["shooting"]["length"] == 4 and res.extra["shooting"]["predictable"] is False
        assert res.parameters["b"].value == pytest.approx(0.5, rel=0.02)
        assert res.parameters["k"].value == pytest.approx(1.0, rel=0.03)
