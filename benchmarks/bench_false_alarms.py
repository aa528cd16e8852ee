"""False alarms of `diagnose` on complete charts (issue 13 "no false alarms from the floor", issue 16's first row).

The plants are continuous (`sdnn excite`: RK4 of the plant chart, 20 steps per sample, T = 1 ms, the paper's
APRBS + relay excitation), with Stribeck friction on every machine:

* ``two``: diagrams/two_mass_plant.yaml, charted by diagrams/two_mass_learned.yaml;
* ``three``: diagrams/three_mass_stribeck_plant.yaml, charted by diagrams/three_mass_learned.yaml.

Both charts are complete in structure: the same shafts, every speed measured, each machine's friction a learned
curve (3 tanh neurons) plus a viscous term, `substeps: auto`, `delays: torques`; but 3 tanh neurons cannot
carry a sign smoothed over 1 mrad/s plus a Stribeck bump (benchmarks/notes/diagnose.md). ``--charts physical`` puts charts
that lack nothing, not even capacity, on plants whose sign is smoothed over 0.05 rad/s:

* ``two``: diagrams/two_mass_stribeck_plant.yaml, charted by diagrams/two_mass_physical.yaml;
* ``three``: diagrams/three_mass_stribeck_wide_plant.yaml, charted by diagrams/three_mass_physical.yaml;

each machine's friction Fs*sign_smooth(w) - (Fs-Fc)*tanh(w/ws) + b*w as in the plant, the widths fixed,
`substeps: auto`, `delays: torques`, every free parameter >= 0. Per seed: one training record (``--seconds``,
excitation seed = seed) and one validation record (half as long, excitation seed = 1000 + seed), both with white
noise of ``--noise`` rad/s on every speed; the chart's free parameters start at the truth times a factor drawn
log-uniformly within x/÷2 (numpy default_rng(seed)). `diagnose` (the library call, default settings, serial)
then must accept nothing. Printed per run: what the first fit did, what was accepted, the validation RMS
before/after, the discretization floor on the validation record (`before.validation_floor`), the best refused
candidate of round 1 and why it was refused, the wall time.

Run from the repository root:
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_false_alarms.py [--charts learned|physical] [--plants two,three] [--noise 0.003,0.01,0.03]
[--n-seeds 3] [--seconds 30] [--max-iter N] [--json OUT.json]`` (one run: 1-30 min on a shared core).
Measured with ``--charts physical`` (3 seeds x 3 noises x 2 plants) before the geodesic LM trainer: 0 effects
accepted in 18 runs, 20-600 s a run. With it (f2404f4): 0 accepted in 18 runs, every first fit converged in
9-50 iterations (two-mass 0.003 seed 2 run at 3dc695d). Learned charts, two-mass, with it: the first fit converges in
490 (0.003 seed 1), 470 (0.01 seed 2) and 112 (0.03 seed 1) iterations, traced, nothing accepted; 0.01 seed 3
and 0.03 seeds 2-3 stop at 1000, not traced: 0 accepted in 6 runs, 1.5-25 min a run on a loaded core. At
diagnose's old default of 100 iterations none would have converged, hence the default 1000. Three-mass learned
chart after the curves' start on sub-steps was fixed (3dc695d): 0 accepted in 9 runs, 7 traced (first fits
converged in 53-699 iterations), 2 first fits at the 1000 limit. The last three two-mass cells (5ac290f): 0.003
seeds 2-3 traced (first fits 148, 374 iterations), nothing accepted; 0.01 seed 1 not traced: 0 of 18 learned runs.
Tables: benchmarks/notes/diagnose.md. The printed first fit gives its LM iterations.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from diagnose_bench import rough_chart  # noqa: E402

from flowchart2sdnn.api import dataset_from_frame  # noqa: E402
from flowchart2sdnn.diagnose import DiagnoseSettings, diagnose  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

BENCHES = {"learned": {"two": ("two_mass_plant", "two_mass_learned"),
                       "three": ("three_mass_stribeck_plant", "three_mass_learned")},
           "physical": {"two": ("two_mass_stribeck_plant", "two_mass_physical"),
                        "three": ("three_mass_stribeck_wide_plant", "three_mass_physical")}}


def record(plant, seconds: float, seed: int, noise: float):
    data = excite(plant, ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise))
    return dataset_from_frame(data, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names),
                              name=f"{plant.name}-seed{seed}-noise{noise:g}")


def _refused(report: dict) -> str:
    """The round that accepted nothing: its best refitted candidate and why it was refused; when no candidate was
    significant, the best-scored one and its p-value (against ``alpha``)."""
    for r in report["rounds"]:
        if not r["accepted"]:
            return f"{r['effect']}@{r['at']}: {r['reason']}"
    last = max((c["round"] for c in report["candidates"]), default=None)
    scored = [c for c in report["candidates"] if c["round"] == last and c.get("p_value") is not None]
    if scored:
        c = min(scored, key=lambda c: c["p_value"])
        return f"{c['effect']}@{c['at']}: not significant (p = {c['p_value']:.2g})"
    return ""


def run_one(key: str, noise: float, seed: int, seconds: float, settings: DiagnoseSettings,
            charts: str = "learned") -> dict:
    plant_name, chart_name = BENCHES[charts][key]
    plant = load_diagram(ROOT / "diagrams" / f"{plant_name}.yaml")
    chart, factors = rough_chart(load_diagram(ROOT / "diagrams" / f"{chart_name}.yaml"), seed)
    train = record(plant, seconds, seed, noise)
    val = record(plant, seconds / 2, 1000 + seed, noise)
    t0 = time.perf_counter()
    result = diagnose(chart, train, [val], settings)
    rep = result.report
    wall = time.perf_counter() - t0
    first = rep["first_fit"]
    trace = result.nominal.identification.optimizer
    return {"commit": _commit(), "charts": charts, "plant": key, "noise": noise, "seed": seed, "seconds": seconds, "init_factors": factors,
            "first_fit_converged": first["converged"], "first_fit_status": first["status"],
            "first_fit_iterations": trace.iterations if trace is not None else None,
            "train_rms_before": rep["before"]["rms"],
            "stop": rep["stop"], "accepted": [f"{a['effect']}@{a['at']} ({a['label']})" for a in rep["accepted"]],
            "val_before": rep["before"]["validation_rms"], "val_after": rep["after"]["validation_rms"],
            "floor": rep["before"].get("validation_floor"), "refused": _refused(rep), "wall": wall,
            "rounds": [{k: r.get(k) for k in ("round", "effect", "at", "label", "accepted", "reason",
                                               "validation_rms_before", "validation_rms_after", "validation_gain_spread",
                                               "control")}
                       for r in rep["rounds"]],
            "substeps": (rep["final"].get("discretization") or {}).get("substeps")}


def _commit() -> str:
    """The code's git commit (``+`` when the work tree differs from it): which rule a stored run measured."""
    import subprocess
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "flowchart2sdnn"], cwd=ROOT)
        return head.stdout.strip() + ("+" if dirty.returncode else "")
    except OSError:
        return ""


def _f(v, fmt=".4f") -> str:
    return "—" if v is None else format(v, fmt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--charts", choices=sorted(BENCHES), default="learned",
                    help="learned: 3-tanh friction curves on 1 mrad/s-sign plants; physical: the plants' own "
                         "friction structure (widths fixed) on 0.05 rad/s-sign plants")
    ap.add_argument("--plants", default="two,three")
    ap.add_argument("--noise", default="0.003,0.01,0.03")
    ap.add_argument("--n-seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=30.0, help="training record; validation is half as long")
    ap.add_argument("--max-iter", type=int, default=None, help="diagnose's max_iter (default: its own)")
    ap.add_argument("--allow-unconverged", action="store_true", help="trace even when the first fit did not converge")
    ap.add_argument("--json", default=None, help="append one JSON line per run to this file")
    args = ap.parse_args()
    settings = DiagnoseSettings(require_converged=not args.allow_unconverged)
    if args.max_iter is not None:
        settings = dataclasses.replace(settings, max_iter=args.max_iter)
    rows = []
    print("| plant | noise | seed | N | first fit | train RMS | accepted | val RMS before → after | floor | "
          "round 1 refused | stop | wall |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    for key in args.plants.split(","):
        for noise in (float(x) for x in args.noise.split(",")):
            for seed in range(args.first_seed, args.first_seed + args.n_seeds):
                r = run_one(key, noise, seed, args.seconds, settings, args.charts)
                rows.append(r)
                print(f"| {key} | {noise:g} | {seed} | {r['substeps']} | "
                      f"{'converged' if r['first_fit_converged'] else r['first_fit_status']} "
                      f"({r['first_fit_iterations']} it) | "
                      f"{_f(r['train_rms_before'])} | {', '.join(r['accepted']) or 'nothing'} | "
                      f"{_f(r['val_before'])} → {_f(r['val_after'])} | {_f(r['floor'])} | {r['refused']} | "
                      f"{r['stop']} | {r['wall']:.0f} s |", flush=True)
                if args.json:
                    with open(args.json, "a") as fh:
                        fh.write(json.dumps(r) + "\n")
    alarms = sum(1 for r in rows if r["accepted"])
    print(f"\nfalse alarms: {alarms} of {len(rows)} runs")


if __name__ == "__main__":
    main()
