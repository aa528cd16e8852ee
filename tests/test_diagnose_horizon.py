"""diagnose's growing-horizon refit from the chart as given, and the median-record acceptance rule.

Oracles: hand-enumerated stage lengths; each record's RMS recomputed from a plain simulation of the fitted
chart (diagnose_bench.simulate, not the metrics code under test); hand-built fits for the acceptance rule.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from diagnose_bench import chart, record, simulate

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.graph import speeds
from flowchart2sdnn.diagnose.loop import (
    GROW_ALWAYS,
    GROW_IF_UNPREDICTABLE,
    DiagnoseSettings,
    Fitted,
    diagnose,
    fit_chart,
    horizons,
    refit_unit,
    refusal,
)

EXCITATION = {"amplitude": (-6.0, 6.0), "relay_level": 3.0, "relay_switch": 1.0, "relay_band": 0.2}
SETTINGS = DiagnoseSettings(refit_iter=10, max_iter=10)


class _Rows:
    def __init__(self, n_rows: int):
        self.n_rows = n_rows


@pytest.mark.parametrize("rows, first, stages", [
    ([3001] * 10, 500, [500, 2000]),
    ([30001], 500, [500, 2000, 8000]),
    ([2000, 120], 500, [500]),          # 2000 is the whole longest record: no stage of that length
    ([400], 500, []),                   # shorter than the first stage: the whole records at once
    ([3001], 0, []),                    # switched off
])
def test_stages_grow_fourfold_up_to_the_longest_record(rows, first, stages):
    assert horizons([_Rows(n) for n in rows], first) == stages


def test_settings_refuse_a_negative_horizon():
    with pytest.raises(ValueError, match="horizon"):
        DiagnoseSettings(horizon=-1)


@pytest.fixture(scope="module")
def one_mass():
    plant = chart("one_mass_friction_plant")
    train = [record(plant, 1.5, 7, 0.02, **EXCITATION), record(plant, 1.0, 8, 0.02, **EXCITATION)]
    records = [(record(plant, 1.0, 107 + i, 0.02, **EXCITATION), 0) for i in range(3)]
    nominal = chart("one_mass")
    place = speeds(nominal)[0]
    return train, records, BUILTIN_EFFECTS["damping"].patch(nominal, place)


def test_the_refit_from_the_chart_as_given_keeps_the_lower_cost_of_both_schedules(one_mass):
    train, records, patched = one_mass
    plain = fit_chart(patched, train, records, SETTINGS, SETTINGS.refit_iter, 0, "nominal")
    unit = (patched, train, records, SETTINGS, SETTINGS.refit_iter, 0, "nominal", ())
    fitted, seconds = refit_unit(unit)
    assert seconds > 0 and fitted.start in ("nominal", "horizon")
    assert fitted.cost <= plain.cost
    if fitted.start == "nominal":
        assert fitted.cost == plain.cost
    off, _ = refit_unit((patched, train, records, replace(SETTINGS, horizon=0), SETTINGS.refit_iter, 0,
                         "nominal", ()))
    assert off.start == "nominal" and off.cost == pytest.approx(plain.cost, rel=1e-12)


def test_the_median_record_rms_is_each_records_rms_of_a_plain_simulation(one_mass):
    train, records, patched = one_mass
    fitted = fit_chart(patched, train, records, SETTINGS, 5, 0, "nominal")
    names = list(fitted.diagram.output_names)
    each = []
    for ds, _ in records:
        u = np.column_stack([ds.columns[n] for n in fitted.diagram.input_names])
        y = np.column_stack([ds.columns[n] for n in names])
        yhat = simulate(fitted.diagram, u)  # zoh: row 0 is the initial state, as the records start at rest
        each.append(math.sqrt(np.mean((y[1:] - yhat[1:]) ** 2)))
    assert fitted.validation_median == pytest.approx(float(np.median(each)), rel=1e-6)


def _fitted(pooled: float, per_record: list[float], cost: float = 1.0) -> Fitted:
    return Fitted(None, cost, 1000, 3, {"rms_all": pooled, "records": [], "rms_records": per_record})


def test_a_gain_on_one_record_only_is_refused():
    before = _fitted(0.060, [0.052, 0.083, 0.052, 0.051, 0.053], cost=1.0)
    one = _fitted(0.057, [0.052, 0.074, 0.052, 0.051, 0.053], cost=0.9)
    assert refusal(one, before, DiagnoseSettings()) == "validation RMS of the median record did not fall enough"
    every = _fitted(0.050, [0.047, 0.062, 0.048, 0.047, 0.049], cost=0.9)
    assert refusal(every, before, DiagnoseSettings()) is None
    worse_fit = _fitted(0.050, [0.047, 0.062, 0.048, 0.047, 0.049], cost=1.1)
    assert refusal(worse_fit, before, DiagnoseSettings()) == "BIC did not fall"
    assert refusal(_fitted(0.0595, [0.05] * 5, 0.9), before, DiagnoseSettings()) == \
        "validation RMS did not fall enough"


class _Recording:
    """A serial executor that keeps the refit units it runs (the screen's units pass through)."""

    def __init__(self):
        self.units = []

    def map(self, fn, items):
        items = list(items)
        if fn is refit_unit:
            self.units += items
        return [fn(u) for u in items]


def test_candidates_that_are_not_neutral_always_grow_the_horizon_neutral_ones_when_unpredictable():
    # noise 0.0005: the chart without the dead time ends far above it, where a neutral candidate is refitted from
    # the chart as given too (near the noise only from the current fit: diagnose.refits.brief_refits)
    plant = chart("one_mass_dead_time_plant")
    train = record(plant, 2.0, 3, 0.0005, **EXCITATION)
    val = record(plant, 1.0, 101, 0.0005, **EXCITATION)
    ex = _Recording()
    settings = DiagnoseSettings(rounds=1, top=3, refit_iter=5, max_iter=5, alpha=0.999, one_step=False)  # refit both
    effects = [BUILTIN_EFFECTS[n] for n in ("friction", "dead_time")]
    diagnose(chart("one_mass"), train, [val], settings, effects, executor=ex)
    # a unit: (chart, train, records, settings, max_iter, dof, start, accepted, grow); an input's dead time
    # marks dead_time; a neutral candidate (friction) grows only when its plain refit is unpredictable
    grown = {any(s.delay is not None for s in u[0].inputs): u[8] for u in ex.units if u[6] == "nominal"}
    assert grown == {True: GROW_ALWAYS, False: GROW_IF_UNPREDICTABLE}
    assert all(u[3].horizon == settings.horizon for u in ex.units)
