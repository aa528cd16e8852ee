"""Cascaded Tanks, one change at a time: what the plain Torricelli chart needs to approach the published 0.191 V.

The hand-written best physical chart (diagrams/real/cascaded_tanks_physical.yaml) holds every change; a change is
switched off by fixing its parameters at their neutral values (an overflow level far above the data, a share,
an offset or a linear coefficient at 0) or, for the input dead time, by reading the input undelayed. Each row is
identified on estimation.csv from the chart's `init` (4 starts) and scored by the benchmark's protocol: test RMSE
on validation.csv from sample 5, both levels' start fitted on its first 5 samples (`--init-window 5`).
Two tables: the changes added one by one to the plain chart, and each change removed alone from the full chart.
The first also holds the plain chart with diagnose's `sensor_limit` patch at y_V (its lower level keeps its start
from the data, `measured_by`; limits from the sensor's 0..10 V range): the 10 V clip on its own.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/cascaded_tanks_ablation.py`` (about 3 min).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

from flowchart2sdnn.api import identify, load_chart, read_csv
from flowchart2sdnn.diagnose.effects import SensorLimit
from flowchart2sdnn.diagnose.graph import Place
from flowchart2sdnn.expr import parse_expr

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "cascaded_tanks"
FAR = 1000.0  # an overflow level or sensor limit the data never reach

#: change -> the parameters that switch it off, at their neutral values ("dead_time" is a block, see without)
CHANGES = {
    "upper overflow (excess lost)": {"L1": FAR},
    "share of it into the lower tank": {"g1": 0.0},
    "sensor limit 10 V": {"ymax": FAR},
    "sensor zero offset": {"off": 0.0},
    "lower overflow": {"L2": FAR},
    "linear outflow terms": {"k1l": 0.0, "k3l": 0.0},
    "pump zero offset": {"c0": 0.0},
    "input dead time 1 sample": {},
}


def without(chart, changes, start=None):
    """The chart with `changes` switched off; the other parameters start at `start` (name -> value) if given."""
    fixed = {k: v for c in changes for k, v in CHANGES[c].items()}
    if "upper overflow (excess lost)" in changes:
        fixed["g1"] = 0.0
    start = start or {}
    params = tuple(replace(p, init=fixed[p.name], fixed=True, min=None, max=None) if p.name in fixed
                   else replace(p, init=start.get(p.name, p.init)) for p in chart.parameters)
    blocks = tuple(replace(b, kind="gain", k=parse_expr("1"), n=None)
                   if b.name == "u_late" and "input dead time 1 sample" in changes else b for b in chart.blocks)
    return replace(chart, parameters=params, blocks=blocks, source_sha256=None)


def sensor_limited(chart):
    """`chart` with diagnose's sensor_limit at y_V, clip o -/+ L from the sensor's range 0..10 V (o = L = 5)."""
    patched = SensorLimit().patch(chart, Place("y_V", "output"), 5.0)
    params = tuple(replace(p, init=5.0) if p.name == "y_V_off" else p for p in patched.parameters)
    return replace(patched, parameters=params)


def score(chart, train, test) -> tuple[float, float, float, dict]:
    """Estimation and test RMSE, seconds, and the fitted parameters."""
    t0 = time.perf_counter()
    result = identify(chart, train, test, init_window=5, starts=4, seed=0)
    fit = json.loads(result.to_json())["fit"]
    values = {n: e.value for n, e in result.parameters.items()}
    return fit["train"]["rms"]["y_V"], fit["validation"]["rms"]["y_V"], time.perf_counter() - t0, values


def main() -> None:
    if not (DATA / "estimation.csv").exists():
        sys.exit(f"{DATA} is absent")
    train, test = read_csv(DATA / "estimation.csv"), read_csv(DATA / "validation.csv")
    full = load_chart(ROOT / "diagrams" / "real" / "cascaded_tanks_physical.yaml")
    names = list(CHANGES)
    print("| chart | estimation RMSE (V) | test RMSE (V) | fit (s) |\n|---|---|---|---|")
    plain = load_chart(ROOT / "diagrams" / "real" / "cascaded_tanks.yaml")
    tr, te, s, _ = score(plain, train, test)
    print(f"| plain Torricelli (diagrams/real/cascaded_tanks.yaml) | {tr:.3f} | {te:.3f} | {s:.0f} |")
    tr, te, s, _ = score(sensor_limited(plain), train, test)
    print(f"| plain + diagnose's sensor_limit at y_V (start from the data) | {tr:.3f} | {te:.3f} | {s:.0f} |")
    # each row starts from the previous row's fit (the new change's parameters from the chart's init), as
    # diagnose refits from the current fit: from the chart's init alone some rows stop in a worse minimum
    warm: dict = {}
    for i in range(len(names) + 1):
        cold = score(without(full, names[i:]), train, test)
        hot = score(without(full, names[i:], warm), train, test) if warm else cold
        tr, te, s, values = min(cold, hot, key=lambda r: r[0])  # the lower estimation RMSE: test unseen
        warm = {k: v for k, v in values.items() if not any(k in CHANGES[c] for c in names[i:])}
        label = "physical chart, all changes off" if i == 0 else "+ " + names[i - 1]
        print(f"| {label} | {tr:.3f} | {te:.3f} | {s:.0f} |")
    substeps = replace(full, substeps=8)  # the spills' K stays 1/s: a softer stop at h = 0.5 s, still stable
    tr, te, s, _ = score(substeps, train, test)
    print(f"| all, substeps 8 (h = 0.5 s) | {tr:.3f} | {te:.3f} | {s:.0f} |")
    print("\n| removed from the full chart | estimation RMSE (V) | test RMSE (V) | fit (s) |\n|---|---|---|---|")
    for name in names:
        tr, te, s, _ = score(without(full, [name]), train, test)
        print(f"| {name} | {tr:.3f} | {te:.3f} | {s:.0f} |")


if __name__ == "__main__":
    main()
