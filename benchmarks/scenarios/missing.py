"""The effects a scenario's plant has and its chart lacks: drawn at a place with a size, patched into the plant.

Each kind names where it attaches (diagnose's place vocabulary: a speed ``w<i>``, a shaft angle ``dphi<j>``, the
input ``M1``, an output) and which of diagnose's candidates, as (effect, place), count as finding it
(``accept``). Kinds from diagnose's library accept themselves; the physical ones the library lacks accept the
library effect that can state them:

=================  =============  ====================================  ====================================
kind               place          in the plant                          diagnose finds it as
=================  =============  ====================================  ====================================
friction           speed          Coulomb + Stribeck (the chart has no  friction
                                  curve there, viscous gain as drawn)
cogging            speed          A sin(p phi + phase), p in 2..12      cogging
unbalance          load speed     -m g l sin(phi + phase)               cogging (its p = 1 term is this torque)
backlash           shaft angle    c (x - g sat(x / g)), half gap g      backlash, dead_zone
nonlinear_spring   shaft angle    c x + c3 x^3                          backlash (an odd curve of the angle)
                   ground phi1    k x + k3 x^3                          spring (an odd curve of the position)
dead_time          input          n-sample delay                        dead_time
input_lag          input          first-order lag tau (current loop)    dead_time (the nearest library effect)
saturation         input          L sat(u / L)                          saturation
input_offset       input          u + o                                 input_offset
sensor_offset      output         measured = physical + o (sensors.py)  sensor_offset
sensor_limit       output         measured clipped at +-L (sensors.py)  sensor_limit
=================  =============  ====================================  ====================================

Sizes run from barely detectable to dominant: ``strength`` u ~ U(0, 1) maps log-uniformly onto the kind's
range (``lo * (hi / lo) ** u``), ranges relative to the plant's scales (torque A, speed, spring deflection A/c).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .plants import Plant, add_term, chart_number, insert_on_input, reroute_in

__all__ = ["Missing", "KINDS", "SENSOR_STAGE", "places", "accepted_answers", "draw_missing", "patch_plant", "friction_override"]

KINDS = ("friction", "cogging", "unbalance", "backlash", "nonlinear_spring", "dead_time", "input_lag",
         "saturation", "input_offset", "sensor_offset", "sensor_limit")
SENSOR_STAGE = ("sensor_offset", "sensor_limit")


@dataclass(frozen=True)
class Missing:
    """One effect of the plant the user's chart lacks. ``size`` holds its physical numbers by name."""

    kind: str
    place: str
    strength: float
    size: dict
    accept: tuple[tuple[str, str], ...]

    @property
    def expressible(self) -> bool:
        """Whether some library candidate states it (else no diagnose answer can be right about it)."""
        return bool(self.accept)

    def as_dict(self) -> dict:
        return {"kind": self.kind, "place": self.place, "strength": self.strength, "size": self.size,
                "accept": [list(a) for a in self.accept]}


def places(plant: Plant, kind: str) -> tuple[str, ...]:
    """Where `kind` can sit in `plant` (empty: not in this family)."""
    if kind in ("friction", "cogging"):
        return plant.speeds
    if kind == "unbalance":
        return (plant.speeds[-1],)
    if kind == "backlash":
        return plant.shafts
    if kind == "nonlinear_spring":
        return plant.shafts + (("phi1",) if plant.family == "spring" else ())
    if kind in ("dead_time", "input_lag", "saturation", "input_offset"):
        return ("M1",)
    if kind in SENSOR_STAGE:
        return plant.outputs
    raise ValueError(f"unknown kind {kind!r}")


def accepted_answers(kind: str, place: str) -> tuple[tuple[str, str], ...]:
    if kind == "unbalance":
        return (("cogging", place),)
    if kind == "backlash":
        return (("backlash", place), ("dead_zone", place))
    if kind == "nonlinear_spring":
        return (("backlash", place),) if place.startswith("dphi") else (("spring", place),)
    if kind == "input_lag":
        return (("dead_time", place),)
    return ((kind, place),)


def _span(u: float, lo: float, hi: float) -> float:
    return lo * (hi / lo) ** u


def _sign(rng: np.random.Generator) -> float:
    return 1.0 if rng.integers(0, 2) else -1.0


def draw_missing(rng: np.random.Generator, plant: Plant, kind: str, place: str, input_peak: float) -> Missing:
    """Draw the size of `kind` at `place` (strength first). `input_peak`: the largest |input| the excitation
    asks for, which a saturation clips a fraction of."""
    u = float(rng.uniform())
    a, w, T = plant.torque, plant.speed, plant.sample_time
    if kind == "friction":
        fc = _span(u, 0.005, 0.4) * a
        size = {"Fc": fc, "Fs": fc * float(rng.uniform(1.1, 2.0))}
    elif kind == "cogging":
        size = {"A": _span(u, 0.005, 0.3) * a, "p": int(rng.integers(2, 13)),
                "phase": float(rng.uniform(0, 2 * math.pi))}
    elif kind == "unbalance":
        size = {"mgl": _span(u, 0.005, 0.6) * a, "phase": float(rng.uniform(0, 2 * math.pi))}
    elif kind == "backlash":
        size = {"gap": _span(u, 0.01, 0.5) * plant.angle_scale(place)}
    elif kind == "nonlinear_spring":
        x = plant.angle_scale(place)
        stiffness = plant.torque / x
        # the cubic's share of the spring torque at the deflection A/k
        size = {"k3": _sign(rng) * _span(u, 0.02, 2.0) * stiffness / x**2}
    elif kind == "dead_time":
        size = {"n": max(1, int(round(_span(u, 1.0, 20.0))))}
    elif kind == "input_lag":
        size = {"tau": _span(u, 0.5, 30.0) * T}
    elif kind == "saturation":
        fraction = 1.0 - _span(u, 0.05, 0.6)
        size = {"fraction": fraction, "L": fraction * input_peak}
    elif kind == "input_offset":
        size = {"o": _sign(rng) * _span(u, 0.005, 0.3) * a}
    elif kind == "sensor_offset":
        scale = w if place.startswith("w") else plant.angle_scale(place)
        size = {"o": _sign(rng) * _span(u, 0.005, 0.3) * scale}
    elif kind == "sensor_limit":
        size = {"fraction": 1.0 - _span(u, 0.05, 0.5)}  # of the clean output's largest |value|
    else:
        raise ValueError(f"unknown kind {kind!r}")
    return Missing(kind, place, u, size, accepted_answers(kind, place))


def friction_override(plant: Plant, missing: tuple[Missing, ...]) -> dict[str, float]:
    """The plant's parameters with the missing frictions' sizes in place of the base draw."""
    values = dict(plant.parameters)
    for m in missing:
        if m.kind == "friction":
            i = m.place.removeprefix("w")
            values[f"Fc{i}"], values[f"Fs{i}"] = m.size["Fc"], m.size["Fs"]
    return values


def patch_plant(chart: dict, m: Missing) -> None:
    """Add `m` to the plant chart (in place)."""
    k, p, s = m.kind, m.place, m.size
    blocks = chart["blocks"]
    tag = f"{k}_{p}"
    if k in ("friction", *SENSOR_STAGE):
        return  # friction: in the parameters (friction_override); sensors: applied to the outputs
    if k in ("cogging", "unbalance"):
        i = p.removeprefix("w")
        amplitude = s["A"] if k == "cogging" else s["mgl"]
        harmonic = s.get("p", 1)
        blocks[f"{tag}_phi"] = {"type": "integrator", "in": p, "init": round(s["phase"] / harmonic, 9),
                                "unit": "rad"}
        blocks[f"{tag}_sin"] = {"type": "function", "f": "sin", "in": f"{tag}_phi", "k": harmonic}
        blocks[tag] = {"type": "gain", "in": f"{tag}_sin", "k": chart_number(amplitude), "unit": "N*m"}
        add_term(chart, f"MB{i}", "-" + tag)
    elif k == "backlash":
        j = p.removeprefix("dphi")
        blocks[f"{tag}_clip"] = {"type": "function", "f": "sat", "in": p, "k": chart_number(1 / s["gap"])}
        blocks[f"{tag}_g"] = {"type": "gain", "in": f"{tag}_clip", "k": chart_number(s["gap"]), "unit": "rad"}
        blocks[tag] = {"type": "sum", "in": [p, f"-{tag}_g"], "unit": "rad"}
        reroute_in(chart, f"MC{j}", p, tag)
    elif k == "nonlinear_spring":
        blocks[tag] = {"type": "product", "in": [p, p, p], "k": chart_number(s["k3"]), "unit": "N*m"}
        if p == "phi1":
            add_term(chart, "MB1", "-" + tag)
        else:
            j = int(p.removeprefix("dphi"))
            add_term(chart, f"MB{j}", "-" + tag)
            add_term(chart, f"MB{j + 1}", tag)
    elif k == "dead_time":
        insert_on_input(chart, p, {tag: {"type": "delay", "in": p, "n": s["n"]}}, tag)
    elif k == "input_lag":
        insert_on_input(chart, p, {
            f"{tag}_e": {"type": "sum", "in": [p, f"-{tag}"]},
            f"{tag}_r": {"type": "gain", "in": f"{tag}_e", "k": chart_number(1 / s["tau"])},
            tag: {"type": "integrator", "in": f"{tag}_r"},
        }, tag)
    elif k == "saturation":
        limit = s["L"]
        insert_on_input(chart, p, {
            f"{tag}_clip": {"type": "function", "f": "sat", "in": p, "k": chart_number(1 / limit)},
            tag: {"type": "gain", "in": f"{tag}_clip", "k": chart_number(limit)},
        }, tag)
    elif k == "input_offset":
        insert_on_input(chart, p, {
            f"{tag}_o": {"type": "constant", "k": chart_number(s["o"])},
            tag: {"type": "sum", "in": [p, f"{tag}_o"]},
        }, tag)
    else:
        raise ValueError(f"unknown kind {k!r}")
