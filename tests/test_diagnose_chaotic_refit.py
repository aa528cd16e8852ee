"""A neutral effect whose refit makes the drive chaotic: the brief refit grows its horizon (issue 16, cogging).

The plant: the diagnose bench's two-mass drive with motor cogging 0.6 sin(6 phi1) (tests/data/diagnose/
two_mass_cogging_plant.yaml), simulated in continuous time (`excite`, RK4) with 0.01 rad/s of noise on both
speeds: one 30 s training record, one 3 s validation record. The chart: the user's two-mass chart (inits 10-20 %
off) with cogging p = 6 added at the motor speed at amplitude 0 (neutral). Oracles: the plant's own numbers (the
amplitude 0.6 N·m in the sine, 0 in the cosine, since both angles start at 0; J1, J2, c) and the noise level.
Before the fix diagnose refitted a neutral candidate over the whole record only: from amplitude 0 the brief
refit stopped in a local minimum (validation RMS 0.10, 10x the noise) and cogging was never accepted.
"""

from __future__ import annotations

import pytest
from diagnose_bench import chart, record

from flowchart2sdnn.diagnose.effects import Cogging
from flowchart2sdnn.diagnose.fitting import fit_chart, unpredictable
from flowchart2sdnn.diagnose.graph import speeds
from flowchart2sdnn.diagnose.loop import GROW_IF_UNPREDICTABLE, DiagnoseSettings, refit_unit

NOISE = 0.01
SETTINGS = DiagnoseSettings()


@pytest.fixture(scope="module")
def bench():
    plant = chart("two_mass_cogging_plant")
    train = [record(plant, 30.0, 1, NOISE)]
    records = [(record(plant, 3.0, 101, NOISE), 0)]
    nominal = chart("two_mass_nominal")
    place = next(p for p in speeds(nominal) if p.at == "w1")
    return train, records, Cogging().patch(nominal, place, 6)


def _values(fitted) -> dict:
    return dict(zip(fitted.identification.problem.names, map(float, fitted.identification.x), strict=True))


def test_a_neutral_cogging_refit_grows_its_horizon_and_finds_the_amplitude(bench):
    train, records, patched = bench
    unit = (patched, train, records, SETTINGS, SETTINGS.refit_iter, 1, "nominal", (), GROW_IF_UNPREDICTABLE)
    fitted, _ = refit_unit(unit)
    assert fitted.start == "horizon"
    assert fitted.validation_rms < 1.5 * NOISE
    x = _values(fitted)
    assert x["cog6_A_w1"] == pytest.approx(0.6, rel=0.02) and abs(x["cog6_B_w1"]) < 0.02
    for name, truth in (("J1", 0.1912), ("J2", 0.3838), ("c", 477.2)):
        assert x[name] == pytest.approx(truth, rel=0.01), name


def test_the_plain_refit_is_stuck_and_flagged_unpredictable_the_grown_one_is_not(bench):
    train, records, patched = bench
    plain = fit_chart(patched, train, records, SETTINGS, SETTINGS.refit_iter, 1, "nominal")
    # what diagnose did before: over the whole 30 s record from amplitude 0 the refit stays far off the noise
    assert plain.validation_rms > 5 * NOISE
    assert unpredictable(plain, train, SETTINGS)
    grown, _ = refit_unit((patched, train, records, SETTINGS, SETTINGS.refit_iter, 1, "nominal", ()))
    assert grown.validation_rms < 1.5 * NOISE
    assert not unpredictable(grown, train, SETTINGS)  # at the noise floor: nothing left to grow for


def test_a_stable_chart_off_the_floor_is_not_unpredictable():
    # a one-mass drive forgets a moved start (its speed decays with b/J): however poor the fit, no growing horizon
    plant = chart("one_mass_friction_plant")
    train = [record(plant, 3.0, 7, 0.02)]
    fitted = fit_chart(chart("one_mass"), train, [(record(plant, 1.0, 107, 0.02), 0)], SETTINGS, 5, 0, "chart")
    assert fitted.rms > 2 * 0.02  # off the floor (NOISE_MARGIN x the noise): the friction is missing
    assert not unpredictable(fitted, train, SETTINGS)
