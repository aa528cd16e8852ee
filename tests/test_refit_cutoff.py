"""The cut-off of diagnose's brief refits: the bound (fitting.behind) by hand, and identify's `cutoff` hook ending a
fit with status cut_off (neither converged nor interrupted), at the iteration the hook names."""

from __future__ import annotations

import math

from test_per_record import _chart, _record

from flowchart2sdnn.diagnose.fitting import CUTOFF_PACE, behind
from flowchart2sdnn.identify import identify


def _feed(cutoff, costs):
    return [cutoff(it, c) for it, c in enumerate(costs, start=1)]


def test_the_bound_carries_the_recent_pace_over_the_iterations_left():
    assert CUTOFF_PACE == 3  # the hand numbers below are for a pace over the last three iterations
    # costs 10, 9, 8, 7 at iterations 1-4 of 10: pace 1 an iteration, 6 left, so it can reach 7 - 6 = 1
    assert _feed(behind(0.5, 10), [10, 9, 8, 7])[-1] is not None  # 1 > 0.5: cut
    assert _feed(behind(1.5, 10), [10, 9, 8, 7])[-1] is None  # 1 < 1.5: it may still get there
    assert all(r is None for r in _feed(behind(math.inf, 10), [10, 9, 8, 7, 6]))


def test_no_cut_before_a_pace_is_known_and_a_rising_cost_has_no_pace():
    assert _feed(behind(0.0, 100), [10, 9, 8]) == [None, None, None]  # three costs give no pace yet
    assert _feed(behind(4.9, 100), [5, 5, 5, 5])[-1] is not None  # flat: it stays at 5 > 4.9


def test_identify_stops_where_the_cutoff_says_with_its_own_status(tmp_path):
    chart = _chart(tmp_path, "false")
    data = _record(chart, 1, 0.03, noise=0.002)
    free = identify(chart, data, max_iter=50, floor_bias=False)
    assert free.lm.iterations > 1 and free.status != "cut_off"  # the fit would go on: the test can see a cut
    cut = identify(chart, data, max_iter=50, floor_bias=False,
                   cutoff=lambda it, cost: "enough" if it >= 1 else None)
    assert cut.status == "cut_off" and cut.message == "cut off: enough"
    assert cut.converged is False and cut.interrupted is False
    assert cut.lm.iterations == 1
