"""The compiled network (zoh alignment) against the continuous chart (issue 2, acceptance 2).

The oracle is flowchart2sdnn.simulate.continuous.simulate_continuous: fine-step RK4 of the chart itself, inputs
zero-order held (row k acts on [t_k, t_k+1)), row k the chart at t_k. It shares no code with the compiler.
The network runs with the default alignment for logged data ("zoh": row 0 is the initial state, the network
input at row k is u(k-1)), so both describe the same held input.

Settings: T = 1 ms (the dc motor's chart uses 0.1 ms, see below), the paper's values J1 0.1912, J2 0.3838,
c 477, d 0.24, fixed friction curves given with the chart's `weights:` key, 4 s of a zero-mean APRBS with the
paper's amplitude (+-7 N*m) and holds of 50-500 ms. Euler is first order: the error is about half a sample
of phase on every oscillation (relative RMS ~ omega*T/2), so it is checked to halve with T as well.
With the paper's faster holds (10-250 ms) the two-mass error is 1.2-2.0 % at T = 1 ms: the 10 Hz shaft
resonance is excited harder, and that is where the 2 % budget goes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
PAPER = {"J1": 0.1912, "J2": 0.3838, "c": 477.0, "d": 0.24}
FRICTION = {"neurons": 2, "weights": {"a": [8.0, 0.5], "v": [0.6, 0.3]}}  # steep Coulomb-like + viscous
# The plant charts smooth sign() over eps = 1 mrad/s: the friction slope Fs/eps = 1200 N*m*s/rad exceeds
# 2*J/T (382 for J1 at 1 ms), and the friction feedback of the discrete model carries one sample of delay,
# so near zero speed it chatters (an unstable discrete loop; the continuous chart sticks). With eps = 10 mrad/s
# the slope is 120 and both models agree; identification uses the learned curves, not these plants.
PLANT_EPS = 0.01


def _chart(name: str, sample_time: float | None = None, paper: bool = False) -> str:
    """The chart at the paper's values; `paper`: on the paper's network (one step per sample, the search's delays)."""
    doc = yaml.safe_load((DIAGRAMS / f"{name}.yaml").read_text())
    if paper:
        doc.update(substeps=1, delays="search")
    for pname, value in PAPER.items():
        if pname in doc.get("parameters", {}):
            doc["parameters"][pname]["init"] = value
    for spec in doc["blocks"].values():
        if spec["type"] == "nonlinear":
            spec.update(FRICTION)
        if spec["type"] == "function" and spec.get("f") == "sign_smooth":
            spec["eps"] = PLANT_EPS
    if sample_time is not None:
        doc["sample_time"] = sample_time
    return yaml.safe_dump(doc, sort_keys=False)


def _relative_rms(name: str, sample_time: float | None = None, seconds: float = 4.0, seed: int = 0,
                  amplitude: float = 7.0, hold=(0.05, 0.5), base_step: float = 1e-3, paper: bool = False) -> float:
    diagram = diagram_from_text(_chart(name, sample_time, paper), f"{name}.yaml")
    T = diagram.sample_time
    # one continuous-time excitation, sampled at base_step and held: comparable across sample times
    levels = aprbs(int(round(seconds / base_step)), base_step, np.random.default_rng(seed),
                   (-amplitude, amplitude), hold)
    levels -= levels.mean()  # the engine and the two-mass drive integrate: keep the speeds bounded
    q = int(round(seconds / T))
    index = np.minimum((np.arange(q) * T / base_step + 1e-9).astype(int), len(levels) - 1)
    u = np.repeat(levels[index][:, None], len(diagram.inputs), axis=1)
    compiled = CompiledNetwork(compile_diagram(diagram).network)
    y_d = run_aligned(compiled, compiled.theta0(), u, "zoh")
    y_c = simulate_continuous(diagram, u, substeps=max(4, int(round(20 * T / 1e-3))))
    assert np.all(np.isfinite(y_d)) and np.linalg.norm(y_c) > 0
    return float(np.linalg.norm(y_d - y_c) / np.linalg.norm(y_c))


@pytest.mark.parametrize("name", ["engine", "two_mass", "mass_spring_damper", "engine_plant", "two_mass_plant"])
@pytest.mark.parametrize("seed", [0, 1])
def test_network_and_continuous_chart_agree_within_two_percent(name, seed):
    assert _relative_rms(name, seed=seed) <= 0.02


def test_dc_motor_agrees_within_two_percent_at_its_own_sample_time():
    """The chart samples at 0.1 ms: its armature time constant L/R = 4.2 ms is only 4 samples of 1 ms, and at
    1 ms the Euler error of the electrical loop is 3.4 % (a property of the scheme, not of the compiler)."""
    err = _relative_rms("dc_motor", seconds=0.5, amplitude=12.0, hold=(0.01, 0.1), base_step=1e-4)
    assert err <= 0.02


def test_the_error_is_first_order_in_the_sample_time():
    """Halving T halves the error: the paper's network is a consistent first-order discretization of the chart."""
    coarse = _relative_rms("two_mass", sample_time=1e-3, seconds=2.0, seed=3, hold=(0.01, 0.25), paper=True)
    fine = _relative_rms("two_mass", sample_time=5e-4, seconds=2.0, seed=3, hold=(0.01, 0.25), paper=True)
    assert 0.002 < fine < coarse
    assert 1.7 < coarse / fine < 2.3
