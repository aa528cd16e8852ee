"""`substeps: auto` reads the fastest mode a chart can reach, not only the one at rest (issue 14's backlash).

A dead zone ``x - g sat(x / g)`` in a shaft is slack at rest (sat' = 1, the spring passes no torque), so the
network linearized at rest has no shaft mode; in contact (sat' = 0) the spring acts. Oracles, computed by
hand or by scipy, never from our output: two masses J1, J2 on an undamped spring c in contact oscillate at
sqrt(c (1/J1 + 1/J2)); three masses on two such shafts in contact at the largest root of det(K - w^2 M) = 0
(scipy.linalg.eigh), faster than either shaft alone, so both dead zones must be read closed together.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.compiler.substeps import AUTO_BOUND
from flowchart2sdnn.diagnose.graph import Place
from flowchart2sdnn.diagnose.overflow import Level, Overflow
from flowchart2sdnn.diagram.validate import diagram_from_text

T = 0.001
TWO_MASS = """\
sdnn: 1
name: two_mass_deadzone
sample_time: 0.001
substeps: {substeps}
delays: torques
inputs:
  M1: {{}}
outputs:
  w2: {{}}
parameters:
  J1: {{init: 0.2}}
  J2: {{init: 0.4}}
  c:  {{init: {c}}}
  g:  {{init: 0.004}}
blocks:
  MB1:  {{type: sum, in: [M1, -MC]}}
  acc1: {{type: gain, in: MB1, k: 1/J1}}
  w1:   {{type: integrator, in: acc1}}
  dw:   {{type: sum, in: [w1, -w2]}}
  x:    {{type: integrator, in: dw}}
  s:    {{type: function, f: sat, in: x, k: 1/g}}
  gs:   {{type: gain, in: s, k: g}}
  xz:   {{type: sum, in: [x, -gs]}}
  MC:   {{type: gain, in: xz, k: c}}
  acc2: {{type: gain, in: MC, k: 1/J2}}
  w2:   {{type: integrator, in: acc2}}
"""

THREE_MASS = """\
sdnn: 1
name: three_mass_deadzones
sample_time: 0.001
delays: torques
inputs:
  M1: {}
outputs:
  w3: {}
parameters:
  J1: {init: 0.2}
  J2: {init: 0.1}
  J3: {init: 0.4}
  c1: {init: 300}
  c2: {init: 500}
  g:  {init: 0.004}
blocks:
  MB1:  {type: sum, in: [M1, -MC1]}
  a1:   {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: a1}
  d1:   {type: sum, in: [w1, -w2]}
  x1:   {type: integrator, in: d1}
  s1:   {type: function, f: sat, in: x1, k: 1/g}
  gs1:  {type: gain, in: s1, k: g}
  z1:   {type: sum, in: [x1, -gs1]}
  MC1:  {type: gain, in: z1, k: c1}
  MB2:  {type: sum, in: [MC1, -MC2]}
  a2:   {type: gain, in: MB2, k: 1/J2}
  w2:   {type: integrator, in: a2}
  d2:   {type: sum, in: [w2, -w3]}
  x2:   {type: integrator, in: d2}
  s2:   {type: function, f: sat, in: x2, k: 1/g}
  gs2:  {type: gain, in: s2, k: g}
  z2:   {type: sum, in: [x2, -gs2]}
  MC2:  {type: gain, in: z2, k: c2}
  a3:   {type: gain, in: MC2, k: 1/J3}
  w3:   {type: integrator, in: a3}
"""


def _auto(text: str):
    comp = compile_diagram(diagram_from_text(text, "chart.yaml"))
    return comp.substeps, comp.network.substeps


@pytest.mark.parametrize("c", [300.0, 477.2, 1500.0])
def test_two_mass_dead_zone_shaft_sets_n_by_its_contact_mode(c):
    omega = math.sqrt(c * (1 / 0.2 + 1 / 0.4))  # the shaft in contact, by hand
    expected = math.ceil(omega * T / AUTO_BOUND)
    assert expected > 1  # at rest the shaft is slack: reading rest alone gives N = 1
    choice, n = _auto(TWO_MASS.format(substeps="auto", c=c))
    assert n == expected
    # the network's discrete mode at h = T/N, read back as a rate, is the continuous one to first order in w*h
    assert choice.omega_max == pytest.approx(omega, rel=0.02)


def test_a_pinned_chart_keeps_its_substeps():
    assert _auto(TWO_MASS.format(substeps=1, c=477.2))[1] == 1


def test_three_masses_read_with_both_dead_zones_closed():
    J = np.diag([0.2, 0.1, 0.4])
    K = np.array([[300.0, -300.0, 0.0], [-300.0, 800.0, -500.0], [0.0, -500.0, 500.0]])
    omega = math.sqrt(scipy.linalg.eigh(K, J, eigvals_only=True).max())
    alone = max(math.sqrt(300 * (1 / 0.2 + 1 / 0.1)), math.sqrt(500 * (1 / 0.1 + 1 / 0.4)))
    expected = math.ceil(omega * T / AUTO_BOUND)
    assert expected > math.ceil(alone * T / AUTO_BOUND)  # one shaft at a time would read too slow
    choice, n = _auto(THREE_MASS)
    assert n == expected
    assert choice.omega_max == pytest.approx(omega, rel=0.02)


def test_an_overflow_stop_is_not_read_as_a_mode_to_resolve():
    """diagnose's overflow stop is a clip resting beyond its limits with a stiffness 1/T that acts within one
    step by design: N stays the shaft's, not the cap."""
    diagram = diagram_from_text(TWO_MASS.format(substeps="auto", c=477.2), "chart.yaml")
    omega = math.sqrt(477.2 * (1 / 0.2 + 1 / 0.4))
    for at in ("w1", "x", "w2"):
        patched = Overflow().patch(diagram, Place(at, "state"), Level(1, 2.0, None, 5.0))
        assert compile_diagram(patched).network.substeps == math.ceil(omega * T / AUTO_BOUND)
