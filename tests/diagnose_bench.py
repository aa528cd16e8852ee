"""Shared helpers of the diagnose tests: charts, virtual test-bench records and a plain simulation."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.diagram.model import Diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

DATA = Path(__file__).resolve().parent / "data" / "diagnose"
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


def chart(name: str) -> Diagram:
    return load_diagram(DATA / f"{name}.yaml")


def record(plant: Diagram, seconds: float, seed: int, noise: float, name: str | None = None,
           **settings) -> Dataset:
    """A record of the virtual test bench (continuous simulation of `plant`, measurement noise) as a Dataset."""
    cols = excite(plant, ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise, **settings))
    keep = list(plant.input_names) + list(plant.output_names)
    n = len(cols["time"])
    return Dataset(name or f"{plant.name}-seed{seed}", {k: np.asarray(cols[k], dtype=float) for k in keep},
                   np.asarray(cols["time"]), n, plant.sample_time, 0.0, f"seed{seed}", {k: k for k in keep})


def rough_chart(chart: Diagram, seed: int, truth: dict | None = None, factor: float = 2.0) -> tuple[Diagram, dict]:
    """`chart` with each free parameter's init at `truth` (else its own init) times a factor drawn log-uniformly
    within x/÷`factor` (numpy default_rng(seed)), a user's rough guess; also the factors drawn, by name."""
    rng = np.random.default_rng(seed)
    params, factors = [], {}
    for p in chart.parameters:
        if p.fixed:
            params.append(p)
            continue
        f = float(np.exp(rng.uniform(-math.log(factor), math.log(factor))))
        factors[p.name] = f
        params.append(dataclasses.replace(p, init=((truth or {}).get(p.name) or p.init) * f))
    return dataclasses.replace(chart, parameters=tuple(params)), factors


def simulate(diagram: Diagram, u: np.ndarray) -> np.ndarray:
    """The compiled chart's outputs at its initial values for inputs u (Q, n_inputs), zoh alignment."""
    compiled = CompiledNetwork(compile_diagram(diagram).network)
    return run_aligned(compiled, compiled.theta0(), np.asarray(u, dtype=float), "zoh")


def aprbs_input(n: int, seed: int, amplitude: float = 5.0) -> np.ndarray:
    """A seeded piecewise-constant input (Q, 1)."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-amplitude, amplitude, n // 50 + 1)
    return np.repeat(levels, 50)[:n, None]
