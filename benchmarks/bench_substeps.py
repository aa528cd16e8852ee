"""The discretization floor and what sub-steps cost.

1. The floor: the chart with the TRUE parameters, run as its compiled network, against the continuous RK4 plant
   of the same chart (`sdnn excite`, noise-free, 20 s, seed 1, T = 1 ms): RMS per output for N = 1, 2, 4, 8 and
   auto, with the delays of the search rule (`delays: search`, the paper's) and of the accuracy rule
   (`delays: torques`). Charts: diagrams/two_mass_coulomb_plant.yaml and diagrams/three_mass_plant.yaml.
2. The cost: one LM iteration (an RTRL Jacobian + a residual-only trial, as the trainer does) on the
   three-mass identification chart (13 free parameters), Q = 25 000 samples, for N = 1, 2, 4, 8: wall and CPU
   ms, and the ratio to N = 1 (the acceptance: at most linear in N).

Run from the repository root: `python benchmarks/bench_substeps.py` (about 1-2 minutes).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.api import dataset_from_frame  # noqa: E402
from flowchart2sdnn.compiler import compile_diagram  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt  # noqa: E402
from flowchart2sdnn.identify.offline.problem import build_problem  # noqa: E402
from flowchart2sdnn.network.alignment import run_aligned  # noqa: E402
from flowchart2sdnn.network.runtime import CompiledNetwork  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

PLANTS = ("two_mass_coulomb_plant", "three_mass_plant")
SETTINGS = (1, 2, 4, 8, "auto")


def floor_table(seconds: float = 20.0) -> None:
    print(f"## floor: network with the true parameters vs continuous RK4, noise-free, {seconds:g} s, RMS rad/s\n")
    print("| chart | delays | N | " + " | ".join(f"w{i}" for i in (1, 2, 3)) + " |")
    print("|---|---|---|---|---|---|")
    for plant in PLANTS:
        d = load_diagram(ROOT / "diagrams" / f"{plant}.yaml")
        data = excite(d, ExcitationSettings(seconds=seconds, seed=1, noise_std=0.0))
        u = np.column_stack([data[n] for n in d.input_names])
        y = np.column_stack([data[n] for n in d.output_names])
        for rule in ("search", "torques"):
            for n in SETTINGS:
                comp = compile_diagram(dataclasses.replace(d, delays=rule, substeps=n))
                c = CompiledNetwork(comp.network)
                rms = np.sqrt(np.mean((run_aligned(c, c.theta0(), u)[1:] - y[1:]) ** 2, axis=0))
                label = f"auto = {comp.network.substeps}" if n == "auto" else str(n)
                cells = [f"{r:.4f}" for r in rms] + ["—"] * (3 - len(rms))
                print(f"| {plant} | {rule} | {label} | " + " | ".join(cells) + " |")


def lm_cost_table(q: int = 25_000, iterations: int = 5) -> None:
    print(f"\n## cost: LM iterations on the three-mass chart (13 free), Q = {q}, {iterations} iterations\n")
    plant = load_diagram(ROOT / "diagrams" / "three_mass_plant.yaml")
    data = excite(plant, ExcitationSettings(seconds=q * plant.sample_time, seed=1, noise_std=0.01))
    import pandas as pd

    ds = dataset_from_frame(pd.DataFrame(data), time="time", inputs=["M1"], outputs=["w1", "w2", "w3"])
    chart = load_diagram(ROOT / "diagrams" / "three_mass.yaml")
    print("| N | wall ms / iteration | CPU ms / iteration | CPU ratio to N = 1 | ratio / N |")
    print("|---|---|---|---|---|")
    base = None
    for n in (1, 2, 4, 8):
        problem = build_problem(dataclasses.replace(chart, substeps=n), ds)
        x0 = problem.compiled.theta0()
        problem.fun(x0)  # compile the kernels outside the timing
        lo, hi = problem.bounds()
        opts = LMOptions(max_iter=iterations, min_rel_cost_change=0.0)
        t0, c0 = time.perf_counter(), time.process_time()
        res = levenberg_marquardt(problem.fun, x0, problem.names, lo, hi, opts, residual=problem.residual)
        wall = (time.perf_counter() - t0) / max(res.iterations, 1) * 1e3
        cpu = (time.process_time() - c0) / max(res.iterations, 1) * 1e3
        base = base or cpu
        print(f"| {n} | {wall:.0f} | {cpu:.0f} | {cpu / base:.2f} | {cpu / base / n:.2f} |")


if __name__ == "__main__":
    floor_table()
    lm_cost_table()
