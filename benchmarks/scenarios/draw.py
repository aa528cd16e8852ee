"""Draw a scenario from a seed: a plant, what its chart lacks, sensors, excitation, and the records.

Every random choice comes from ``numpy.random.SeedSequence(seed)``'s children, one stream per topic (choices,
plant, excitation, missing effects, sensor, records, the user's inits), so the same seed gives the same
scenario, and a category fixing a choice leaves the other topics' draws as they were. Choices the category
fixes are still drawn (then overridden), so that the rest of the choice stream does not shift.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from flowchart2sdnn.data.csvdata import write_csv

from .excite import EXCITATIONS, Excitation, draw_excitation, run_record
from .missing import (
    KINDS,
    SENSOR_STAGE,
    Missing,
    accepted_answers,
    draw_missing,
    friction_override,
    patch_plant,
    places,
)
from .plants import FAMILIES, Plant, base_chart, chart_text, draw_plant
from .sensors import SENSORS, Sensor, draw_sensor

__all__ = ["COUNTS", "CATEGORIES", "Scenario", "parse_category", "draw", "draw_spec", "write_scenario"]

COUNTS = {"complete": 0, "one-missing": 1, "two-missing": 2}
CATEGORIES = tuple(COUNTS) + tuple(f"{c}-{e}" for c in COUNTS for e in EXCITATIONS)


def parse_category(category: str | None) -> tuple[int | None, str | None]:
    """``complete|one-missing|two-missing`` optionally followed by ``-aprbs|-multisine|-closed-loop``."""
    if category is None:
        return None, None
    for head, n in COUNTS.items():
        if category == head:
            return n, None
        if category.startswith(head + "-") and category[len(head) + 1:] in EXCITATIONS:
            return n, category[len(head) + 1:]
    raise ValueError(f"unknown category {category!r}; one of {', '.join(CATEGORIES)}")


@dataclass(frozen=True)
class Scenario:
    """A drawn scenario: the truth (plant, missing effects) and what the user has (chart text, records)."""

    seed: int
    category: str
    family: str
    plant: Plant
    missing: tuple[Missing, ...]
    tolerated: tuple[tuple[str, str], ...]
    sensor: Sensor
    excitation: Excitation
    seconds: float
    validation_seconds: float
    plant_yaml: str
    chart_yaml: str
    train: dict | None = None
    validation: dict | None = None
    facts: dict | None = None

    @property
    def truth(self) -> dict:
        return {"seed": self.seed, "category": self.category, "family": self.family,
                "parameters": self.plant.parameters, "torque_scale": self.plant.torque,
                "speed_scale": self.plant.speed, "t_acc": self.plant.t_acc,
                "viscous_in_chart": self.plant.viscous_in_chart,
                "missing": [m.as_dict() for m in self.missing], "tolerated": [list(t) for t in self.tolerated],
                "sensor": self.sensor.as_dict(), "excitation": self.excitation.as_dict(),
                "seconds": self.seconds, "validation_seconds": self.validation_seconds, "facts": self.facts}


def _pick(rng: np.random.Generator, items):
    return items[int(rng.integers(0, len(items)))]


def _draw_missing(rng: np.random.Generator, plant: Plant, count: int, input_peak: float) -> tuple[Missing, ...]:
    """`count` effects of different kinds whose accepted answers do not overlap (else one answer found both)."""
    out: list[Missing] = []
    for _ in range(count):
        taken = {a for m in out for a in m.accept}
        used = {m.kind for m in out}
        spots = {k: [p for p in places(plant, k) if not taken & set(accepted_answers(k, p))]
                 for k in KINDS if k not in used}
        kind = _pick(rng, [k for k, free in spots.items() if free])
        out.append(draw_missing(rng, plant, kind, _pick(rng, spots[kind]), input_peak))
    return tuple(out)


def _user_inits(rng: np.random.Generator, values: dict[str, float]) -> dict[str, float]:
    """A user's rough guess: each value times a factor log-uniform within x/÷2."""
    return {k: v * math.exp(rng.uniform(-math.log(2), math.log(2))) for k, v in values.items()}


def draw_spec(seed: int, category: str | None = None, family: str | None = None,
              seconds: float | None = None, sensor: str | None = None) -> Scenario:
    """The scenario without its records (fast): everything but the simulation. See :func:`draw`."""
    count, excitation_kind = parse_category(category)
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(7)]
    choice, r_plant, r_exc, r_missing, r_sensor, _, r_init = streams
    drawn_count = int(choice.integers(0, 3))
    drawn_family = _pick(choice, FAMILIES)
    drawn_excitation = _pick(choice, EXCITATIONS)
    drawn_sensor = _pick(choice, SENSORS)
    drawn_seconds = float(choice.uniform(10.0, 60.0))
    count = drawn_count if count is None else count
    family = family or drawn_family
    excitation_kind = excitation_kind or drawn_excitation
    seconds = seconds or drawn_seconds
    validation_seconds = min(15.0, max(seconds / 3, min(5.0, seconds)))

    plant = draw_plant(r_plant, family)
    excitation = draw_excitation(r_exc, plant, excitation_kind)
    missing = _draw_missing(r_missing, plant, count, excitation.input_peak)
    sens = draw_sensor(r_sensor, sensor or drawn_sensor)
    sens = replace(sens, offsets={m.place: m.size["o"] for m in missing if m.kind == "sensor_offset"},
                   limits={m.place: m.size["fraction"] for m in missing if m.kind == "sensor_limit"})
    plant = replace(plant, parameters=friction_override(plant, missing))
    name = f"{family.replace('-', '_')}_s{seed}"

    true_chart = base_chart(plant, name + "_plant", physical_friction=True)
    for m in missing:
        if m.kind not in SENSOR_STAGE:
            patch_plant(true_chart, m)
    true_chart["description"] = (f"scenario seed {seed}: the true plant; missing from the user's chart: "
                                 + (", ".join(f"{m.kind}@{m.place}" for m in missing) or "nothing"))
    no_curve = tuple(m.place for m in missing if m.kind == "friction")
    modelled = tuple(w for w in plant.speeds if w not in no_curve)
    user = base_chart(plant, name, physical_friction=False, friction_at=modelled,
                      parameters=_user_inits(r_init, plant.parameters))
    user["description"] = "the user's chart: learned friction curves" + (
        " with viscous gains" if plant.viscous_in_chart else " without viscous gains") + ", inits within x/÷2"
    # a chart without a viscous gain leaves the viscous friction to the learned curve: an added damping there is
    # a fair completion, not a false alarm
    tolerated = () if plant.viscous_in_chart else tuple(("damping", w) for w in plant.speeds)
    label = next(k for k, v in COUNTS.items() if v == count) + "-" + excitation_kind
    return Scenario(seed, label, family, plant, missing, tolerated, sens, excitation, seconds, validation_seconds,
                    chart_text(true_chart), chart_text(user))


def draw(seed: int, category: str | None = None, family: str | None = None, seconds: float | None = None,
         sensor: str | None = None) -> Scenario:
    """Draw scenario `seed` and simulate its training and validation records with the continuous oracle.

    Parameters
    ----------
    seed : int
        Everything random derives from it.
    category : str, optional
        Fix the number of missing effects and optionally the excitation (:data:`CATEGORIES`).
    family, sensor : str, optional
        Fix the plant family (:data:`~.plants.FAMILIES`) or the sensor kind (white, ar, encoder).
    seconds : float, optional
        Training record length (default: drawn in 10-60 s); the validation record is a third of it, 5-15 s
        (never longer than the training record).
    """
    spec = draw_spec(seed, category, family, seconds, sensor)
    records = np.random.SeedSequence(seed).spawn(7)[5]
    # simulated from the plant's text, so that what truth.json's plant.yaml says is what made the records
    r_train, r_val = (np.random.default_rng(s) for s in records.spawn(2))
    plant_chart = yaml.safe_load(spec.plant_yaml)
    train, f_train = run_record(plant_chart, spec.plant, spec.excitation, spec.sensor, spec.seconds, r_train)
    val, f_val = run_record(plant_chart, spec.plant, spec.excitation, spec.sensor, spec.validation_seconds, r_val)
    f_train["exposure"] = _exposure(spec.missing, train, f_train["ranges"])
    return replace(spec, train=train, validation=val, facts={"train": f_train, "validation": f_val})


def _exposure(missing: tuple[Missing, ...], record: dict, ranges: dict) -> dict[str, float]:
    """For a clip (saturation, sensor limit): the share of training samples at the limit. A clip the record never
    reaches is in the truth but not in the data (a PI loop may never command that much)."""
    out = {}
    for m in missing:
        if m.kind == "saturation":
            out[f"{m.kind}@{m.place}"] = float(np.mean(np.abs(record[m.place]) > m.size["L"]))
        elif m.kind == "sensor_limit":
            limit = m.size["fraction"] * ranges[m.place][1]
            out[f"{m.kind}@{m.place}"] = float(np.mean(np.abs(record[m.place]) >= limit * (1 - 1e-12)))
    return out


def write_scenario(scenario: Scenario, directory: str | Path) -> dict[str, Path]:
    """plant.yaml, chart.yaml, train.csv, validation.csv and truth.json in `directory` (created)."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    paths = {k: d / f for k, f in (("plant", "plant.yaml"), ("chart", "chart.yaml"), ("train", "train.csv"),
                                    ("validation", "validation.csv"), ("truth", "truth.json"))}
    paths["plant"].write_text(scenario.plant_yaml)
    paths["chart"].write_text(scenario.chart_yaml)
    if scenario.train is not None:
        write_csv(paths["train"], scenario.train)
        write_csv(paths["validation"], scenario.validation)
    paths["truth"].write_text(json.dumps(scenario.truth, indent=1, default=float))
    return paths
