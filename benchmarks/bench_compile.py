"""Compile time of generated chains of coupled masses (two-mass style), for issue 2's benchmark.

Mass i (inertia J_i, friction-free) is coupled to mass i+1 by a spring c_i and a damper d_i, mass 1 is driven by
the torque M1, the last speed is the output. Run: ``python benchmarks/bench_compile.py [N ...]``.

The passes are timed at one step per sample (`substeps: 1` in the chart): a chart without the key gets
`substeps: auto`, whose eigenvalue analysis of the network (dense, O(n^3) in the neurons, twice) is timed apart
in the last column, for chains of up to AUTO_UP_TO masses.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from flowchart2sdnn.compiler import compile_diagram, compile_file
from flowchart2sdnn.diagram.validate import load_diagram

__all__ = ["chain_chart"]


def chain_chart(n: int) -> str:
    """YAML text of a chain of `n` coupled masses (n >= 2)."""
    lines = ["sdnn: 1", f"name: chain{n}", "sample_time: 0.001", "substeps: 1", "inputs:", "  M1: {unit: N*m}",
             "outputs:", f"  w{n}: {{unit: rad/s}}", "parameters:"]
    for i in range(1, n + 1):
        lines.append(f"  J{i}: {{init: 0.2, unit: kg*m^2, min: 0}}")
    for i in range(1, n):
        lines.append(f"  c{i}: {{init: 400, unit: N*m/rad, min: 0}}")
        lines.append(f"  d{i}: {{init: 0.3, unit: N*m*s/rad, min: 0}}")
    lines.append("blocks:")
    for i in range(1, n + 1):
        terms = ["M1"] if i == 1 else [f"MC{i - 1}", f"MD{i - 1}"]
        if i < n:
            terms += [f"-MC{i}", f"-MD{i}"]
        lines.append(f"  MB{i}: {{type: sum, in: [{', '.join(terms)}], unit: N*m}}")
        lines.append(f"  acc{i}: {{type: gain, in: MB{i}, k: 1/J{i}}}")
        lines.append(f"  w{i}: {{type: integrator, in: acc{i}, unit: rad/s}}")
    for i in range(1, n):
        lines.append(f"  dw{i}: {{type: sum, in: [w{i}, -w{i + 1}]}}")
        lines.append(f"  dphi{i}: {{type: integrator, in: dw{i}, unit: rad}}")
        lines.append(f"  MC{i}: {{type: gain, in: dphi{i}, k: c{i}}}")
        lines.append(f"  MD{i}: {{type: gain, in: dw{i}, k: d{i}}}")
    return "\n".join(lines) + "\n"


#: the auto column is measured up to this size (1000 masses: about a minute of CPU)
AUTO_UP_TO = 300


def _best(func, repeat: int) -> tuple[float, float, object]:
    """Best wall and CPU seconds of `repeat` calls (CPU time is the fairer number on a shared machine)."""
    wall = cpu = float("inf")
    result = None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        result = func()
        wall, cpu = min(wall, time.perf_counter() - w0), min(cpu, time.process_time() - c0)
    return wall, cpu, result


def main(sizes: list[int]) -> int:
    print(f"{'masses':>7} {'layers':>7} {'compile s':>10} {'(cpu s)':>8} {'file->net s':>12} {'(cpu s)':>8} "
          f"{'growth':>7} {'auto N':>7} {'auto cpu s':>10}")
    previous = None
    cpu_of: dict[int, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = Path(tmp) / f"chain{n}.yaml"
            path.write_text(chain_chart(n), encoding="utf-8")
            repeat = 3 if n <= 100 else 2
            diagram = load_diagram(path)
            wall, cpu, comp = _best(lambda d=diagram: compile_diagram(d), repeat)
            fwall, fcpu, _ = _best(lambda p=path: compile_file(p), repeat)
            growth = f"{fcpu / previous:7.1f}" if previous else f"{'':>7}"
            auto = ""
            if n <= AUTO_UP_TO:
                _, acpu, acomp = _best(lambda d=diagram: compile_diagram(d, substeps="auto"), 1)
                auto = f" {acomp.network.substeps:>7} {acpu:>10.3f}"
            print(f"{n:>7} {len(comp.network.layers):>7} {wall:>10.3f} {cpu:>8.3f} {fwall:>12.3f} {fcpu:>8.3f} {growth}"
                  + auto)
            previous = fcpu
            cpu_of[n] = fcpu
    print("compile: chart IR -> network (lint, loops, discretize, emit); file->net: sdnn compile's work "
          "(read, validate, compile), both at substeps: 1; growth: CPU time ratio to the previous size; auto: "
          "the same chart at substeps: auto (without the key), the N it chose and its compile CPU time")
    if 1000 in cpu_of:
        ok = cpu_of[1000] < 2.0
        print(f"1000 masses, file -> network: {cpu_of[1000]:.3f} CPU s ({'under' if ok else 'OVER'} the 2 s budget)")
        return 0 if ok else 1
    return 0


if __name__ == "__main__":
    sys.exit(main([int(a) for a in sys.argv[1:]] or [10, 100, 1000]))
