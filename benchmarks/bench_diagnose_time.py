"""Time to diagnose's answer on fresh drives, serial and with ``--workers``.

Each draw (seed drawn at run time and printed; ``--seed S`` replays one) takes a plant and the user's chart of
bench_fits_finish (every friction one learned curve, no viscous gain, inits x/÷ up to 2), a 30 s training and a
15 s validation record (0.01 rad/s white noise, APRBS + relay), and with ``--missing load-friction`` drops the
last machine's friction curve from the chart (``--missing none``: the complete chart). It runs
``diagnose(chart, train, [validation])`` with the default settings and prints what was accepted, the
validation RMS before and after, and the seconds of each phase (from the progress messages).

Run: ``python benchmarks/bench_diagnose_time.py --family two-mass --missing load-friction [--workers 2]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_fits_finish import PLANTS, draw_plant, record, user_chart  # noqa: E402

from flowchart2sdnn.diagnose.fitting import DiagnoseSettings  # noqa: E402
from flowchart2sdnn.diagnose.loop import diagnose  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402

MISSING = ("none", "load-friction")


def without_load_friction(chart):
    """The chart with the last machine's learned friction curve taken out of its sum."""
    curves = sorted(b.name for b in chart.blocks if b.kind == "nonlinear")
    last = curves[-1]
    blocks = []
    for b in chart.blocks:
        if b.name == last:
            continue
        if b.kind == "sum":
            b = dataclasses.replace(b, inputs=tuple(t for t in b.inputs if t.signal != last))
        blocks.append(b)
    return dataclasses.replace(chart, blocks=tuple(blocks))


def one_draw(family: str, missing: str, seed: int, workers: int, live: bool = False) -> dict:
    rng = np.random.default_rng(seed)
    plant, truth = draw_plant(load_diagram(ROOT / "diagrams" / f"{PLANTS[family]}.yaml"), rng)
    chart = user_chart(plant, truth, rng)
    if missing == "load-friction":
        chart = without_load_friction(chart)
    train = record(plant, 30.0, seed, 0.01)
    val = record(plant, 15.0, seed + 1, 0.01)
    marks = []
    t0, c0 = time.perf_counter(), time.process_time()

    def progress(text, fraction=None):
        if text.startswith("LM iteration") and marks and marks[-1][1].startswith("LM iteration"):
            marks[-1] = (time.perf_counter() - t0, text)  # one line per fit, not per iteration
            return
        marks.append((time.perf_counter() - t0, text))
        if live:
            print(f"  {marks[-1][0]:7.1f} s  {text}", flush=True)

    executor = None
    if workers > 1:
        from flowchart2sdnn.executors import make_executor
        executor = make_executor(workers)
    d = diagnose(chart, train, [val], settings=DiagnoseSettings(seed=seed), progress=progress, executor=executor)
    secs, cpu = time.perf_counter() - t0, time.process_time() - c0
    rep = d.report
    return {"seed": seed, "family": family, "missing": missing, "seconds": secs, "cpu": cpu, "stop": rep["stop"],
            "accepted": [f"{a['effect']}@{a['at']}" for a in rep["accepted"]],
            "before": rep["before"]["validation_rms"], "after": rep["after"]["validation_rms"],
            "first_fit": rep["first_fit"]["status"], "timing": rep["timing"], "marks": marks}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=list(PLANTS), default="two-mass")
    ap.add_argument("--missing", choices=MISSING, default="load-friction")
    ap.add_argument("--n", type=int, default=1)
    ap.add_argument("--seed", type=int, action="append")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--marks", action="store_true", help="print every progress message with its time")
    ap.add_argument("--no-cutoff", action="store_true",
                    help="the baseline: brief refits run their whole --refit-iter budget (no cut-off)")
    args = ap.parse_args()
    if args.no_cutoff:
        from flowchart2sdnn.diagnose import fitting

        fitting.behind = lambda target, max_iter: (lambda it, cost: None)
    seeds = args.seed or [int(s) for s in np.random.SeedSequence().generate_state(args.n)]
    print(f"# seeds drawn: {seeds}", flush=True)
    for seed in seeds:
        r = one_draw(args.family, args.missing, seed, args.workers, args.marks)
        t = r["timing"]
        print(f"{r['family']} missing {r['missing']} seed {seed}: {r['seconds']:.1f} s ({r['cpu']:.1f} s CPU in this process)  first fit {r['first_fit']}  "
              f"accepted {r['accepted'] or 'nothing'}  stop {r['stop']}  validation RMS {r['before']:.4g} -> "
              f"{r['after']:.4g}  (first fit {t['nominal_fit']:.1f} s, screens "
              f"{sum(t['screen']):.1f} s, refits {sum(t['refit']):.1f} s over {len(t['refit'])})", flush=True)


if __name__ == "__main__":
    main()
