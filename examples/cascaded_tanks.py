"""Cascaded Tanks benchmark: the plain two-tank Torricelli chart identified on the estimation record, its
simulation RMSE on the validation record from sample 5 (the benchmark's protocol, SOURCE.md).

The data are read in place from ../shared/data/real/cascaded_tanks (never copied into the repository).
Initial state of the validation record (sdnn has no initial-state window option yet): the lower level starts
at the first measured sample (`init: data`); the upper level x10 is fitted on the first 5 validation samples with
every other parameter fixed at its identified value (the protocol allows the first 5 outputs for this).
Run: PYTHONPATH=. python examples/cascaded_tanks.py [--starts N]
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "cascaded_tanks"
CHART = ROOT / "diagrams" / "real" / "cascaded_tanks.yaml"
WINDOW = 5  # the protocol's initial-state window and the first scored sample


def rmse_from(chart, record, first: int = WINDOW) -> float:
    y = chart_simulation(chart, record)
    measured = record.columns["y_V"]
    return float(math.sqrt(np.mean((y[first:] - measured[first:]) ** 2)))


def chart_simulation(chart, record) -> np.ndarray:
    from flowchart2sdnn.compiler import compile_diagram
    from flowchart2sdnn.network.alignment import run_aligned
    from flowchart2sdnn.network.runtime import CompiledNetwork

    cn = CompiledNetwork(compile_diagram(chart).network)
    u = record.columns["u_V"][:, None]
    return run_aligned(cn, cn.theta0(), u, "zoh", {"y_V": float(record.columns["y_V"][0])})[:, 0]


def validation_start(chart, record) -> tuple[float, object]:
    """x10 fitted on the first WINDOW samples of `record`, every other parameter fixed."""
    params = tuple(replace(p, fixed=p.name != "x10") for p in chart.parameters)
    windowed = replace(chart, parameters=params)
    result = sd.identify(windowed, record.slice(0, WINDOW), max_iter=200, starts=8, seed=1)
    return result.parameters["x10"].value, result.chart


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--starts", type=int, default=8)
    parser.add_argument("--substeps", type=int, default=None)
    args = parser.parse_args()
    chart = sd.load_chart(CHART)
    if args.substeps:
        chart = replace(chart, substeps=args.substeps)
    train = sd.read_csv(DATA / "estimation.csv")
    test = sd.read_csv(DATA / "validation.csv")
    result = sd.identify(chart, train, starts=args.starts, seed=0)
    print(result.status, {n: round(e.value, 6) for n, e in result.parameters.items()})
    for w in result.warnings:
        print("warning:", w)
    fitted = result.chart
    print(f"estimation RMSE from sample {WINDOW}: {rmse_from(fitted, train):.4f} V")
    x10, tested = validation_start(fitted, test)
    print(f"validation: x10 = {x10:.4f} V from the first {WINDOW} samples; "
          f"test RMSE from sample {WINDOW}: {rmse_from(tested, test):.4f} V")
    same = rmse_from(fitted, test)
    print(f"(with the estimation record's x10 instead: {same:.4f} V)")
    # the upper tank at rest at the start: k1 sqrt(x10) = k3 sqrt(y0) (the record starts nearly flat)
    k = {p.name: p.init for p in fitted.parameters}
    rest = (k["k3"] / k["k1"]) ** 2 * float(test.columns["y_V"][0])
    at_rest = replace(fitted, parameters=tuple(replace(p, init=rest) if p.name == "x10" else p
                                               for p in fitted.parameters))
    print(f"(with the upper tank at rest at the start, x10 = {rest:.4f} V: {rmse_from(at_rest, test):.4f} V)")


if __name__ == "__main__":
    main()
