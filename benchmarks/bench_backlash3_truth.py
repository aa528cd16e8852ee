"""Is backlash3's end point the final chart's minimum, or a search that stopped short? (bench_one_missing, seed 2)

The final chart of `bench_one_missing.py --cases backlash3` (diagrams/three_mass.yaml with diagnose's dead zone
at dphi2, the place and effect diagnose accepts) is fitted by `identify` with diagnose's full-fit settings (LM,
trainlm damping, the bound transform, 1000 iterations, single shooting, no bias refit) on the bench's training
record of seed s (30 s, 0.01 rad/s noise, `sdnn excite` of tests/data/diagnose/three_mass_backlash_plant.yaml)
from the **true** parameters (the gap at the plant's 4 mrad). Printed: the training cost E at the truth and at
the minimum the fit reaches, the viscous b's errors with their noise-only and bias-widened 95 % intervals
(identify.offline.run.with_floor_bias, what diagnose's `final` reports), the corrected values (identified - beta), the
b1-b2 correlation. When the end point diagnose reports has the same E, that is the record's and the network's
minimum, not an unconverged refit. `--noise 0` and `--substeps N` separate the noise's part from the network
step's (benchmarks/notes/diagnose.md, "Three-mass seed 2").

Run from the repository root: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_backlash3_truth.py [--seeds 2]
[--noise 0.01] [--substeps auto]`` (10-30 s a seed).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_one_missing import CASES, record  # noqa: E402

from flowchart2sdnn.diagnose.effects import DeadZone  # noqa: E402
from flowchart2sdnn.diagnose.fitting import DiagnoseSettings  # noqa: E402
from flowchart2sdnn.diagnose.graph import spring_angles  # noqa: E402
from flowchart2sdnn.diagram.dump import with_values  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.identify.offline.problem import build_problem  # noqa: E402
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify, with_floor_bias  # noqa: E402


def final_chart(substeps):
    """diagrams/three_mass.yaml with diagnose's dead zone at dphi2 (its parameter `dphi2_gap`)."""
    given = load_diagram(CASES["backlash3"].chart)
    place = next(p for p in spring_angles(given) if p.at == "dphi2")
    chart = DeadZone().patch(given, place, 0.004)
    return chart if substeps == "auto" else dataclasses.replace(chart, substeps=int(substeps))


def run(seed: int, noise: float, substeps) -> None:
    plant = load_diagram(CASES["backlash3"].plant)
    values = plant.parameter_values()
    chart = final_chart(substeps)
    truth = {p.name: values[p.name] for p in chart.parameters if p.name in values}
    truth["dphi2_gap"] = values["dz2"]
    start = with_values(chart, truth, {})
    train = record(plant, CASES["backlash3"].train_s, seed, noise)
    problem = build_problem(start, train, "zoh", 0)
    at_truth = 0.5 * float(np.sum(problem.residual(problem.compiled.theta0()) ** 2))
    s = IdentifySettings(max_iter=1000, alignment="zoh", lm_tau=DiagnoseSettings().lm_tau, floor_bias=False,
                         shooting="off", lm_damping="trainlm", lm_bounds="transform")
    fit = with_floor_bias(identify(start, train, None, s), [train])
    cost = fit.fit.train.cost
    bias = fit.extra["discretization"]["bias"]
    u = fit.uncertainty
    i1, i2 = u.names.index("b1"), u.names.index("b2")
    print(f"seed {seed}, noise {noise}, N = {fit.extra['discretization']['substeps']}: E at the truth {at_truth:.6g}, "
          f"at the minimum {cost:.6g} (RMS {math.sqrt(2 * cost / problem.n_residuals):.5g}), {fit.status} after "
          f"{fit.optimizer.iterations} iterations; corr(b1, b2) {u.correlation[i1][i2]:+.3f}")
    for name in ("b1", "b2", "b3", "d1", "d2", "dphi2_gap"):
        e, t = fit.parameters[name], truth[name]
        corrected = (bias.get("corrected") or {}).get(name, {}).get("value", math.nan)
        print(f"  {name:9s} {e.value:.5g} ({100 * (e.value / t - 1):+.1f} %), 95 % noise-only [{e.ci95_noise[0]:.5g}, "
              f"{e.ci95_noise[1]:.5g}], widened by |beta| [{e.ci95[0]:.5g}, {e.ci95[1]:.5g}], truth {t:.5g}, "
              f"corrected {corrected:.5g} ({100 * (corrected / t - 1):+.1f} %)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="2")
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--substeps", default="auto", help="auto (the chart's) or a whole number of steps per sample")
    args = ap.parse_args()
    if args.substeps != "auto" and not args.substeps.isdigit():
        ap.error(f"--substeps expects auto or a whole number, got {args.substeps!r}")
    for seed in (int(s) for s in args.seeds.split(",")):
        run(seed, args.noise, args.substeps)


if __name__ == "__main__":
    main()
