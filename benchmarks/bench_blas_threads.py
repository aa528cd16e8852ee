"""BLAS threads on our matrix sizes: the library's default (one thread, flowchart2sdnn/threads.py) against
OpenBLAS's own thread count, in the same run, on an idle machine and with a second process keeping one core busy
(a test suite, another fit, ``--workers``).

Sizes: JᵀJ of a 30 s two-mass record (60 000 rows x 60 quantities; 2·M·P² = 0.43 GFLOP) and the Cholesky
factorisation of a multiple-shooting normal matrix (774 x 774; n³/3 = 0.15 GFLOP), as measured in an
`identify` of the two-mass user chart. Prints the median of 15 calls each, GFLOP/s and the ratio.

Run: ``python benchmarks/bench_blas_threads.py`` (do not set OPENBLAS_NUM_THREADS).
"""

from __future__ import annotations

import multiprocessing
import os
import statistics
import time

import numpy as np
from scipy.linalg import cho_factor
from threadpoolctl import threadpool_info, threadpool_limits


def _busy(stop):
    x = 0
    while not stop.is_set():
        x += 1


def _median(fn, reps=15) -> float:
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    if any(os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
        raise SystemExit("unset OPENBLAS_NUM_THREADS / OMP_NUM_THREADS / MKL_NUM_THREADS: this compares thread counts")
    rng = np.random.default_rng(0)
    J = rng.standard_normal((60_000, 60))
    M = rng.standard_normal((2000, 774))
    A = M.T @ M + np.eye(774)
    cases = {"J^T J 60000x60": (lambda: J.T @ J, 2 * 60_000 * 60**2),
             "Cholesky 774": (lambda: cho_factor(A, check_finite=False), 774**3 / 3)}
    own = max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")
    print(f"cores {os.cpu_count()}, OpenBLAS threads by default {own}")
    print(f"{'case':18s} {'machine':9s} {'default ms':>10s} {'one ms':>8s} {'GFLOP/s one':>11s} {'default/one':>11s}")
    for machine in ("idle", "one busy"):
        stop = multiprocessing.Event()
        hog = None
        if machine == "one busy":
            hog = multiprocessing.Process(target=_busy, args=(stop,))
            hog.start()
            time.sleep(0.5)
        try:
            for name, (fn, flops) in cases.items():
                fn()
                default = _median(fn)
                with threadpool_limits(limits=1, user_api="blas"):
                    one = _median(fn)
                print(f"{name:18s} {machine:9s} {1e3 * default:10.2f} {1e3 * one:8.2f} {flops / one / 1e9:11.2f} "
                      f"{default / one:11.2f}")
        finally:
            if hog is not None:
                stop.set()
                hog.join()


if __name__ == "__main__":
    main()
