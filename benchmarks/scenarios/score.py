"""Score `sdnn diagnose` by rates on fresh scenarios: draw, write, diagnose, judge, summarise.

Seeds are drawn at run time (``secrets``) and printed first, so any draw can be replayed with ``--seed``. Each
scenario is written to its own directory (plant.yaml, chart.yaml, train.csv, validation.csv, truth.json, and
after the run verdict.json); diagnose reads the chart and the CSVs from there through the library API, as a
user's script would, with its default settings (``--rounds`` aside).

Run from the repository root::

    python -m benchmarks.scenarios.score --n 40 --category one-missing-closed-loop --workers 1
    python -m benchmarks.scenarios.score --seed 123456 --category two-missing      # replay one draw
    python -m benchmarks.scenarios.score --n 5 --dry                                # draw and write only
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import secrets  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

from .draw import CATEGORIES, draw, write_scenario  # noqa: E402
from .plants import FAMILIES  # noqa: E402
from .rates import judge, summarise  # noqa: E402
from .sensors import SENSORS  # noqa: E402

__all__ = ["run_one", "main"]


def run_one(seed: int, category: str | None, family: str | None, seconds: float | None, sensor: str | None,
            root: str, dry: bool, rounds: int) -> dict:
    """Draw scenario `seed`, write it under `root`, and (unless `dry`) diagnose and judge it: one result row."""
    t0 = time.perf_counter()
    try:
        scenario = draw(seed, category, family, seconds, sensor)
    except (ValueError, FloatingPointError) as exc:  # the generator's own plant blew up: nothing to judge
        return {"seed": seed, "draw_failed": str(exc)}
    paths = write_scenario(scenario, Path(root) / f"seed{seed}")
    row = {"seed": seed, "category": scenario.category, "family": scenario.family,
           "sensor": scenario.sensor.kind, "seconds_record": round(scenario.seconds, 1),
           "missing": [f"{m.kind}@{m.place}" for m in scenario.missing], "dir": str(paths["chart"].parent),
           "draw_seconds": time.perf_counter() - t0,
           "unexposed": [k for k, v in scenario.facts["train"]["exposure"].items() if v == 0.0]}
    if dry:
        return row
    from flowchart2sdnn.api import load_chart, read_csv
    from flowchart2sdnn.diagnose import DiagnoseSettings, diagnose
    from flowchart2sdnn.errors import SdnnError

    report, error, crashed = None, None, False
    t1 = time.perf_counter()
    try:
        chart = load_chart(paths["chart"])
        train = read_csv(paths["train"], chart=chart)
        val = read_csv(paths["validation"], chart=chart)
        report = diagnose(chart, train, [val], DiagnoseSettings(rounds=rounds)).report
    except (SdnnError, ValueError) as exc:  # diagnose declining the scenario is a result, not a crash
        error = f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # noqa: BLE001  (a crash is a result too: counted, and the run goes on)
        error, crashed = f"{type(exc).__name__}: {exc}", True
    row["seconds"] = time.perf_counter() - t1
    verdict = judge(scenario.truth, report, error, crashed)
    if report is not None:
        verdict["stop"] = report.get("stop")
        verdict["validation_rms"] = [report["before"].get("validation_rms"), report["after"].get("validation_rms")]
    (paths["chart"].parent / "verdict.json").write_text(json.dumps({**row, **verdict}, indent=1, default=str))
    return {**row, **verdict}


def _line(r: dict) -> str:
    if "draw_failed" in r:
        return f"seed {r['seed']:>10} not drawn: the generator's plant failed ({r['draw_failed']})"
    head = (f"seed {r['seed']:>10} {r['category']:<26} {r['family']:<10} {r['sensor']:<7} "
            f"{r['seconds_record']:>5.1f} s  missing: {', '.join(r['missing']) or 'nothing'}")
    if r.get("unexposed"):
        head += f" (never reached in the training record: {', '.join(r['unexposed'])})"
    if "accepted" not in r:
        return head + f"  -> {r['dir']}"
    marks = [k for k in ("right_first", "both", "clean") if r.get(k) is not None]
    verdict = " ".join(f"{k}={'yes' if r[k] else 'NO'}" for k in marks)
    return (head + f"  accepted: {', '.join(r['accepted']) or 'nothing'}  {verdict}"
            + ("  REFUSED" if r["refused"] else "") + ("  CRASHED" if r.get("crashed") else "")
            + (f"  [{r['error']}]" if r.get("error") else "")
            + (f"  true effect ranked {r['true_rank']}" if r.get("true_rank") else "")
            + ("  (refitted and refused)" if r.get("true_refused") else "") + f"  ({r['seconds']:.0f} s)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.scenarios.score", description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10, help="draws (ignored with --seed)")
    ap.add_argument("--category", choices=CATEGORIES, help="fix the number of missing effects (and excitation)")
    ap.add_argument("--family", choices=FAMILIES)
    ap.add_argument("--sensor", choices=SENSORS)
    ap.add_argument("--seed", type=int, action="append", help="replay this draw (repeatable)")
    ap.add_argument("--seconds", type=float, help="training record length (default: drawn in 10-60 s)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=3, help="diagnose's rounds")
    ap.add_argument("--out", help="directory for the scenarios (default: a new temporary one)")
    ap.add_argument("--dry", action="store_true", help="only draw and write the scenarios")
    args = ap.parse_args(argv)
    seeds = args.seed or [secrets.randbits(31) for _ in range(args.n)]
    root = args.out or tempfile.mkdtemp(prefix="sdnn-scenarios-")
    print(f"seeds: {' '.join(map(str, seeds))}", flush=True)
    print(f"scenarios in {root}", flush=True)
    jobs = [(s, args.category, args.family, args.seconds, args.sensor, root, args.dry, args.rounds) for s in seeds]
    rows = []
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            for r in pool.map(run_one, *zip(*jobs, strict=True)):
                rows.append(r)
                print(_line(r), flush=True)
    else:
        for job in jobs:
            rows.append(run_one(*job))
            print(_line(rows[-1]), flush=True)
    if not args.dry:
        print()
        for line in summarise([r for r in rows if "draw_failed" not in r]):
            print(line)
        (Path(root) / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
