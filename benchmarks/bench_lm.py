"""Offline LM on the two-mass network at Q = 25 000: time per iteration (target <= 20 ms) against scipy.

Ours: fit/lm.py with the RTRL Jacobian of CompiledNetwork.jacobian (numba) and, for trial steps, the
residual-only CompiledNetwork.simulate. Baseline, measured in the same run on the same problem (data, start,
bounds): scipy.optimize.least_squares (method "trf", bounds, 2-point finite-difference Jacobian, every column
a simulation of the same numba kernel). Both run a fixed number of iterations; the table gives the time per
iteration, the ratio and the final cost.

Problem: diagrams/two_mass.yaml on the paper's network (tests/data/two_mass_euler.yaml, N = 1; 15 free quantities: J2, c, d and the 12 friction weights of both machines)
on 25 s of diagrams/two_mass_plant.yaml (w2 measured), excited as in section 6.1 (seed 1); start J2 = 0.45,
c = 450, d = 0.25 and the compiled friction weights; J2, c, d >= 0; our mu0 = 100 (from mu0 = 1e-3 the first
steps send the friction weights where the Euler-discretised friction loop chatters and the Jacobian overflows).
Times are wall clock and process CPU time (on a shared machine the CPU time is the fairer number).

Flop count of one of our iterations (P, N, C, C_n, D as in bench_online.py; Q samples; t trial simulations):
    RTRL Jacobian    Q (2 P C_n + 2 D + P N + 2 C)
    J^T J, J^T e     2 Q P^2 + 2 Q P
    damped solve     P^3 / 3 + 2 P^2                      (per trial)
    trials           t * 2 Q C
Run: ``python benchmarks/bench_lm.py`` (about a minute).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see benchmarks/README.md: BLAS threads thrash on a shared machine

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.compiler import compile_file  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt  # noqa: E402
from flowchart2sdnn.network.runtime import CompiledNetwork  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iterations", type=int, default=20)
    args = ap.parse_args()
    q = 25000
    data = excite(load_diagram(ROOT / "diagrams/two_mass_plant.yaml"), ExcitationSettings(seconds=q / 1000, seed=1))
    u, y = data["M1"][:, None], data["w2"]
    cn = CompiledNetwork(compile_file(ROOT / "tests/data/two_mass_euler.yaml").network)
    x0 = cn.theta0()
    x0[:3] = [0.45, 450.0, 0.25]
    lower = np.array([0.0, 0.0, 0.0] + [-np.inf] * (cn.n_theta - 3))

    def fun(x):
        yhat, dy = cn.jacobian(x, u)
        return y - yhat[:, 0], dy[:, 0, :]

    def residual(x):
        return y - cn.simulate(x, u)[:, 0]

    fun(x0)  # JIT warm-up of both kernels
    residual(x0)
    t0, c0 = time.perf_counter(), time.process_time()
    ours = levenberg_marquardt(fun, x0, cn.names, lower=lower, residual=residual,
                               options=LMOptions(max_iter=args.iterations, mu0=100.0))
    t_ours, c_ours = time.perf_counter() - t0, time.process_time() - c0
    it_ours = max(ours.iterations, 1)
    n_trials = ours.nfev - ours.njev  # residual-only evaluations

    t0, c0 = time.perf_counter(), time.process_time()
    base = least_squares(residual, x0, bounds=(lower, np.full(cn.n_theta, np.inf)), method="trf",
                         jac="2-point", max_nfev=args.iterations + 1, x_scale="jac")
    t_base, c_base = time.perf_counter() - t0, time.process_time() - c0
    it_base = max(base.njev, 1)

    f = cn._flat
    p, n, c = cn.n_theta, f.n_neurons, f.n_connections
    c_n, d = int((f.conn_kind == 0).sum()), cn.weights.n_slots
    flops_jac = q * (2 * p * c_n + 2 * d + p * n + 2 * c)
    flops = ours.njev * (flops_jac + 2 * q * p * p + 2 * q * p) + n_trials * (2 * q * c + p**3 / 3 + 2 * p * p)

    print(f"\noffline LM, two-mass network (P = {p}), Q = {q}")
    print(f"{'method':<44}{'iter':>5}{'wall ms/it':>11}{'CPU ms/it':>10}{'final cost':>13}{'GFLOP/s':>9}")
    print(f"{'ours: fit/lm.py + RTRL (numba)':<44}{ours.iterations:>5}{1e3 * t_ours / it_ours:>11.1f}"
          f"{1e3 * c_ours / it_ours:>10.1f}{ours.cost:>13.5g}{flops / c_ours / 1e9:>9.3f}")
    print(f"{'scipy least_squares trf, 2-point FD Jacobian':<44}{base.njev:>5}{1e3 * t_base / it_base:>11.1f}"
          f"{1e3 * c_base / it_base:>10.1f}{0.5 * base.fun @ base.fun:>13.5g}{'':>9}")
    print(f"ratio (baseline time per iteration / ours): wall {(t_base / it_base) / (t_ours / it_ours):.1f}x,"
          f" CPU {(c_base / it_base) / (c_ours / it_ours):.1f}x; target for ours: <= 20 ms per iteration"
          f" (GFLOP/s against CPU time)")
    print(f"ours: {ours.njev} Jacobians, {n_trials} residual-only trials, status {ours.status};"
          f" flop count {flops / 1e6:.1f} MFLOP ({flops_jac / 1e6:.1f} MFLOP per Jacobian)")
    print(f"start cost {ours.cost_history[0]:.5g}; J2, c, d: ours {np.round(ours.x[:3], 4)},"
          f" baseline {np.round(base.x[:3], 4)} (truth 0.3838, 477.2, 0.2406)")


if __name__ == "__main__":
    main()
