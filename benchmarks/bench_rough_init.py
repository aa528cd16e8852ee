"""Rough inits: how often one default start reaches the global minimum, ours against a plain trust region.

The bench (issue 14): the two-mass drive simulated by `sdnn excite` (continuous RK4 plant, APRBS + relay,
seed 1, 0.01 rad/s noise), N charts whose free physical parameters start at truth ×/÷ a log-uniform factor up
to 3 (draw i uses ``numpy.random.default_rng([seed, i])``, one factor per free parameter in chart order), J1
fixed at the truth. Two charts:

* ``learned``: diagrams/two_mass.yaml on the paper's network (tests/data/two_mass_euler.yaml; learned tanh friction curves, output w2) on diagrams/two_mass_plant.yaml
  (Coulomb + Stribeck + viscous friction on both machines);
* ``coulomb``: diagrams/two_mass_coulomb.yaml (physical Coulomb + viscous terms) on its own plant.

For each draw: (a) ``ours``: LM as `identify` runs it by default (the options of
:func:`flowchart2sdnn.identify.offline.optimize.lm_options`, one start); (b) ``trf``: ``scipy.optimize.least_squares(
method='trf', x_scale='jac')`` with the chart's bounds (min: 0 -> positivity) on the SAME residual and RTRL
Jacobian (`Problem.fun`), so only the optimizer differs. A run "reaches the global minimum" when its cost is
within 1.05x of the reference: the lowest of a fit started at the truth (both optimizers) and every run.
``--variant`` runs our LM with one change (see VARIANTS) to measure what closes the gap.

Run: ``python benchmarks/bench_rough_init.py --chart coulomb --n 8 --seconds 30`` (minutes per chart on a
shared 2-core machine). Measured with the default (μD² damping, the curves' stick-slip start, geodesic
acceleration with bend limit 0.75) and ``--variant plain-steps`` (the default before geodesic acceleration)
interleaved in the same run, 26 Nov 2026, heavily loaded machine (seconds noisy; iterations include the curves'
150 brief ones, the 1000 limit applies after them; more in benchmarks/notes/rough_init.md):

| chart, record, seed, draws | default: at the minimum, converged, median iterations | plain-steps, the same | scipy trf |
|---|---|---|---|
| coulomb, 30 s, seed 1, N = 8 | 8/8, 8/8, 22 (18-38); 2.36× trf's seconds (median per draw) | 8/8, 8/8, 44 (28-131); 3.15× | 8/8, 21 evaluations (14-25) |
| learned, 10 s, seed 2, N = 10 | 10/10, 10/10, 190 (180-709) | 10/10, 2/10 (8 at the limit), 1150 | — |
| learned, 10 s, seed 1, N = 20 | 20/20, 20/20, 765 (671-1147) | (draws 0-3: 4/4, 4/4, 454, at 1.128 against 1.120) | — |
| learned, 30 s, seed 1, N = 4 | 4/4, 4/4, 888 (888-1095) | 4/4, 0/4 (all at the limit), 1150 | — |
| learned, 30 s, seed 1, N = 20 (default only) | 20/20, 20/20, 888 (632-1095) | — | — |

The rows above were measured before Nielsen's damping and the first trial with its Jacobian (fit.lm's
``damping``, ``trial_jacobian``; ``--variant before-speed`` undoes both), identify's default since on charts
without learned curves. One run per chart, 26 Nov 2026, load average 2.7-3.8 (benchmarks/notes/rough_init.md, "Speed"):

| chart, record, seed, draws | Nielsen + first-trial Jacobian: at the minimum, converged, median iterations | before-speed, the same | scipy trf |
|---|---|---|---|
| coulomb, 30 s, seed 1, N = 8 (the default) | 8/8, 8/8, 22 (19-36); **1.88×** trf's seconds | 8/8, 8/8, 22 (18-38); 2.31× | 8/8, 21 evaluations (14-25) |
| three-physical, 10 s, seed 1, N = 6 (the default) | 6/6, 6/6, 37.5 (35-52), 8.7 s | 6/6, 6/6, 47 (23-72), 10.9 s | — |
| learned, 10 s, seed 2, N = 10 (not the default) | 10/10, 10/10, 178 (172-190) | 10/10, 10/10, 190 (180-714) | — |
| learned, 10 s, seed 1, N = 12 (not the default) | 12/12, 9/12 (3 at the limit, lower costs), 897 | (draws 0-3) 4/4, 4/4, 749 | — |

``--variant scaled-bounds-plain`` (one-sided bounds bending within 1 % of the start's distance, plain steps;
not the default: a quantity whose minimum is its bound crawls there) gave 1.37× trf's seconds on coulomb.

Since 27 Nov identify keeps the bounds of charts without learned curves in the box with a trust radius
(fit.boxstep, fit.lm damping "trust"; ``--variant transform`` is the default before, ``box-nielsen`` the box with
Nielsen's damping). One run, coulomb, 30 s, seed 1, N = 8, load from three other benches (benchmarks/notes/rough_init.md,
"Bounds without a transform"):

| variant | at the minimum, converged, median iterations (range) | s per draw / trf's, median (range) |
|---|---|---|
| box-trust (the default) | 8/8, 8/8, 16 (9-22) | **0.88** (0.67-1.55) |
| box-nielsen | 8/8, 8/8, 24 (17-33) | 1.24 (0.99-2.55) |
| transform (the default before) | 8/8, 8/8, 22 (19-36) | 1.95 (1.35-4.35) |
| scipy trf | 8/8, 8/8, 21 evaluations (14-25) | 1 |

A second run (default against transform and trf): 0.87 (0.56-1.54) against 1.86.
three-physical, 10 s, N = 4, ``--no-trf``: box-trust 4/4, 4/4, 12 (11-41), 5.7 s per fit; the transform 4/4, 4/4,
37 (35-52), 23.3 s.

On the learned chart J2 and c end within 0.4 % and 0.1 % of the truth from every draw; d goes to its bound 0 on
10 s (−86 % on 30 s): it trades against the two learned curves' viscous slopes. Earlier (plain steps): trainlm's
μI found the coulomb minimum from 2 of 3 draws in 167-668 iterations (μD²: 3/3, 22-27); the learned curves
from the chart's random weights (``--variant random-curves``) 0/20 on the 10 s record.

Three-mass drive (``--chart three-physical``: three_mass_physical.yaml on three_mass_stribeck_wide_plant.yaml;
``--chart three-learned``: three_mass_learned.yaml on three_mass_stribeck_plant.yaml), ``--variant identify
--no-trf`` (one `identify()` call with every default: shooting auto, sub-steps auto, the curves' start), 10 s,
seed 1 (the issue's ≥ 18/20). three-physical measured before geodesic acceleration (plain steps; not
re-measured); three-learned with geodesic steps and the curves' step at 0.3 of the network's own chatter limit
2J/h (N = 8 here; it was 2J/T, 8× softer, benchmarks/notes/rough_init.md), draws 0-4, 5-12, 13-19 in three runs, two at
once on the shared 2-core machine (load average 3.5-4: seconds 2-3× a quiet machine's), 26 Nov 2026:

| chart, record, draws | global minimum | costs | converged | iterations, median (range) | s per fit | worst physical error |
|---|---|---|---|---|---|---|
| three-physical, 10 s, N = 20 | 20/20 (ref 1.47438) | 1.4744-1.481 | 20/20 | 190 (23-377) | 35.6 (5.6-66.9) | b2 −14.5 % |
| three-learned, 10 s, N = 20 | 20/20 (ref 1.475) | 1.475-1.484 | 19/20 (draw 9 at the limit) | 318 (156-1150) | 125 (30-233) | the bᵢ (b3 up to +1569 %: traded against the curves' slopes); J, c within 0.1 %, d within 0.6 % |
| three-learned with the crawl rule (27 Nov, one run beside the test suite) | 20/20 (ref 1.47524) | 1.475-1.484 | 20/20 | 293 (158-670) | 49.9 (20.6-92.9) | the bᵢ, as above; J, c within 0.1 %, d within 0.5 % |
| three-learned, 30 s, crawl rule (27 Nov, draws 0-9 and 10-19 at once) | 19/20 (ref 4.4766) | 4.477-4.506 (draw 3: 81 150, shafts locked by the curves' brief fit; identify() itself, with its second look, ends at 4.47677) | 20/20 | 345 (109-660) | 145 | the bᵢ −6…+18 %; J, c within 0.05 %, d within 0.7 % |
| three-learned before the step fix (plain steps), N = 7 | 6/7 (ref 1.475) | 1.475-1.805 | 1/7 | 1150 (856-1150) | 149 (112-191) | b1 +352 %, b2 −100 % |

``--shooting L`` adds our default LM with multiple shooting (identify.shooting.multiple). learned, 10 s, N = 4, seed 1,
``--shooting 250`` (stages 250/1000/4000, then single shooting): 0/4 against 1/4 single shooting (costs 1.35-13.2
against 1.27-1.46; one final stage at the 1000 limit), median 23.7 s against 6.6 s: the learned chart's local
minima (d traded against the learned curves' slopes) are not the long-horizon kind that shooting removes.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy.optimize import least_squares  # noqa: E402

from flowchart2sdnn.api import dataset_from_frame  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.identify.offline.curvestart import curve_start  # noqa: E402
from flowchart2sdnn.identify.offline.optimize import lm_options  # noqa: E402
from flowchart2sdnn.identify.offline.problem import build_problem  # noqa: E402
from flowchart2sdnn.identify.offline.run import identify  # noqa: E402
from flowchart2sdnn.identify.offline.workers import run_start  # noqa: E402
from flowchart2sdnn.identify.settings import IdentifySettings  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402

CHARTS = {"learned": ("two_mass", "two_mass_plant"), "coulomb": ("two_mass_coulomb", "two_mass_coulomb_plant"),
          "three-learned": ("three_mass_learned", "three_mass_stribeck_plant"),
          "three-physical": ("three_mass_physical", "three_mass_stribeck_wide_plant")}
#: our LM with one change each; "default" is identify's default
#: ("curve_start": "random" starts the learned curves from the chart's seeded weights, the default before
#: identify.offline.curvestart; keys "lm_*" are IdentifySettings fields, resolved by identify.offline.optimize.lm_options as identify
#: does; every other key is an LMOptions field set after them). On charts without learned curves the default
#: keeps the bounds without a transform ("box") with a trust radius; the variants that change the geodesic steps,
#: the transform's width or the damping schedule start from the bound transform ("lm_bounds": "transform"), the
#: default there before (and still on learned charts).
T = {"lm_bounds": "transform"}
VARIANTS = {
    "default": {},
    "transform": T,  # the bound transform, geodesic steps, Nielsen's damping: the default before "box"
    "plain-steps": {**T, "geodesic": 0.0},  # no geodesic acceleration: the default before it
    "bend-0.5": {**T, "geodesic": 0.5},  # geodesic acceleration's largest bend (the default's: IDENTIFY_GEODESIC)
    "bend-1.0": {**T, "geodesic": 1.0},
    "random-curves": {"curve_start": "random"},
    "noscale": {"scale": "none"},
    "jac-per-weight": {"scale": "jac", "scale_groups": ()},
    "tau0": {"tau": 0.0},
    # the speed changes (fit.lm's damping and trial_jacobian), each undone alone and both
    "trainlm-damping": {**T, "damping": "trainlm"},  # mu x0.1 / x10 (before Nielsen's schedule)
    # one-sided bounds bending within 1 % of the start's distance from the bound (fit.transforms), not 1 unit
    "scaled-bounds": {**T, "bound_width": 0.01},
    "scaled-bounds-plain": {**T, "bound_width": 0.01, "geodesic": 0.0},
    # bounds without a transform (fit.boxstep: plain steps in the physical coordinates kept inside the bounds),
    # with Nielsen's damping; with a trust radius ("trust", Moré's LM) it is the default on charts without
    # learned curves (box-trust)
    "box-nielsen": {"lm_bounds": "box", "lm_damping": "nielsen"},
    "box-trust": {"lm_bounds": "box", "lm_damping": "trust"},
    "residual-trials": {**T, "trial_jacobian": False},  # every trial residual-only, the Jacobian simulated again
    "before-speed": {**T, "damping": "trainlm", "trial_jacobian": False},
    "identify": {},  # identify() itself, every default (substeps, shooting auto, curves' start): fit_identify
    # identify() with the box and the trust radius on learned curves too (the default keeps their transform)
    "identify-box": {"lm_bounds": "box", "lm_damping": "trust"},
}
FACTOR = 3.0
GLOBAL = 1.05


def bench_data(plant, seconds: float, seed: int, noise: float):
    data = excite(plant, ExcitationSettings(seconds=seconds, seed=seed, noise_std=noise))
    return dataset_from_frame(data, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names),
                              name=f"excite({plant.name}, {seconds:g} s, seed {seed})")


def rough_chart(chart, truth: dict, rng: np.random.Generator):
    """The chart with every free parameter's init at truth ×/÷ a log-uniform factor up to FACTOR; J1 fixed."""
    params = []
    for p in chart.parameters:
        if p.name == "J1":
            p = dataclasses.replace(p, init=truth["J1"], fixed=True)
        elif not p.fixed:
            p = dataclasses.replace(p, init=truth[p.name] * float(np.exp(rng.uniform(-1, 1) * np.log(FACTOR))))
        params.append(p)
    return dataclasses.replace(chart, parameters=tuple(params))


def truth_chart(chart, truth: dict):
    return dataclasses.replace(chart, parameters=tuple(
        dataclasses.replace(p, init=truth[p.name], fixed=p.fixed or p.name == "J1") for p in chart.parameters))


def fit_ours(chart, data, variant: dict, seed: int, shooting: int = 0):
    problem = build_problem(chart, data, seed=seed)
    x0 = problem.compiled.theta0()
    lo, hi = problem.bounds()
    variant = dict(variant)
    curves = variant.pop("curve_start", IdentifySettings().curve_start)
    settings = {k: variant.pop(k) for k in list(variant) if k.startswith("lm_")}
    opts = dataclasses.replace(lm_options(IdentifySettings(seed=seed, **settings), problem), **variant)
    t0 = time.perf_counter()
    brief = 0
    if curves == "stick":  # as identify's _offline: the learned curves' step start and brief fit first
        warm = curve_start(problem, x0, lo, hi, opts)
        x0, brief = warm.x, warm.iterations
    r = run_start(problem, x0, lo, hi, opts, shooting=shooting)
    iterations = brief + r.iterations + sum(s["iterations"] for s in r.stages[:-1])  # every stage's (shooting)
    return problem, r.x, r.cost, time.perf_counter() - t0, iterations, r.status


def fit_identify(chart, data, seed: int, **settings):
    """One default `identify` run (what a user gets: shooting auto, the curves' start, the stability check);
    `settings`: IdentifySettings fields that differ from the defaults."""
    t0 = time.perf_counter()
    out = identify(chart, data, settings=IdentifySettings(seed=seed, **settings))
    secs = time.perf_counter() - t0
    lm = out.lm
    brief = (out.extra.get("curve_start") or {}).get("iterations", 0)
    iterations = brief + lm.iterations + sum(s["iterations"] for s in lm.stages[:-1])
    values = {n: e.value for n, e in out.parameters.items() if n in out.problem.names}
    status = f"{lm.status}{'' if out.converged else ' (NOT conv.)'}"
    return out.problem, np.array(list(values.values())), float(lm.cost), secs, iterations, status, values


def fit_trf(chart, data, seed: int):
    problem = build_problem(chart, data, seed=seed)
    x0 = problem.compiled.theta0()
    lo, hi = problem.bounds()
    memo = {}

    def both(x):
        key = x.tobytes()
        if key not in memo:
            memo.clear()
            out = problem.fun(x)
            memo[key] = (None, None) if out is None else out
        return memo[key]

    def res(x):
        e, _ = both(x)
        return np.full(problem.n_residuals, 1e150) if e is None else -e

    def jac(x):
        return both(x)[1]

    t0 = time.perf_counter()
    r = least_squares(res, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=1000)
    return problem, r.x, float(r.cost), time.perf_counter() - t0, r.nfev, str(r.status)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--chart", choices=sorted(CHARTS), default="coulomb")
    ap.add_argument("--n", type=int, default=8)
    ap.add_argument("--first", type=int, default=0, help="first draw (draws first .. first + n - 1)")
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=1, help="seed of the bench record and of the rough draws")
    ap.add_argument("--variant", action="append", choices=sorted(VARIANTS), help="our LM variants (default: default)")
    ap.add_argument("--no-trf", action="store_true")
    ap.add_argument("--shooting", type=int, action="append", default=[],
                    help="also our default LM with multiple shooting, segments of this many samples (repeatable)")
    args = ap.parse_args()
    variants = args.variant or ["default"]
    chart_name, plant_name = CHARTS[args.chart]
    plant = load_diagram(ROOT / "diagrams" / f"{plant_name}.yaml")
    chart = load_diagram(ROOT / ("tests/data/two_mass_euler.yaml" if args.chart == "learned" else f"diagrams/{chart_name}.yaml"))
    truth = {p.name: float(p.init) for p in plant.parameters}
    data = bench_data(plant, args.seconds, args.seed, 0.01)
    print(f"# {args.chart}: {chart_name}.yaml on {plant_name}.yaml, {args.seconds:g} s, seed {args.seed}, "
          f"noise 0.01, draws {args.first}-{args.first + args.n - 1}, factor ×/÷{FACTOR:g}")
    runs: dict[str, list] = {v: [] for v in variants}
    runs.update({f"shoot-{n}": [] for n in args.shooting})
    if not args.no_trf:
        runs["trf"] = []
    ref = []
    for name in variants:
        if name.startswith("identify"):
            ref.append(fit_identify(truth_chart(chart, truth), data, args.seed, **VARIANTS[name])[2])
            continue
        ref.append(fit_ours(truth_chart(chart, truth), data, VARIANTS[name], args.seed)[2])
    if not args.no_trf:
        ref.append(fit_trf(truth_chart(chart, truth), data, args.seed)[2])
    print(f"truth starts: {', '.join(f'{c:.6g}' for c in ref)}", flush=True)  # a run cut short keeps its reference
    for i in range(args.first, args.first + args.n):
        rough = rough_chart(chart, truth, np.random.default_rng([args.seed, i]))
        for name in runs:  # interleaved: every method on draw i before draw i + 1 (fair under shared load)
            if name == "trf":
                out = fit_trf(rough, data, args.seed)
            elif name.startswith("identify"):
                out = fit_identify(rough, data, args.seed, **VARIANTS[name])
            elif name.startswith("shoot-"):
                out = fit_ours(rough, data, VARIANTS["default"], args.seed, int(name[6:]))
            else:
                out = fit_ours(rough, data, VARIANTS[name], args.seed)
            problem, x, cost, secs, evals, status = out[:6]
            values = out[6] if len(out) > 6 else dict(zip(problem.names, x, strict=True))
            runs[name].append((cost, secs, evals, status, values))
            errs = " ".join(f"{k} {100 * (values[k] / truth[k] - 1):+.1f}%" for k in values if k in truth)
            worst = max((abs(values[k] / truth[k] - 1) for k in values if k in truth), default=0.0)
            runs[name][-1] += (worst,)
            print(f"draw {i} {name:10s} cost {cost:10.4g} {secs:6.1f} s {evals:4d} it/ev {status:18s} {errs}",
                  flush=True)
    best = min([*ref] + [r[0] for rs in runs.values() for r in rs])
    print(f"\nreference cost {best:.6g} (truth starts: {', '.join(f'{c:.6g}' for c in ref)})\n")
    print("| optimizer | global minimum (cost <= 1.05x ref) | costs | median s per fit | median iterations/evaluations "
          "(range) | converged | median (max) worst physical error |")
    print("|---|---|---|---|---|---|---|")
    for name, rs in runs.items():
        hit = sum(r[0] <= GLOBAL * best for r in rs)
        conv = sum("NOT" not in r[3] and r[3] != "max_iter" for r in rs)
        its = [r[2] for r in rs]
        worst = [100 * r[5] for r in rs]
        print(f"| {name} | {hit}/{len(rs)} | {min(r[0] for r in rs):.4g}-{max(r[0] for r in rs):.4g} | "
              f"{np.median([r[1] for r in rs]):.1f} | {np.median(its):.0f} ({min(its)}-{max(its)}) | "
              f"{conv}/{len(rs)} | {np.median(worst):.1f} % ({max(worst):.1f} %) |")
    if "trf" in runs:  # the speed acceptance: a default fit no slower than trf, draw by draw in one run
        for name, rs in runs.items():
            if name != "trf":
                ratio = [r[1] / t[1] for r, t in zip(rs, runs["trf"], strict=True)]
                print(f"{name} / trf seconds per draw: median {np.median(ratio):.2f} "
                      f"({min(ratio):.2f}-{max(ratio):.2f})")


if __name__ == "__main__":
    main()
