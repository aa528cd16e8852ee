"""What an accepted effect takes off the candidate list (diagnose.loop): friction's physical terms leave room
for a learned curve at the same speed; a learned curve, or any other effect, takes its place.

The slow test runs the README tour's bench (two-mass plant with Stribeck friction on both machines, nothing
else) and checks the loop against that truth: every accepted effect is friction, and no cogging or backlash
the plant lacks is accepted (before this rule the third round filled the Stribeck bump with cogging p = 2).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from diagnose_bench import chart, record

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, Friction, Physical, Scales
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, candidates, diagnose, done_key
from flowchart2sdnn.diagram.validate import load_diagram

SCALES = Scales(rms={"w1": 5.0, "w2": 5.0, "dw": 0.5, "dphi": 0.01, "M1": 3.0}, lo={"M1": -7.0}, hi={"M1": 7.0})


def _friction_options(cands, at: str) -> set[str]:
    return {"coulomb" if isinstance(c.option, Physical) else "curve" for c in cands
            if c.name == "friction" and c.at == at}


def _accept(nominal, at: str, physical: bool) -> tuple:
    place = next(p for p in Friction().places(nominal) if p.at == at)
    option = next(o for o in Friction().options(nominal, place, SCALES) if isinstance(o, Physical) == physical)
    cand = next(c for c in candidates([Friction()], nominal, SCALES, set()) if c.at == at and c.option == option)
    return done_key(cand)


def test_after_the_physical_terms_a_learned_curve_is_still_offered_at_that_speed():
    nominal = chart("two_mass_nominal")
    before = candidates(list(BUILTIN_EFFECTS.values()), nominal, SCALES, set())
    assert _friction_options(before, "w2") == {"coulomb", "curve"}
    after = candidates(list(BUILTIN_EFFECTS.values()), nominal, SCALES, {_accept(nominal, "w2", physical=True)})
    assert _friction_options(after, "w2") == {"curve"}
    assert _friction_options(after, "w1") == {"coulomb", "curve"}  # the other speed is untouched


def test_a_learned_curve_takes_friction_off_the_list_at_that_speed():
    nominal = chart("two_mass_nominal")
    after = candidates(list(BUILTIN_EFFECTS.values()), nominal, SCALES, {_accept(nominal, "w1", physical=False)})
    assert _friction_options(after, "w1") == set()
    assert _friction_options(after, "w2") == {"coulomb", "curve"}


def test_other_effects_are_taken_off_whole_and_cogging_per_harmonic():
    nominal = chart("two_mass_nominal")
    effects = list(BUILTIN_EFFECTS.values())
    cands = candidates(effects, nominal, SCALES, set())
    dead_time = next(c for c in cands if c.name == "dead_time")
    cog = [c for c in cands if c.name == "cogging" and c.at == "w1"]
    assert len(cog) > 1
    after = candidates(effects, nominal, SCALES, {done_key(dead_time), done_key(cog[0])})
    assert not [c for c in after if c.name == "dead_time"]
    left = {c.option for c in after if c.name == "cogging" and c.at == "w1"}
    assert cog[0].option not in left and {c.option for c in cog[1:]} <= left


@pytest.mark.slow
def test_the_tour_bench_gets_friction_on_both_speeds_and_nothing_it_lacks():
    plant = load_diagram(Path(__file__).resolve().parents[1] / "diagrams" / "two_mass_plant.yaml")
    data = record(plant, 30.0, 1, 0.01)
    report = diagnose(chart("two_mass_nominal"), data, (), DiagnoseSettings(rounds=3, split=0.7)).report
    accepted = [(a["effect"], a["at"]) for a in report["accepted"]]
    assert accepted and all(effect == "friction" for effect, _ in accepted), accepted
    assert {at for _, at in accepted} == {"w1", "w2"}, accepted
