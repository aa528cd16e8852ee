"""A synthetic fleet through `sdnn batch` and `sdnn report`: files per second, and whether the drift is found.

20 drives, 10 daily logs each (200 files), made on the virtual test bench (``excite``) from a two-mass plant
with Coulomb and viscous friction on the motor. Every drive has its own parameters (5 % spread around the
nominal chart); drives 0-3 wear: their Coulomb friction Fc grows by 6 % of its first value a day; drives 4-5
lose shaft stiffness: c falls by 3 % a day. The rest stay as they were. The batch runs as the command a user
types (a subprocess, ``--workers N``); the report's drift list is compared with the truth.

Run: ``python benchmarks/bench_fleet.py [--drives 20] [--days 10] [--seconds 2] [--workers 2] [--keep DIR]``.
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import diagram_from_text
from flowchart2sdnn.executors import make_executor
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

REPO = Path(__file__).resolve().parents[1]

CHART = """\
sdnn: 1
name: fleet_drive
description: two-mass drive with Coulomb and viscous friction on the motor (fleet benchmark)
sample_time: 0.001
inputs:
  M1: {unit: N*m}
outputs:
  w1: {unit: rad/s}
  w2: {unit: rad/s}
parameters:
  J1: {init: 0.1912, unit: kg*m^2, min: 0}
  J2: {init: 0.3838, unit: kg*m^2, min: 0}
  c:  {init: 477.2, unit: N*m/rad, min: 0}
  d:  {init: 0.2406, unit: N*m*s/rad, min: 0}
  Fc: {init: 0.8, unit: N*m, min: 0, description: motor Coulomb friction}
  b:  {init: 0.02, unit: N*m*s/rad, min: 0, description: motor viscous friction}
blocks:
  MB1:  {type: sum, in: [M1, -MC, -MD, -MF, -MV], unit: N*m}
  acc1: {type: gain, in: MB1, k: 1/J1}
  w1:   {type: integrator, in: acc1, unit: rad/s}
  sg:   {type: function, f: sign_smooth, in: w1, eps: 0.01}
  MF:   {type: gain, in: sg, k: Fc, unit: N*m}
  MV:   {type: gain, in: w1, k: b, unit: N*m}
  dw:   {type: sum, in: [w1, -w2]}
  dphi: {type: integrator, in: dw, unit: rad}
  MC:   {type: gain, in: dphi, k: c}
  MD:   {type: gain, in: dw, k: d}
  MB2:  {type: sum, in: [MC, MD], unit: N*m}
  acc2: {type: gain, in: MB2, k: 1/J2}
  w2:   {type: integrator, in: acc2, unit: rad/s}
"""
NOMINAL = {"J1": 0.1912, "J2": 0.3838, "c": 477.2, "d": 0.2406, "Fc": 0.8, "b": 0.02}
WEARING = {0: ("Fc", 0.06), 1: ("Fc", 0.06), 2: ("Fc", 0.06), 3: ("Fc", 0.06), 4: ("c", -0.03), 5: ("c", -0.03)}


def plant(drive: int, day: int, seed: int = 0) -> dict[str, float]:
    """The true parameters of a drive on a day: its own spread around nominal, plus wear."""
    rng = np.random.default_rng([seed, drive])
    values = {k: v * (1 + 0.05 * rng.standard_normal()) for k, v in NOMINAL.items()}
    if drive in WEARING:
        name, per_day = WEARING[drive]
        values[name] *= 1 + per_day * day
    return values


def make_log(args: tuple) -> str:
    """Write one drive-day log (module level: runs in a worker)."""
    path, drive, day, seconds = args
    diagram = diagram_from_text(CHART, "fleet_drive.yaml")
    settings = ExcitationSettings(seconds=seconds, seed=1000 * drive + day, noise_std=0.01)
    write_csv(path, excite(diagram, settings, parameters=plant(drive, day)), "%.10g")
    return path


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=20)
    ap.add_argument("--days", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=2.0, help="log length per file (1 kHz)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, help="directory to keep the fleet, results and report in")
    args = ap.parse_args()
    tmp = None
    if args.keep:
        root = args.keep
        root.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory()
        root = Path(tmp.name)
    try:
        return _run(args, root)
    finally:
        if tmp is not None:
            tmp.cleanup()


def _run(args, root: Path) -> int:
    chart = root / "fleet_drive.yaml"
    chart.write_text(CHART)
    logs = root / "logs"
    logs.mkdir(exist_ok=True)
    jobs = [(str(logs / f"drive{k:02d}_day{day:03d}.csv"), k, day, args.seconds)
            for k in range(args.drives) for day in range(args.days)]
    print(f"cpus {os.cpu_count()}, load average {_load()}")
    t0 = time.perf_counter()
    with make_executor(args.workers) as ex:
        list(ex.map(make_log, [j for j in jobs if not os.path.exists(j[0])]))
    print(f"made {len(jobs)} logs of {args.seconds:g} s in {time.perf_counter() - t0:.1f} s")

    results = root / "results.csv"
    if results.exists():
        results.unlink()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-m", "flowchart2sdnn.cli", "batch", str(chart), str(logs / "*.csv"), "-o", str(results),
           "--workers", str(args.workers), "--quiet"]
    print(f"load average before batch {_load()}")
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env)
    wall = time.perf_counter() - t0
    print(f"batch: {len(jobs)} files in {wall:.1f} s wall = {len(jobs) / wall:.2f} files/s "
          f"({args.workers} workers, process start-up included); load average after {_load()}")
    with open(results) as handle:
        rows = list(csv.DictReader(handle))
    seconds = np.array([float(r["seconds"]) for r in rows if r["seconds"]])
    failed = [r["file"] for r in rows if r["status"] == "error"]
    print(f"per file in the worker: median {np.median(seconds):.2f} s, max {seconds.max():.2f} s; "
          f"{len(failed)} failed")

    report = root / "report"
    out = subprocess.run([sys.executable, "-m", "flowchart2sdnn.cli", "report", str(results), "-o", str(report)],
                         check=True, env=env, capture_output=True, text=True)
    print(out.stdout.strip())
    with open(report / "drift.csv") as handle:
        drift = list(csv.DictReader(handle))
    found = {(r["drive"], r["parameter"]) for r in drift if r["drift"]}
    truth = {(f"drive{k:02d}", name) for k, (name, _) in WEARING.items() if k < args.drives}
    print(f"drift found {len(found & truth)}/{len(truth)}, false alarms {sorted(found - truth)}, "
          f"missed {sorted(truth - found)}")
    for r in drift:
        if (r["drive"], r["parameter"]) in truth:
            k = int(r["drive"][5:])
            name, per_day = WEARING[k]
            true_slope = per_day * plant(k, 0)[name]
            print(f"  {r['drive']} {name}: slope {float(r['slope_per_day']):.4g}/day (true {true_slope:.4g}), "
                  f"change {float(r['change_percent']):+.1f} %")
    return 0 if found == truth and not failed else 1


if __name__ == "__main__":
    raise SystemExit(main())
