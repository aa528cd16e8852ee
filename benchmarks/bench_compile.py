"""Compile time of generated chains of coupled masses (two-mass style), for issue 2's benchmark.

Mass i (inertia J_i, friction-free) is coupled to mass i+1 by a spring c_i and a damper d_i, mass 1 is driven by
the torque M1, the last speed is the output. Run: ``python benchmarks/bench_compile.py [N ...]``.
"""

from __future__ import annotations

import sys
import time

from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import diagram_from_text

__all__ = ["chain_chart"]


def chain_chart(n: int) -> str:
    """YAML text of a chain of `n` coupled masses (n >= 2)."""
    lines = ["sdnn: 1", f"name: chain{n}", "sample_time: 0.001", "inputs:", "  M1: {unit: N*m}",
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


def _time_compile(n: int, repeat: int = 3) -> tuple[float, float, int]:
    text = chain_chart(n)
    best_total = best_compile = float("inf")
    layers = 0
    for _ in range(repeat):
        t0 = time.perf_counter()
        diagram = diagram_from_text(text, f"chain{n}.yaml")
        t1 = time.perf_counter()
        net = compile_diagram(diagram).network
        t2 = time.perf_counter()
        best_total = min(best_total, t2 - t0)
        best_compile = min(best_compile, t2 - t1)
        layers = len(net.layers)
    return best_total, best_compile, layers


def main(sizes: list[int]) -> int:
    print(f"{'masses':>7} {'layers':>7} {'load+compile s':>15} {'compile s':>10} {'growth':>8}")
    previous = None
    results = {}
    for n in sizes:
        total, comp, layers = _time_compile(n, repeat=3 if n <= 100 else 1)
        growth = f"{total / previous:8.1f}" if previous else f"{'':>8}"
        print(f"{n:>7} {layers:>7} {total:>15.3f} {comp:>10.3f} {growth}")
        previous = total
        results[n] = total
    if 1000 in results:
        ok = results[1000] < 2.0
        print(f"1000 masses: {results[1000]:.3f} s ({'under' if ok else 'OVER'} the 2 s budget)")
        return 0 if ok else 1
    return 0


if __name__ == "__main__":
    sys.exit(main([int(a) for a in sys.argv[1:]] or [10, 100, 1000]))
