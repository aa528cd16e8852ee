"""Acceptance of `sdnn diagnose` (issue 5) on the two-mass virtual test bench: slow, run with `-m slow`.

Each plant is the paper's two-mass drive with exactly one effect the chart lacks, simulated in continuous
time with measurement noise (std NOISE on both speeds). The true effect at the true place must be accepted
first (a dead time with the right number of samples), the validation RMS must fall by 3x or to within 20 %
of the noise floor, and the chart's linear parameters must come back within 5 % once it is accepted.

Why NOISE = 0.05 rad/s (about 1 % of the speeds' RMS, an encoder-differentiated speed): the compiled
two-mass network integrates w2 half a sample early (explicit/implicit Euler on the chosen feedback edges),
which leaves a systematic 0.013 rad/s RMS on w2 with the exact chart. With 0.01 rad/s of noise that
discretisation error is most of the residual and the loop rightly "explains" part of it with a damping term;
see benchmarks/notes/diagnose.md.
"""

from __future__ import annotations

import pytest
from diagnose_bench import chart, record

from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose

pytestmark = pytest.mark.slow

NOISE = 0.05
TRUTH = {"J1": 0.1912, "J2": 0.3838, "c": 477.2, "d": 0.2406, "b1": 0.05}


def _check(report: dict, effect: str | tuple, at: str, option=None, linear=("J1", "J2", "c", "d")) -> dict:
    first = report["rounds"][0]
    assert report["accepted"], report["stop"]
    acc = report["accepted"][0]
    effects = (effect,) if isinstance(effect, str) else effect
    assert acc["effect"] in effects and acc["at"] == at, report["accepted"]
    if option is not None:
        assert acc["option"] == option
    before, after = first["validation_rms_before"], first["validation_rms_after"]
    assert after <= before / 3 or after <= 1.2 * NOISE, (before, after)
    for name in linear:
        assert first["parameters"][name] == pytest.approx(TRUTH[name], rel=0.05), name
    return first


def _long(plant: str, chart_name: str, seed: int = 1):
    p = chart(plant)
    train = record(p, 30.0, seed, NOISE)
    val = record(p, 10.0, seed + 100, NOISE)
    return diagnose(chart(chart_name), train, [val], DiagnoseSettings(rounds=2)).report


def test_friction_on_the_load():
    _check(_long("two_mass_friction_plant", "two_mass_shaft"), "friction", "w2")


def test_input_dead_time_with_the_right_number_of_samples():
    _check(_long("two_mass_dead_time_plant", "two_mass_nominal"), "dead_time", "M1", 6,
           ("J1", "J2", "c", "d", "b1"))


def test_input_saturation_with_its_limits():
    first = _check(_long("two_mass_saturation_plant", "two_mass_nominal"), "saturation", "M1",
                   linear=("J1", "J2", "c", "d", "b1"))
    p = first["parameters"]
    assert p["M1_off"] - p["M1_lim"] == pytest.approx(-5.0, abs=0.1)
    assert p["M1_off"] + p["M1_lim"] == pytest.approx(6.0, abs=0.1)


def test_missing_viscous_friction_is_added_as_damping():
    first = _check(_long("two_mass_base_plant", "two_mass_shaft"), "damping", "w1")
    assert first["parameters"]["b_w1"] == pytest.approx(TRUTH["b1"], rel=0.05)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_nothing_is_accepted_when_nothing_is_missing(seed):
    report = _long("two_mass_base_plant", "two_mass_nominal", seed)
    assert report["accepted"] == [], report["rounds"]


def _short_records(plant: str, chart_name: str):
    """Chaotic drives: ten 3 s training records and five 3 s validation records, each from rest."""
    p = chart(plant)
    train = [record(p, 3.0, 1 + i, NOISE) for i in range(10)]
    val = [record(p, 3.0, 1001 + i, NOISE) for i in range(5)]
    return diagnose(chart(chart_name), train, val, DiagnoseSettings(rounds=2)).report


@pytest.fixture(scope="module")
def backlash_report():
    return _short_records("two_mass_backlash_plant", "two_mass_nominal")


def test_shaft_backlash_on_short_records_meets_the_issue_criteria(backlash_report):
    # the learned odd curve (backlash) or the exact gap (dead_zone): either is backlash at the shaft. The exact
    # gap wins once its refit from the chart as given grows its horizon (0.5 s of each record first): validation
    # RMS 0.2945 -> 0.0595, every linear parameter within 1 %
    first = _check(backlash_report, ("backlash", "dead_zone"), "dphi", linear=("J1", "J2", "c", "d", "b1"))
    if backlash_report["accepted"][0]["effect"] == "dead_zone":
        assert first["parameters"]["dphi_gap"] == pytest.approx(0.004, rel=0.05)


def test_shaft_backlash_nothing_else_is_accepted(backlash_report):
    # after the gap the four typical validation records sit at the noise floor; a term that only moves the one
    # record whose chaotic trajectory diverged (round 2 used to accept cogging there) must not be added
    assert len(backlash_report["accepted"]) == 1, backlash_report["rounds"]


def test_motor_cogging_on_short_records():
    _check(_short_records("two_mass_cogging_plant", "two_mass_nominal"), "cogging", "w1", 6,
           ("J1", "J2", "c", "d", "b1"))
