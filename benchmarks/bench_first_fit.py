"""Would diagnose refuse? The first fit of a chart that lacks one or two effects, on fresh scenario draws.

diagnose traces a chart only from a first fit at its minimum: it refuses ("first_fit_not_converged") when that
fit stopped while parameters would still move by more than their standard error. This bench runs exactly that
first fit (diagnose.fitting.fit_chart with diagnose's settings) and that test (diagnose.fitting.still_moving) on
scenarios drawn from fresh seeds (printed; `--seed S` replays one) by benchmarks/scenarios: one or two missing
effects, every family, open loop (APRBS + relay, multisine) and a closed PI speed loop, white, coloured and
quantised sensor noise. It prints per category the refusal rate with a 95 % Wilson interval, the stop status
counts and the iterations and seconds of the first fit.

Run: ``python benchmarks/bench_first_fit.py --n 30`` (about 10-60 s a draw on 2 cores).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.scenarios.draw import draw, write_scenario  # noqa: E402
from benchmarks.scenarios.rates import wilson  # noqa: E402
from flowchart2sdnn.api import load_chart, read_csv  # noqa: E402
from flowchart2sdnn.diagnose import DiagnoseSettings  # noqa: E402
from flowchart2sdnn.diagnose.fitting import fit_chart, still_moving  # noqa: E402

CATEGORIES = ("one-missing-aprbs", "one-missing-multisine", "one-missing-closed-loop",
              "two-missing-aprbs", "two-missing-closed-loop")


class DrawFailed(Exception):
    """The scenario itself could not be simulated (the generator's plant blew up): no record, nothing to judge."""


def one_draw(seed: int, category: str, root: Path, seconds: float | None = None) -> dict:
    try:
        scenario = draw(seed, category, seconds=seconds)
    except (ValueError, FloatingPointError) as exc:
        raise DrawFailed(str(exc)) from exc
    paths = write_scenario(scenario, root / f"seed{seed}")
    chart = load_chart(paths["chart"])
    train, val = read_csv(paths["train"], chart=chart), read_csv(paths["validation"], chart=chart)
    settings = DiagnoseSettings()
    t0 = time.perf_counter()
    fitted = fit_chart(chart, [train], [(val, 0)], settings, settings.max_iter, 0, "chart")
    moving = still_moving(fitted) if fitted.identification.converged is False else []
    return {"seed": seed, "category": category, "family": scenario.family, "sensor": scenario.sensor.kind,
            "missing": [f"{m.kind}@{m.place}" for m in scenario.missing], "status": fitted.identification.status,
            "iterations": fitted.identification.lm.iterations if fitted.identification.lm else 0,
            "refused": bool(moving), "moving": moving, "seconds": time.perf_counter() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=30, help="draws in all (spread over the categories)")
    ap.add_argument("--seed", type=int, action="append", help="replay these seeds (with --category)")
    ap.add_argument("--category", choices=CATEGORIES)
    ap.add_argument("--seconds", type=float, help="fix the training record's length (default: drawn, 10-60 s)")
    args = ap.parse_args()
    seeds = args.seed or [int(s) for s in np.random.SeedSequence().generate_state(args.n)]
    print(f"# seeds drawn: {seeds}" + (f"; records {args.seconds:g} s" if args.seconds else ""), flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, seed in enumerate(seeds):
            category = args.category or CATEGORIES[i % len(CATEGORIES)]
            try:
                r = one_draw(seed, category, Path(tmp), args.seconds)
            except DrawFailed as exc:
                print(f"{category:24s} seed {seed:>10d} not drawn: {str(exc)[:100]}", flush=True)
                continue
            except Exception as exc:  # noqa: BLE001  (a fit that raises is a result: counted as refused)
                r = {"seed": seed, "category": category, "status": f"error: {exc}"[:120], "iterations": 0,
                     "refused": True, "moving": [], "seconds": 0.0, "family": "?", "sensor": "?", "missing": []}
            rows.append(r)
            print(f"{r['category']:24s} seed {seed:>10d} {r['family']:10s} {r['sensor']:8s} "
                  f"{','.join(r['missing']):40s} {r['status']:16s} {r['iterations']:4d} it {r['seconds']:6.1f} s"
                  f"{'  REFUSED: ' + ', '.join(r['moving']) if r['refused'] else ''}", flush=True)
    k = sum(r["refused"] for r in rows)
    lo, hi = wilson(k, len(rows))
    print(f"\nrefused: {k}/{len(rows)} [{lo:.3f}, {hi:.3f}]")
    print("stops:", dict(Counter(r["status"] for r in rows)))
    its = np.array([r["iterations"] for r in rows])
    print(f"iterations median {np.median(its):g} (max {its.max()}); seconds median "
          f"{np.median([r['seconds'] for r in rows]):.1f}")


if __name__ == "__main__":
    main()
