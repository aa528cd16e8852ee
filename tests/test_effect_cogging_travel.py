"""Cogging harmonics against the travel of a position the chart already has (issue 5, EMPS).

Oracle: the periods 2*pi/p computed here by hand against twice the position's RMS given in the scales.
"""

from __future__ import annotations

import math

from diagnose_bench import chart

from flowchart2sdnn.diagnose.effects import Cogging, Scales
from flowchart2sdnn.diagnose.graph import speeds

EMPS = chart("emps_mass")  # q = integral(v): a linear axis whose output is its position


def test_harmonics_longer_than_the_travel_are_not_offered():
    (place,) = speeds(EMPS)
    c = Cogging(harmonics=(1, 3, 12, 30, 1257))
    # rms(q) = 0.14 m: keep p with 2*pi/p <= 0.28 m, i.e. p >= 22.4
    assert c.options(EMPS, place, Scales({"q": 0.14, "v": 0.09})) == (30, 1257)
    assert Cogging().options(EMPS, place, Scales({"q": 0.14})) == ()
    # a long travel (100 m): every harmonic; 2*pi/1 = 6.28 <= 200
    assert c.options(EMPS, place, Scales({"q": 100.0})) == (1, 3, 12, 30, 1257)
    assert [p for p in (1, 3, 12) if 2 * math.pi / p <= 2 * 1.0] == [12]
    assert c.options(EMPS, place, Scales({"q": 1.0})) == (12, 30, 1257)


def test_charts_without_a_position_of_the_speed_keep_every_harmonic():
    two = chart("two_mass_nominal")  # dphi integrates w1 - w2, not one speed
    for place in speeds(two):
        assert Cogging().options(two, place, Scales({"dphi": 1e-3})) == Cogging().harmonics
    # no rms known for the position: unchanged as well
    assert Cogging().options(EMPS, speeds(EMPS)[0], Scales({})) == Cogging().harmonics
