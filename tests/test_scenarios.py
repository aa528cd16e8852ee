"""The scenario generator of benchmarks/scenarios/: reproducible draws, every combination simulates, the user's
chart is the plant minus exactly the missing effects, the loops are closed on the logged speed, encoder speeds
are difference quotients of a quantised angle, the effects have their physics, and the Wilson intervals."""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

# the generator lives in the repository's benchmarks/ (not installed): importable however pytest is started
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.scenarios.draw import CATEGORIES, draw, draw_spec, parse_category, write_scenario
from benchmarks.scenarios.excite import EXCITATIONS, excitation_inputs
from benchmarks.scenarios.missing import KINDS, SENSOR_STAGE, draw_missing, patch_plant, places
from benchmarks.scenarios.plants import FAMILIES, base_chart, chart_text, draw_plant
from benchmarks.scenarios.rates import judge, summarise, wilson
from benchmarks.scenarios.score import main as score_main
from benchmarks.scenarios.sensors import SENSORS, Sensor, difference_quotient, quantise
from flowchart2sdnn.analysis.lint import lint_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.simulate.continuous import simulate_continuous

SHORT = 1.0  # s: records long enough to exercise every path, short enough for a unit test


def _records_rng(seed: int) -> np.random.Generator:
    """The training record's stream, as draw.py derives it (to regenerate the reference a record used)."""
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(7)[5].spawn(2)[0])


# ------------------------------------------------------------------------------------------------ draws
def test_a_draw_is_reproducible_from_its_seed():
    a, b = draw(11, seconds=SHORT), draw(11, seconds=SHORT)
    assert a.chart_yaml == b.chart_yaml and a.plant_yaml == b.plant_yaml and a.truth == b.truth
    for name in a.train:
        assert np.array_equal(a.train[name], b.train[name])
        assert np.array_equal(a.validation[name], b.validation[name])
    c = draw_spec(12)
    assert (c.plant_yaml, c.chart_yaml) != (a.plant_yaml, a.chart_yaml)


def test_a_category_fixes_its_choices_and_leaves_the_rest():
    for category in CATEGORIES:
        count, excitation = parse_category(category)
        s = draw_spec(5, category)
        assert len(s.missing) == count
        assert excitation is None or s.excitation.kind == excitation
    # the plant does not depend on the category
    assert draw_spec(5, "complete").plant == draw_spec(5, "two-missing").plant
    with pytest.raises(ValueError, match="unknown category"):
        parse_category("three-missing")


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("excitation", EXCITATIONS)
@pytest.mark.parametrize("sensor", SENSORS)
def test_every_family_excitation_and_sensor_draws_and_simulates(family, excitation, sensor):
    s = draw(3, f"two-missing-{excitation}", family, SHORT, sensor)
    q = int(round(SHORT / s.plant.sample_time))
    for record in (s.train, s.validation):
        assert list(record) == ["time", "M1", *s.plant.outputs]
        assert all(len(v) == q and np.all(np.isfinite(v)) for v in record.values())
        assert np.ptp(record["M1"]) > 0 and all(np.ptp(record[y]) > 0 for y in s.plant.outputs)


@pytest.mark.parametrize("kind", KINDS)
def test_every_missing_effect_patches_into_a_plant_that_simulates(kind):
    rng = np.random.default_rng(1)
    family = next(f for f in ("two-mass", "spring") if places(draw_plant(np.random.default_rng(0), f), kind))
    plant = draw_plant(rng, family)
    for place in places(plant, kind):
        m = draw_missing(rng, plant, kind, place, input_peak=plant.torque)
        chart = base_chart(plant, "p", physical_friction=True)
        patch_plant(chart, m)
        if kind not in ("friction", *SENSOR_STAGE):
            assert any(name.startswith(f"{kind}_{place}") for name in chart["blocks"])
        u = np.sin(np.arange(500) * 0.01)[:, None] * plant.torque
        y = simulate_continuous(diagram_from_text(chart_text(chart)), u)
        assert np.all(np.isfinite(y))


# ------------------------------------------------------------------------------------------------ charts
def _blocks(text: str) -> dict:
    return yaml.safe_load(text)["blocks"]


def _terms(spec: dict) -> list[str]:
    t = spec.get("in", [])
    return list(t) if isinstance(t, list) else [t]


_FRICTION_OR_CURVE = re.compile(r"(NL|MR|sg|st|Fsg|Fst|Fv)\d")
_WRAPS_ITS_PLACE = ("dead_time", "input_lag", "saturation", "input_offset", "backlash")


def _without_effects_and_friction(blocks: dict, missing) -> dict:
    """The chart's blocks with every missing effect taken out (an effect between a signal and its readers
    replaced by the signal, an added torque dropped) and the friction terms (physical or learned) removed."""
    tags = {f"{m.kind}_{m.place}": m for m in missing}

    def owner(name: str):
        return next((m for t, m in tags.items() if name == t or name.startswith(t + "_")), None)

    out = {}
    for name, spec in blocks.items():
        if owner(name) or _FRICTION_OR_CURVE.fullmatch(name):
            continue
        terms = []
        for t in _terms(spec):
            signal, m = t.lstrip("-"), owner(t.lstrip("-"))
            if _FRICTION_OR_CURVE.fullmatch(signal):
                continue
            if m is None:
                terms.append(t)
            elif m.kind in _WRAPS_ITS_PLACE:
                terms.append(t.replace(signal, m.place))
        out[name] = {**spec, "in": terms} if "in" in spec else spec
    return out


@pytest.mark.parametrize("seed", range(40))
def test_the_users_chart_lints_clean_and_lacks_exactly_the_missing_effects(seed):
    s = draw_spec(seed)
    user = diagram_from_text(s.chart_yaml)
    assert lint_diagram(user) == []
    assert lint_diagram(diagram_from_text(s.plant_yaml)) == []
    plant, chart = _blocks(s.plant_yaml), _blocks(s.chart_yaml)
    for m in s.missing:  # every chart-stage effect is in the plant
        assert m.kind in ("friction", *SENSOR_STAGE) or f"{m.kind}_{m.place}" in plant
    assert _without_effects_and_friction(plant, s.missing) == _without_effects_and_friction(chart, ())
    # friction: a learned curve exactly where the plant's friction is not missing, with a viscous gain as drawn
    no_curve = {m.place for m in s.missing if m.kind == "friction"}
    assert {n for n in chart if n.startswith("NL")} == {f"NL{w[1:]}" for w in s.plant.speeds if w not in no_curve}
    assert all(n in chart for n in plant if n.startswith("Fv")) == s.plant.viscous_in_chart
    assert dict(s.sensor.offsets) == {m.place: m.size["o"] for m in s.missing if m.kind == "sensor_offset"}
    assert set(s.sensor.limits) == {m.place for m in s.missing if m.kind == "sensor_limit"}
    # the user's inits are the truth within x/÷2
    values = s.plant.parameters
    for p in user.parameters:
        assert 0.5 <= p.init / values[p.name] <= 2.0


def test_a_complete_scenario_has_no_missing_effect_and_the_same_structure():
    s = draw_spec(4, "complete-aprbs", "three-mass")
    plant, chart = _blocks(s.plant_yaml), _blocks(s.chart_yaml)
    assert s.missing == ()
    assert set(chart) - set(plant) == {"NL1", "NL2", "NL3"}
    for name in ("MB1", "MB2", "MB3", "MC1", "MC2", "dphi1", "dphi2", "acc3"):
        assert _terms(chart[name]) == _terms(plant[name])


# ------------------------------------------------------------------------------------------------ physics
def _simulate(chart: dict, u: np.ndarray) -> dict:
    return simulate_continuous(diagram_from_text(chart_text(chart)), u, signals=True)


def test_the_effects_have_their_physics():
    rng = np.random.default_rng(2)
    plant = draw_plant(rng, "two-mass")
    u = (np.sin(np.arange(2000) * 0.004) * plant.torque)[:, None]
    plain = _simulate(base_chart(plant, "p", True), u)

    def patched(kind, place, **size):
        m = draw_missing(np.random.default_rng(0), plant, kind, place, plant.torque)
        m.size.update(size)
        chart = base_chart(plant, "p", True)
        patch_plant(chart, m)
        return _simulate(chart, u), m

    sig, m = patched("dead_time", "M1")  # an n-sample dead time shifts every output by n samples
    n = m.size["n"]
    assert np.allclose(sig["w2"][n:], plain["w2"][:-n], atol=1e-9)
    sig, m = patched("saturation", "M1")
    assert np.allclose(sig["saturation_M1"], np.clip(u[:, 0], -m.size["L"], m.size["L"]))
    sig, m = patched("input_lag", "M1")  # d x / dt = (u - x) / tau, over each held input sample exactly
    x, decay = sig["input_lag_M1"], math.exp(-plant.sample_time / m.size["tau"])
    assert np.allclose(x[1:], u[:-1, 0] + (x[:-1] - u[:-1, 0]) * decay, rtol=1e-6, atol=1e-9 * plant.torque)
    sig, m = patched("unbalance", "w2")  # -m g l sin(load angle + phase) in the load's torque sum
    angle = np.concatenate([[0.0], np.cumsum(sig["w2"][:-1] + sig["w2"][1:]) / 2 * plant.sample_time])
    assert np.allclose(sig["unbalance_w2"], m.size["mgl"] * np.sin(angle + m.size["phase"]),
                       atol=1e-3 * m.size["mgl"])
    sig, m = patched("backlash", "dphi1")  # nothing transmitted inside the gap
    inside = np.abs(sig["dphi1"]) < m.size["gap"]
    assert np.allclose(sig["MC1"][inside], 0.0) and np.any(~inside)


def test_sensor_noise_has_the_drawn_size_and_colour():
    clean = {"w1": np.zeros(200_000)}
    ranges = {"w1": (10.0, 5.0)}
    white = Sensor("white", 7, fraction=0.01).measure(clean, ("w1",), 0.001, {}, ranges)["w1"]
    assert abs(np.std(white) / 0.1 - 1) < 0.02 and abs(np.corrcoef(white[1:], white[:-1])[0, 1]) < 0.01
    ar = Sensor("ar", 7, fraction=0.01, ar=0.8).measure(clean, ("w1",), 0.001, {}, ranges)["w1"]
    assert abs(np.std(ar) / 0.1 - 1) < 0.05 and abs(np.corrcoef(ar[1:], ar[:-1])[0, 1] - 0.8) < 0.01
    offset = Sensor("white", 7, fraction=0.01, offsets={"w1": 0.2}).measure(clean, ("w1",), 0.001, {}, ranges)
    assert np.mean(offset["w1"]) == pytest.approx(0.2, abs=1e-3)
    limited = Sensor("white", 7, fraction=0.01, limits={"w1": 0.02}).measure(clean, ("w1",), 0.001, {}, ranges)
    assert np.max(np.abs(limited["w1"])) == pytest.approx(0.02 * 5.0) and np.std(limited["w1"]) < 0.1


@pytest.mark.parametrize("excitation", EXCITATIONS)
def test_encoder_speeds_are_difference_quotients_of_a_quantised_angle(excitation):
    s = draw(8, f"complete-{excitation}", "spring", 2.0, "encoder")
    step, T = 2 * math.pi / s.sensor.counts, s.plant.sample_time
    counts = np.cumsum(s.train["w1"] * T) / step  # the angle the speeds integrate to, in counts
    assert s.train["w1"][0] == 0.0
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    # and it is the encoder's position reading, up to the start: both are that quantised angle
    position = s.train["phi1"] / step
    assert np.allclose(position, np.round(position), atol=1e-6)
    assert np.allclose(counts, position - position[0], atol=1e-6)
    assert np.array_equal(difference_quotient(quantise(np.array([0.0, 1.0, 2.5]), 4), 1.0),
                          np.array([0.0, 0.0, math.pi / 2]))


def test_the_closed_loop_is_closed_on_the_logged_speed():
    """The logged command is the PI controller's output computed from the logged (noisy) speed: recompute it."""
    seed = 9
    s = draw(seed, "complete-closed-loop", "two-mass", 2.0, "white")
    T, st, lim = s.plant.sample_time, s.excitation.settings, s.excitation.amplitude
    q = len(s.train["time"])
    ref = excitation_inputs(s.excitation, s.plant, q, _records_rng(seed))[:, 0]
    e = ref - s.train["w1"]
    integral, computed = 0.0, np.zeros(q)
    for k in range(q):
        integral = lim * np.clip((integral + st["ki"] * T * e[k]) / lim, -1, 1)
        computed[k] = lim * np.clip((st["kp"] * e[k] + integral) / lim, -1, 1)
    # applied one sample later; at t_0 the oracle's delay passes its operand's first value
    command = np.concatenate([computed[:1], computed[:-1]])
    assert s.facts["train"]["loop_mismatch"] < 1e-9
    assert np.allclose(s.train["M1"], command, atol=1e-7 * lim)
    # and the loop acts: the command follows the speed error (a PI's proportional part)
    assert np.corrcoef(s.train["M1"][1:], e[:-1])[0, 1] > 0.3


def test_the_relay_acts_on_the_logged_speed():
    s = draw(10, "complete-aprbs", "one-mass", 2.0, "ar")
    assert s.facts["train"]["loop_mismatch"] < 1e-9 and s.facts["train"]["passes"] == 2
    rng = _records_rng(10)
    aprbs = excitation_inputs(s.excitation, s.plant, len(s.train["time"]), rng)[:, 0]
    relay = s.train["M1"] - aprbs  # the relay's part: +-level, scaled in the band
    level = s.excitation.settings["relay_level"]
    assert np.all(np.isclose(np.abs(relay), level) | np.isclose(np.abs(relay), 0.2 * level))


# ------------------------------------------------------------------------------------------------ rates
def test_wilson_intervals_match_the_hand_computation():
    z2 = 1.959963984540054**2
    lo, hi = wilson(0, 40)
    assert lo == 0.0 and hi == pytest.approx(z2 / (40 + z2)) and round(hi, 3) == 0.088
    lo, hi = wilson(40, 40)
    assert lo == pytest.approx(40 / (40 + z2)) and hi == 1.0
    assert wilson(20, 40) == pytest.approx((0.351995, 0.648005), abs=1e-6)
    assert wilson(5, 20) == pytest.approx((0.111862, 0.468701), abs=1e-6)
    assert wilson(0, 0) == (0.0, 1.0)


def _truth(*missing, tolerated=()):
    return {"missing": [{"kind": k, "place": p, "accept": a} for k, p, a in missing], "tolerated": tolerated}


def _report(*accepted, stop="done_after_accepting"):
    return {"accepted": [{"effect": e, "at": p} for e, p in accepted], "stop": stop}


def test_judge_names_right_first_both_clean_and_refusals():
    one = _truth(("unbalance", "w2", [["cogging", "w2"]]))
    assert judge(one, _report(("cogging", "w2")))["right_first"] is True
    assert judge(one, _report(("cogging", "w1"), ("cogging", "w2")))["right_first"] is False
    assert judge(one, _report())["right_first"] is False
    two = _truth(("dead_time", "M1", [["dead_time", "M1"]]), ("backlash", "dphi1", [["backlash", "dphi1"],
                                                                                   ["dead_zone", "dphi1"]]))
    v = judge(two, _report(("dead_zone", "dphi1"), ("dead_time", "M1")))
    assert v["right_first"] and v["both"]
    assert judge(two, _report(("dead_time", "M1")))["both"] is False
    complete = _truth(tolerated=[["damping", "w1"]])
    assert judge(complete, _report(("damping", "w1")))["clean"] is True
    assert judge(complete, _report(("friction", "w1")))["clean"] is False
    refused = judge(complete, _report(stop="first_fit_not_converged"))
    assert refused["refused"] and refused["clean"] is False
    assert judge(one, None, "SdnnError: bad")["refused"]
    crashed = judge(one, None, "LinAlgError: singular", crashed=True)
    assert crashed["crashed"] and not crashed["refused"] and crashed["right_first"] is False
    ranked = _report()
    ranked["candidates"] = [{"round": 1, "rank": 1, "effect": "friction", "at": "w2", "score": 9.0},
                            {"round": 1, "rank": 3, "effect": "cogging", "at": "w2", "score": 2.0, "refitted": True}]
    v = judge(one, ranked)
    assert v["true_rank"] == 3 and v["true_refused"] and v["right_first"] is False
    inexpressible = judge(_truth(("nonlinear_spring", "phi1", [])), _report())
    assert inexpressible["right_first"] is None
    lines = summarise([{"category": "one-missing-aprbs", "seconds": 3.0, **judge(one, _report(("cogging", "w2")))}])
    assert any("right effect at the right place first 1/1" in line for line in lines)


def test_score_dry_writes_a_scenario(tmp_path, capsys):
    assert score_main(["--seed", "21", "--dry", "--seconds", "1", "--family", "one-mass", "--out",
                       str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "seeds: 21" in out
    files = {p.name for p in (tmp_path / "seed21").iterdir()}
    assert files == {"plant.yaml", "chart.yaml", "train.csv", "validation.csv", "truth.json"}


def test_written_records_read_back_as_the_chart_expects(tmp_path):
    from flowchart2sdnn.api import load_chart, read_csv

    s = draw(13, "one-missing", "two-mass", SHORT)
    paths = write_scenario(s, tmp_path)
    chart = load_chart(paths["chart"])
    data = read_csv(paths["train"], chart=chart)
    assert data.n_rows == len(s.train["time"])
    assert np.allclose(data.columns["w1"], s.train["w1"], rtol=1e-9)
