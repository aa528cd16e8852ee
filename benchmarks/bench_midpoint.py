"""`delays: midpoint` against the default `delays: torques`, both at `substeps: auto`: fit time and floor.

The bench (issue 13): `sdnn excite` of diagrams/two_mass_coulomb_plant.yaml and diagrams/three_mass_plant.yaml
(continuous RK4, APRBS + relay, record seed 1, 0.01 rad/s noise, 10 s), each fitted once by `identify` with its
defaults from the identification chart's 20 %-off `init` (two_mass_coulomb.yaml, three_mass.yaml), once with the
chart's own rule (torques, the baseline) and once with `delays: midpoint`. Printed per chart and rule: the N
that auto picks, the CPU seconds of the fit (process time, numba's kernels compiled by a warm-up fit first),
the discretization floor that identify measures on the fitted chart (network against the continuous oracle),
the largest error of J, c, d in %, and the ratios midpoint / torques of time and floor measured in the same run.

Run: ``python benchmarks/bench_midpoint.py`` (about 1 minute on the 2-core machine).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.api import dataset_from_frame, identify  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

BENCHES = (("two-mass", "two_mass_coulomb", "two_mass_coulomb_plant"), ("three-mass", "three_mass", "three_mass_plant"))
STIFF = ("J", "c", "d")  # inertias, shafts and shaft dampings: what the floor biases first


def fit(chart, data, delays: str):
    start = time.process_time()
    result = identify(dataclasses.replace(chart, delays=delays), data)
    cpu = time.process_time() - start
    doc = result.to_document()
    floor = (doc["discretization"].get("floor") or {}).get("rms") or {}
    return doc["discretization"]["substeps"], cpu, max(floor.values(), default=float("nan")), result


def main() -> None:
    print("| chart | rule | N (auto) | fit CPU [s] | worst floor [rad/s] | worst J, c, d error | time ratio | floor ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for label, chart_name, plant_name in BENCHES:
        plant = load_diagram(ROOT / "diagrams" / f"{plant_name}.yaml")
        chart = load_diagram(ROOT / "diagrams" / f"{chart_name}.yaml")
        cols = excite(plant, ExcitationSettings(seconds=10, seed=1, noise_std=0.01))
        data = dataset_from_frame(cols, time="time", inputs=list(plant.input_names),
                                  outputs=list(plant.output_names), name=f"excite({plant_name})")
        truth = plant.parameter_values()
        fit(chart, data, "midpoint")  # warm-up: numba compiles the kernels once
        base = None
        for rule in ("torques", "midpoint"):
            n, cpu, floor, result = fit(chart, data, rule)
            worst = max(abs(e.value / truth[k] - 1) for k, e in result.parameters.items()
                        if k in truth and not e.fixed and k.rstrip("0123456789") in STIFF)
            base = base or (cpu, floor)
            print(f"| {label} | {rule} | {n} | {cpu:.2f} | {floor:.2g} | {100 * worst:.3f} % | "
                  f"{cpu / base[0]:.2f} | {floor / base[1]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
