"""Plant families as charts in the project's YAML language: the true plant and the chart a user writes of it.

A family is a chain of masses on shafts driven by the motor torque ``M1`` on the first mass: one mass, two
masses, three masses, or one mass on a spring to ground. Every mass has physical friction (Coulomb with a
Stribeck bump plus viscous, as diagrams/two_mass_plant.yaml); the user's chart models it with a learned curve
(``nonlinear``, 3 neurons) with or without a viscous gain, the way diagrams/two_mass_learned.yaml does.

Signal names are diagnose's places (:mod:`flowchart2sdnn.diagnose.graph`): the speeds ``w1..wn`` (integrators
of torque sums through ``1/J``), the shaft angles ``dphi1..`` (integrators of ``w_j - w_j+1`` feeding the spring
gain), the input ``M1``, the outputs. The ground spring acts on the position ``phi1 = integral(w1)``, which is
not a shaft angle in diagnose's sense (no speed difference): no library effect attaches there.

Charts are plain dicts (``blocks`` in insertion order) so that effects can be patched in before the text is
written; :func:`chart_text` gives the YAML a user would read.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np
import yaml

__all__ = ["FAMILIES", "Plant", "draw_plant", "base_chart", "chart_text", "chart_number", "SUBSTEPS", "log_uniform", "add_term",
           "insert_on_input", "reroute_in", "copy_chart"]

FAMILIES = ("one-mass", "two-mass", "three-mass", "spring")
SUBSTEPS = 20  # the oracle's RK4 steps per sample
_MASSES = {"one-mass": 1, "two-mass": 2, "three-mass": 3, "spring": 1}


def chart_number(x: float) -> float:
    """A number as a chart writes it: 9 significant digits, a YAML number."""
    return float(f"{x:.9g}")


def log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


@dataclass(frozen=True)
class Plant:
    """A drawn member of a family: its parameter values and the scales the effects and excitations are sized by.

    ``torque`` is the drive's torque scale A (N*m), ``speed`` the speed scale (rad/s) the excitation keeps the
    motor in, ``t_acc`` the time A needs to bring the whole inertia to ``speed``.
    """

    family: str
    masses: int
    parameters: dict[str, float]
    torque: float
    speed: float
    t_acc: float
    sample_time: float = 0.001
    viscous_in_chart: bool = True  # the user's chart has a viscous gain beside each learned friction curve

    @property
    def speeds(self) -> tuple[str, ...]:
        return tuple(f"w{i}" for i in range(1, self.masses + 1))

    @property
    def shafts(self) -> tuple[str, ...]:
        return tuple(f"dphi{j}" for j in range(1, self.masses))

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.speeds + (("phi1",) if self.family == "spring" else ())

    @property
    def inertia(self) -> float:
        return sum(self.parameters[f"J{i}"] for i in range(1, self.masses + 1))

    def angle_scale(self, place: str) -> float:
        """The deflection the torque scale gives at a spring: A / stiffness."""
        k = self.parameters["k0"] if place == "phi1" else self.parameters["c" + place.removeprefix("dphi")]
        return self.torque / k


def draw_plant(rng: np.random.Generator, family: str) -> Plant:
    """Physical parameters log-uniform over the ranges of small drives (every number is in the result).

    Shaft stiffnesses and dampings are drawn as a resonance (5-50 Hz) and a damping ratio (0.01-0.2), the
    ground spring as a natural frequency (0.5-10 Hz): a stiffness drawn alone against random inertias would
    mostly give resonances the 1 kHz records cannot resolve, or none the record shows.
    """
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; one of {', '.join(FAMILIES)}")
    n = _MASSES[family]
    p: dict[str, float] = {f"J{i}": log_uniform(rng, 0.01, 0.5) for i in range(1, n + 1)}
    for j in range(1, n):
        ja, jb = p[f"J{j}"], p[f"J{j + 1}"]
        inv = 1 / ja + 1 / jb
        omega = 2 * math.pi * log_uniform(rng, 5.0, 50.0)
        p[f"c{j}"] = omega**2 / inv
        p[f"d{j}"] = 2 * log_uniform(rng, 0.01, 0.2) * math.sqrt(p[f"c{j}"] / inv)
    if family == "spring":
        p["k0"] = (2 * math.pi * log_uniform(rng, 0.5, 10.0)) ** 2 * p["J1"]
    speed = log_uniform(rng, 2.0, 30.0)
    t_acc = log_uniform(rng, 0.05, 0.5)
    inertia = sum(p[f"J{i}"] for i in range(1, n + 1))
    accel_torque = inertia * speed / t_acc
    for i in range(1, n + 1):
        fc = accel_torque * log_uniform(rng, 0.02, 0.2)
        p[f"Fc{i}"] = fc
        p[f"Fs{i}"] = fc * rng.uniform(1.1, 2.0)
        p[f"ws{i}"] = speed * log_uniform(rng, 0.02, 0.2)
        p[f"b{i}"] = accel_torque / speed * log_uniform(rng, 0.01, 0.1)
    torque = accel_torque + sum(p[f"Fs{i}"] for i in range(1, n + 1))
    if family == "spring":  # the spring's torque at the motion a speed of `speed` has at the natural frequency
        torque += math.sqrt(p["k0"] * p["J1"]) * speed
    viscous = bool(rng.integers(0, 2))
    return Plant(family, n, p, torque, speed, t_acc, viscous_in_chart=viscous)


# ------------------------------------------------------------------------------------------------ charts
_UNITS = {"J": "kg*m^2", "c": "N*m/rad", "d": "N*m*s/rad", "k": "N*m/rad", "b": "N*m*s/rad", "Fc": "N*m",
          "Fs": "N*m", "ws": "rad/s"}


def _unit(name: str) -> str | None:
    return _UNITS.get(name.rstrip("0123456789"))


def base_chart(plant: Plant, name: str, physical_friction: bool, friction_at: tuple[str, ...] | None = None,
               parameters: dict[str, float] | None = None) -> dict:
    """The family's chart: masses, shafts, ground spring, and friction at `friction_at` (default: every speed).

    ``physical_friction``: the plant's Coulomb + Stribeck + viscous terms; otherwise the user's learned curve
    (with a viscous gain when ``plant.viscous_in_chart``). `parameters` are the inits written (default: the
    plant's values); parameters no block uses are left out.
    """
    values = dict(plant.parameters if parameters is None else parameters)
    n = plant.masses
    friction_at = plant.speeds if friction_at is None else friction_at
    blocks: dict[str, dict] = {}
    sums: dict[int, list[str]] = {i: [] for i in range(1, n + 1)}
    sums[1].append("M1")
    for j in range(1, n):
        sums[j] += [f"-MC{j}", f"-MD{j}"]
        sums[j + 1] += [f"MC{j}", f"MD{j}"]
    if plant.family == "spring":
        sums[1].append("-MK")
    for i in range(1, n + 1):
        blocks[f"MB{i}"] = {"type": "sum", "in": sums[i], "unit": "N*m"}
        blocks[f"acc{i}"] = {"type": "gain", "in": f"MB{i}", "k": f"1/J{i}", "unit": "rad/s^2"}
        blocks[f"w{i}"] = {"type": "integrator", "in": f"acc{i}", "unit": "rad/s"}
        if f"w{i}" in friction_at:
            terms = _physical_friction(blocks, i, plant, values) if physical_friction else _learned_friction(blocks, i, plant)
        else:
            terms = [f"Fv{i}"] if plant.viscous_in_chart and not physical_friction else []
            if terms:
                blocks[f"Fv{i}"] = {"type": "gain", "in": f"w{i}", "k": f"b{i}", "unit": "N*m"}
        if terms:
            blocks[f"MR{i}"] = {"type": "sum", "in": terms, "unit": "N*m"}
            sums[i].append(f"-MR{i}")
    for j in range(1, n):
        blocks[f"dw{j}"] = {"type": "sum", "in": [f"w{j}", f"-w{j + 1}"], "unit": "rad/s"}
        blocks[f"dphi{j}"] = {"type": "integrator", "in": f"dw{j}", "unit": "rad"}
        blocks[f"MC{j}"] = {"type": "gain", "in": f"dphi{j}", "k": f"c{j}", "unit": "N*m"}
        blocks[f"MD{j}"] = {"type": "gain", "in": f"dw{j}", "k": f"d{j}", "unit": "N*m"}
    if plant.family == "spring":
        blocks["phi1"] = {"type": "integrator", "in": "w1", "unit": "rad"}
        blocks["MK"] = {"type": "gain", "in": "phi1", "k": "k0", "unit": "N*m"}
    chart = {
        "sdnn": 1,
        "name": name,
        "description": "",
        "sample_time": plant.sample_time,
        "inputs": {"M1": {"unit": "N*m", "description": "motor torque"}},
        "outputs": {y: {"unit": "rad" if y.startswith("phi") else "rad/s"} for y in plant.outputs},
        "parameters": {},
        "blocks": blocks,
    }
    _set_parameters(chart, values, physical=physical_friction)
    return chart


def _physical_friction(blocks: dict, i: int, plant: Plant, values: dict[str, float]) -> list[str]:
    w = f"w{i}"
    # the sign smoothed over 1 mrad/s, or wider where that slope would make the oracle's RK4 steps unstable
    # (|d friction / d w| / J times the step below 1)
    step = plant.sample_time / SUBSTEPS
    eps = max(1e-3, float(f"{2 * values[f'Fs{i}'] * step / values[f'J{i}']:.3g}"))
    blocks[f"sg{i}"] = {"type": "function", "f": "sign_smooth", "in": w, "eps": eps}
    blocks[f"st{i}"] = {"type": "function", "f": "tanh", "in": w, "k": f"1/ws{i}"}
    blocks[f"Fsg{i}"] = {"type": "gain", "in": f"sg{i}", "k": f"Fs{i}", "unit": "N*m"}
    blocks[f"Fst{i}"] = {"type": "gain", "in": f"st{i}", "k": f"Fs{i}-Fc{i}", "unit": "N*m"}
    blocks[f"Fv{i}"] = {"type": "gain", "in": w, "k": f"b{i}", "unit": "N*m"}
    return [f"Fsg{i}", f"-Fst{i}", f"Fv{i}"]


def _learned_friction(blocks: dict, i: int, plant: Plant) -> list[str]:
    blocks[f"NL{i}"] = {"type": "nonlinear", "in": f"w{i}", "neurons": 3}
    if not plant.viscous_in_chart:
        return [f"NL{i}"]
    blocks[f"Fv{i}"] = {"type": "gain", "in": f"w{i}", "k": f"b{i}", "unit": "N*m"}
    return [f"NL{i}", f"Fv{i}"]


def _set_parameters(chart: dict, values: dict[str, float], physical: bool) -> None:
    used = " ".join(str(b.get("k", "")) for b in chart["blocks"].values())
    tokens = set(used.replace("/", " ").replace("-", " ").replace("*", " ").replace("+", " ").split())
    for name, value in values.items():
        if name in tokens:
            spec = {"init": float(f"{value:.6g}")}
            if _unit(name):
                spec["unit"] = _unit(name)
            if not physical:
                spec["min"] = 0
            chart["parameters"][name] = spec


def add_term(chart: dict, sum_name: str, term: str) -> None:
    chart["blocks"][sum_name]["in"].append(term)


def reroute_in(chart: dict, block: str, old: str, new: str) -> None:
    """Block `block` reads `new` where it read `old` (either sign)."""
    spec = chart["blocks"][block]
    terms = spec["in"] if isinstance(spec["in"], list) else [spec["in"]]
    out = [("-" + new if t == "-" + old else new if t == old else t) for t in terms]
    spec["in"] = out if isinstance(spec["in"], list) else out[0]


def insert_on_input(chart: dict, signal: str, blocks: dict[str, dict], last: str) -> None:
    """Put `blocks` (ending in `last`) between `signal` and every block that read it."""
    new_names = set(blocks)
    for name, spec in list(chart["blocks"].items()):
        if name in new_names:
            continue
        terms = spec.get("in")
        if terms is None:
            continue
        terms = terms if isinstance(terms, list) else [terms]
        if signal in terms or "-" + signal in terms:
            reroute_in(chart, name, signal, last)
    chart["blocks"].update(blocks)


def chart_text(chart: dict) -> str:
    """The chart as YAML, blocks in flow style one a line (as the project's charts are written)."""
    head = {k: v for k, v in chart.items() if k not in ("inputs", "outputs", "parameters", "blocks")}
    text = yaml.safe_dump(head, sort_keys=False, width=110, allow_unicode=True)
    for section in ("inputs", "outputs", "parameters", "blocks"):
        items = chart.get(section) or {}
        text += f"{section}:" + ("\n" if items else " {}\n")
        for name, spec in items.items():
            text += f"  {name}: " + yaml.safe_dump(spec, default_flow_style=True, sort_keys=False,
                                                   width=10_000).strip() + "\n"
    return text


def copy_chart(chart: dict) -> dict:
    return copy.deepcopy(chart)
