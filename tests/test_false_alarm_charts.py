"""The physical charts of the false-alarm bench (benchmarks/bench_false_alarms.py --charts physical) lack nothing.

Oracles: the plant itself, simulated continuously (RK4) from the same inputs: at its `init` (the truth) each chart
must give the plant's outputs, so its structure is the plant's and only the free values are left to fit; and the
sub-step rule's own bound (auto's N stays below its cap on these charts, and would hit it with the old plants'
1 mrad/s sign, the reason the bench uses plants smoothed over 0.05 rad/s)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.compiler.pipeline import compile_diagram
from flowchart2sdnn.compiler.substeps import AUTO_CAP
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.simulate.continuous import simulate_continuous

DIAGRAMS = Path(__file__).resolve().parents[1] / "diagrams"
PAIRS = [("two_mass_stribeck_plant", "two_mass_physical"), ("three_mass_stribeck_wide_plant", "three_mass_physical")]


def _torque(q: int, seed: int = 4) -> np.ndarray:
    """Piecewise-constant torque, levels held 50-300 samples, through zero speed often (friction's kinks)."""
    rng = np.random.default_rng(seed)
    u, k = np.zeros(q), 0
    while k < q:
        n = int(rng.integers(50, 300))
        u[k:k + n] = rng.uniform(-6.0, 6.0)
        k += n
    return u[:, None]


@pytest.mark.parametrize("plant_name, chart_name", PAIRS)
def test_the_chart_at_its_init_is_the_plant(plant_name, chart_name):
    plant = load_diagram(DIAGRAMS / f"{plant_name}.yaml")
    chart = load_diagram(DIAGRAMS / f"{chart_name}.yaml")
    u = _torque(3000)
    y_plant = simulate_continuous(plant, u, substeps=20)
    y_chart = simulate_continuous(chart, u, substeps=20)
    assert np.ptp(y_plant, axis=0).min() > 1.0  # the drive moves (through the friction's kinks)
    np.testing.assert_allclose(y_chart, y_plant, rtol=0, atol=1e-12)
    fixed = {p.name for p in chart.parameters if p.fixed}
    assert fixed == {p.name for p in chart.parameters if p.name.startswith("ws")}  # only the widths are known
    assert all(p.min == 0 for p in chart.parameters)


@pytest.mark.parametrize("plant_name, chart_name", PAIRS)
def test_auto_substeps_stay_below_the_cap_and_the_1_mrad_sign_would_hit_it(plant_name, chart_name, tmp_path):
    choice = compile_diagram(load_diagram(DIAGRAMS / f"{chart_name}.yaml")).substeps
    assert choice.requested == "auto" and not choice.capped and choice.substeps < AUTO_CAP
    sharp = tmp_path / "sharp.yaml"
    sharp.write_text((DIAGRAMS / f"{chart_name}.yaml").read_text().replace("eps: 0.05", "eps: 0.001"))
    assert compile_diagram(load_diagram(sharp)).substeps.capped
