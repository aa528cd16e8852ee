"""Issue 16's one-missing-effect table at a user's noise: is the true effect at the true place accepted first?

Each case is a continuous plant (`sdnn excite`: RK4, 20 steps per sample) with exactly one effect that its chart
lacks. Per seed s: one training record (30 s for the drives, excitation seed s) and one validation record (15 s;
3 s for the chaotic backlash and cogging drives; excitation seed 100 + s), white noise of ``--noise`` on every
output, and the chart's free parameters started at the plant's value (the chart's own init where the plant has
no such parameter) times a factor drawn log-uniformly within x/÷2 (numpy default_rng(s)). Then the library call
`diagnose(chart, train, [val], DiagnoseSettings(rounds=2))`. A row passes (issue 16) when the first accepted
effect is the true one at the true place, the validation RMS falls to within 1.2x the noise or by 3x or more, and
the linear parameters come back within 5 % (dampings within 10 %).

Cases (plants and charts in tests/data/diagnose/ unless named otherwise; the two-mass charts pin the paper's
scheme, N = 1 and the search rule):

* ``friction``: load friction (two_mass_friction_plant, charted by two_mass_shaft): friction at w2;
* ``dead_time``: 6-sample input dead time (two_mass_dead_time_plant / two_mass_nominal): dead_time at M1, n = 6;
* ``saturation``: torque clip (two_mass_saturation_plant / two_mass_nominal): saturation at M1;
* ``backlash``: shaft backlash, 4 mrad (two_mass_backlash_plant / two_mass_nominal): backlash or dead_zone at dphi;
* ``cogging``: motor cogging (two_mass_cogging_plant / two_mass_nominal): cogging at w1;
* ``level``: the upper tank overflows at 6 (tanks_overflow_plant / tanks; 1200 s / 600 s records, T = 1 s,
  the tanks' excitation of tests/test_diagnose_overflow.py): overflow at x1dev;
* ``backlash3``: backlash, 4 mrad, on the second shaft of the three-mass drive (three_mass_backlash_plant,
  charted by diagrams/three_mass.yaml, `substeps: auto`, `delays: torques`): backlash or dead_zone at dphi2.

Run from the repository root:
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_one_effect.py [--cases friction,cogging] [--seeds 1,2,3]
[--noise 0.01] [--shooting L] [--json OUT.jsonl]`` (a run: 10 s to a few minutes on one core).
Tables: docs/diagnose.md ("one missing effect at a time").
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.api import dataset_from_frame  # noqa: E402
from flowchart2sdnn.diagnose import DiagnoseSettings, diagnose  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

BENCH = ROOT / "tests" / "data" / "diagnose"
TANKS_EXCITATION = {"amplitude": (0.0, 2.0), "hold": (20.0, 80.0), "relay_level": 0.0}


@dataclasses.dataclass(frozen=True)
class Case:
    plant: Path
    chart: Path
    effects: tuple[str, ...]
    at: str
    option: object = None
    train_s: float = 30.0
    val_s: float = 15.0
    excitation: dict = dataclasses.field(default_factory=dict)


CASES = {
    "friction": Case(BENCH / "two_mass_friction_plant.yaml", BENCH / "two_mass_shaft.yaml", ("friction",), "w2"),
    "dead_time": Case(BENCH / "two_mass_dead_time_plant.yaml", BENCH / "two_mass_nominal.yaml", ("dead_time",),
                      "M1", 6),
    "saturation": Case(BENCH / "two_mass_saturation_plant.yaml", BENCH / "two_mass_nominal.yaml",
                       ("saturation",), "M1"),
    "backlash": Case(BENCH / "two_mass_backlash_plant.yaml", BENCH / "two_mass_nominal.yaml",
                     ("backlash", "dead_zone"), "dphi", val_s=3.0),
    "cogging": Case(BENCH / "two_mass_cogging_plant.yaml", BENCH / "two_mass_nominal.yaml", ("cogging",), "w1",
                    val_s=3.0),
    "level": Case(BENCH / "tanks_overflow_plant.yaml", BENCH / "tanks.yaml", ("overflow",), "x1dev",
                  train_s=1200.0, val_s=600.0, excitation=TANKS_EXCITATION),
    "backlash3": Case(BENCH / "three_mass_backlash_plant.yaml", ROOT / "diagrams" / "three_mass.yaml",
                      ("backlash", "dead_zone"), "dphi2", val_s=3.0),
}


def record(plant, seconds: float, seed: int, noise: float, excitation: dict):
    data = excite(plant, ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise, **excitation))
    return dataset_from_frame(data, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names),
                              name=f"{plant.name}-seed{seed}-noise{noise:g}")


def rough_chart(chart, truth: dict, seed: int):
    """`chart` with each free parameter started at the plant's value (else its own init) times a factor in
    [1/2, 2], log-uniform, seeded."""
    rng = np.random.default_rng(seed)
    params, factors = [], {}
    for p in chart.parameters:
        if p.fixed:
            params.append(p)
            continue
        f = float(np.exp(rng.uniform(-math.log(2), math.log(2))))
        factors[p.name] = f
        params.append(dataclasses.replace(p, init=truth.get(p.name, p.init) * f))
    return dataclasses.replace(chart, parameters=tuple(params)), factors


def _is_damping(name: str) -> bool:
    return name[0] in "db" and name[1:].isdigit() or name in ("d", "b")


def run_one(key: str, seed: int, noise: float, settings: DiagnoseSettings) -> dict:
    case = CASES[key]
    plant, given = load_diagram(case.plant), load_diagram(case.chart)
    truth = plant.parameter_values()
    chart, factors = rough_chart(given, truth, seed)
    train = record(plant, case.train_s, seed, noise, case.excitation)
    val = record(plant, case.val_s, 100 + seed, noise, case.excitation)
    t0 = time.perf_counter()
    rep = diagnose(chart, train, [val], settings).report
    wall = time.perf_counter() - t0
    acc = rep["accepted"][0] if rep["accepted"] else None
    first = rep["rounds"][0] if rep["rounds"] else {}
    right = acc is not None and acc["effect"] in case.effects and acc["at"] == case.at and (
        case.option is None or acc.get("option") == case.option)
    before, after = first.get("validation_rms_before"), first.get("validation_rms_after")
    fell = (right and before is not None and after is not None
            and (after <= 1.2 * noise or after <= before / 3))
    values = first.get("parameters") or {}
    errors = {n: 100 * (values[n] - truth[n]) / truth[n] for n in truth
              if n in values and truth[n] and any(p.name == n and not p.fixed for p in given.parameters)}
    within = all(abs(e) <= (10 if _is_damping(n) else 5) for n, e in errors.items()) if right else False
    return {"case": key, "seed": seed, "noise": noise, "init_factors": factors, "commit": _commit(),
            "first_fit_converged": rep["first_fit"]["converged"], "stop": rep["stop"],
            "accepted": [f"{a['effect']}@{a['at']} ({a['label']})" for a in rep["accepted"]],
            "right_first": right, "val_before": before, "val_after": after, "fell": fell,
            "errors": errors, "within": within, "passed": bool(right and fell and within), "wall": wall}


def _commit() -> str:
    import subprocess
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(["git", "diff", "--quiet", "HEAD", "--", "flowchart2sdnn"], cwd=ROOT)
        return head.stdout.strip() + ("+" if dirty.returncode else "")
    except OSError:
        return ""


def _f(v) -> str:
    return "—" if v is None else f"{v:.4g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help=f"comma list of {', '.join(CASES)}")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--shooting", type=int, default=None, help="DiagnoseSettings.shooting (segment length)")
    ap.add_argument("--json", default=None, help="append one JSON line per run to this file")
    args = ap.parse_args()
    unknown = [k for k in args.cases.split(",") if k not in CASES]
    if unknown:
        ap.error(f"unknown case(s) {', '.join(unknown)}; expected some of {', '.join(CASES)}")
    settings = DiagnoseSettings(rounds=2)
    if args.shooting is not None:
        settings = dataclasses.replace(settings, shooting=args.shooting)
    print("| case | seed | accepted | val RMS before → after | worst parameter error % | pass | stop | wall |")
    print("|---|---|---|---|---|---|---|---|", flush=True)
    rows = []
    for key in args.cases.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            r = run_one(key, seed, args.noise, settings)
            rows.append(r)
            worst = max(r["errors"].items(), key=lambda kv: abs(kv[1]), default=None)
            print(f"| {key} | {seed} | {', '.join(r['accepted']) or 'nothing'} | {_f(r['val_before'])} → "
                  f"{_f(r['val_after'])} | {'' if worst is None else f'{worst[0]} {worst[1]:+.2f}'} | "
                  f"{'yes' if r['passed'] else 'NO'} | {r['stop']} | {r['wall']:.0f} s |", flush=True)
            if args.json:
                with open(args.json, "a") as fh:
                    fh.write(json.dumps(r) + "\n")
    print(f"\npassed: {sum(r['passed'] for r in rows)} of {len(rows)} runs")


if __name__ == "__main__":
    main()
