"""The score test on the part of the record the current fit still follows (issue 16, cogging at seeds 2-3).

The rule (diagnose/tracked.py): the tracked part of a record ends at the first window of WINDOW rows whose mean
square residual exceeds FOLLOW_FRACTION² times the record's whole mean square. Oracle for the rule: a running
mean square computed by a plain loop over a residual with a known divergence. Oracle for the use: the plant
(tests/data/diagnose/two_mass_cogging_plant.yaml, continuous RK4 via `excite`, 0.01 rad/s noise) has cogging
at the motor speed w1; the chart without it, started at the bench's rough inits (seed 3: each parameter x/÷2,
numpy default_rng(3)), fits to train RMS 0.66 - the fit loses the chaotic record after about 1 s. Scored over
the whole record the cogging place is not first; scored on the tracked part it is.
"""

from __future__ import annotations

import numpy as np
import pytest
from diagnose_bench import chart, record, rough_chart

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS
from flowchart2sdnn.diagnose.fitting import current_problem, effect_scales, fit_chart
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, candidates
from flowchart2sdnn.diagnose.score import screen
from flowchart2sdnn.diagnose.tracked import (
    FOLLOW_FRACTION,
    ROWS_PER_QUANTITY,
    WINDOW,
    prefix_problem,
    record_rows,
    score_rows,
    tracked_rows,
)
from flowchart2sdnn.identify.assess.noise import NOISE_MARGIN

NOISE = 0.01
SETTINGS = DiagnoseSettings()


def _loop_prefix(e: np.ndarray, window: int, bound: float) -> int:
    """The first window whose mean square (over rows and outputs) exceeds `bound`, by a plain loop."""
    for i in range(len(e) - window + 1):
        if sum(float(v) ** 2 for v in e[i:i + window].ravel()) / e[i:i + window].size > bound:
            return i + window - 1
    return len(e)


def test_the_tracked_part_ends_where_a_hand_computed_running_rms_crosses_half_the_diverged_level():
    rng = np.random.default_rng(0)
    n, t0 = 3000, 1200
    e = NOISE * rng.standard_normal((n, 2))
    grow = np.minimum(np.exp((np.arange(n) - t0) / 60.0), 40.0)  # divergence after t0, saturating at 40x noise
    e[:, 0] += NOISE * grow * np.sin(np.arange(n) / 7.0)
    whole = float(np.mean(e ** 2))
    expect = _loop_prefix(e, WINDOW, FOLLOW_FRACTION ** 2 * whole)
    assert t0 < expect < n  # the divergence is found after t0, not before
    assert tracked_rows(e) == expect
    # a residual at the noise floor is followed whole, however a window fluctuates
    assert tracked_rows(e[:t0], floor_ms=NOISE_MARGIN ** 2 * NOISE ** 2) == t0
    # short residuals: whole
    assert tracked_rows(e[:WINDOW - 1]) == WINDOW - 1
    # raised to a floor of 500 rows, still followed better than the rest: the part is kept
    assert record_rows(e, NOISE ** 2, 500) == expect
    # raised to 2000 rows the part takes in the diverged residual: not followed better than the rest, whole record
    assert np.mean(e[:2000] ** 2) > FOLLOW_FRACTION ** 2 * whole
    assert record_rows(e, NOISE ** 2, 2000) == n
    # a residual off the floor all along (5x the noise, no divergence): the first window crosses the bound, but
    # the floor's 500 rows are not followed better than the rest, so the whole record is scored
    flat = 5 * NOISE * rng.standard_normal((n, 2))
    assert tracked_rows(flat) < 500
    assert record_rows(flat, NOISE_MARGIN ** 2 * NOISE ** 2, 500) == n


@pytest.fixture(scope="module")
def diverged():
    plant = chart("two_mass_cogging_plant")
    given = chart("two_mass_nominal")
    rough, _ = rough_chart(given, 3, plant.parameter_values())
    train = [record(plant, 30.0, 3, NOISE)]
    records = [(record(plant, 3.0, 103, NOISE), 0)]
    fitted = fit_chart(rough, train, records, SETTINGS, SETTINGS.max_iter, 0, "chart")
    return fitted, train


def _place_rank(scr, key) -> int:
    return [s.candidate.key for s in scr.best_per_place()].index(key) + 1


def test_the_cogging_place_ranks_first_on_the_tracked_part_not_on_the_whole_record(diverged):
    fitted, train = diverged
    assert fitted.rms > 20 * NOISE  # the first fit has lost the chaotic record
    problem = current_problem(fitted, train, SETTINGS)
    rows = score_rows(fitted, problem, train, SETTINGS)
    assert rows is not None and len(rows) == 1
    # the rows are the hand-computed running RMS's crossing, raised to the floor
    e = problem.residual(problem.compiled.theta0()).reshape(-1, 2)
    hand = _loop_prefix(e, WINDOW, FOLLOW_FRACTION ** 2 * float(np.mean(e ** 2)))
    floor = max(SETTINGS.horizon, ROWS_PER_QUANTITY * len(problem.names), 2 * WINDOW)
    assert rows[0] == min(len(e), max(floor, hand)) < len(e) // 4
    # the fit follows the tracked part: its residual there is far below the whole record's
    assert np.sqrt(np.mean(e[:rows[0]] ** 2)) < 0.5 * fitted.rms
    cands = candidates(tuple(BUILTIN_EFFECTS.values()), fitted.diagram, effect_scales(problem), set())
    part_problem, cut = prefix_problem(fitted, train, SETTINGS, rows)
    assert part_problem.targets.shape[0] == rows[0]
    part = screen(cands, part_problem, cut, SETTINGS.alignment, SETTINGS.seed, SETTINGS.top_options)
    assert _place_rank(part, ("cogging", "w1")) == 1
    whole = screen(cands, problem, train, SETTINGS.alignment, SETTINGS.seed, SETTINGS.top_options)
    assert _place_rank(whole, ("cogging", "w1")) > SETTINGS.top  # why: not even refitted from the whole record


def test_a_fit_at_the_noise_floor_scores_the_whole_record():
    plant = chart("two_mass_cogging_plant")
    train = [record(plant, 5.0, 3, NOISE)]
    records = [(record(plant, 2.0, 103, NOISE), 0)]
    fitted = fit_chart(plant, train, records, SETTINGS, 5, 0, "chart")  # the plant itself: nothing missing
    problem = current_problem(fitted, train, SETTINGS)
    assert score_rows(fitted, problem, train, SETTINGS) is None


def test_the_tracked_parts_picks_join_the_refit_set_once_as_their_whole_record_scores():
    from types import SimpleNamespace

    from flowchart2sdnn.diagnose.choice import union_picks
    from flowchart2sdnn.diagnose.score import Baseline, Score, Screen

    def cand(effect, at, label):
        return SimpleNamespace(key=(effect, at), label=label)

    def score(c, value):
        return Score(c, value, 1.0, 1.0 - value, 1, 2 * value, 0.0)

    sat, cog6, cog8 = cand("saturation", "M1", "L=9"), cand("cogging", "w1", "p=6"), cand("cogging", "w1", "p=8")
    whole = [score(sat, 10.0), score(cog6, 3.0), score(cog8, 2.0)]
    scr = Screen(Baseline(1.0, 0.0, 1, 10, 1, 0.1), tuple(whole))
    best = [whole[0], whole[1]]
    picks = [score(cog8, 50.0), score(cog6, 40.0)]  # scored on the tracked part: already-present cog6 not twice
    out = union_picks(best, picks, scr)
    assert out == [whole[0], whole[1], whole[2]]  # cog8 joins as its whole-record Score (the report's ranking)
