"""The cost of one LM iteration with multiple shooting against one with single shooting (issue 14's speed item).

Bench: diagrams/two_mass_coulomb.yaml (its `init`, 20 % off the truth; `substeps: auto`, `delays: torques`) on
a record of its own plant from `sdnn excite` (continuous RK4, seed 1, 0.01 rad/s noise) of ``--seconds`` (25 s:
Q = 25 000 samples, the issue's size). Both fits are identify's default LM (``lm_options``) on the same
problem, run for ``--iterations`` iterations from the chart's `init` with the convergence tests off, so both do
the same kind of work: one residual and Jacobian (RTRL) per accepted step, one residual per trial, the damped
normal equations. Single shooting is `Problem.fun`; multiple shooting is the first stage of
identify.shooting.multiple (`Segmented`, continuity weight 1) at each ``--length`` L, its segments on one thread and on
``--threads``. Printed: seconds per iteration and the ratio to single shooting, measured in the same run (the
issue asks for at most 1.5 at Q = 25 000), and the seconds of one Jacobian and two residuals (an iteration's
simulation work without its count of rejected trials, which differs between the runs).

Measured 27 Nov 2026 (idle, N = 7, Nielsen's damping: both runs 11 residuals in 5 iterations), each record's
segments in one kernel call: L = 100 1.28x (work 1.20x; 2 threads 0.99x), L = 500 1.23x (1.09x; 0.92x),
L = 2500 1.24x (1.11x; 0.86x); one kernel call per segment before (load 6): L = 100 1.61x, L = 500 1.55x.
With the bounds in the box and a trust radius (identify's default on this chart since 27 Nov, fit.lm's "trust"
damping; loaded machine, --repeat 1, the trust radius's mu by eigen-decomposition then): L = 100 1.26x (work
1.24x; 2 threads 1.08x), L = 500 1.08x (1.10x; 1.00x), L = 2500 1.88x (1.23x; 1.44x): at L = 2500 the segmented
fit refused 3 trials in 5 iterations where single shooting refused none (9 Jacobians and 3 residuals against 7
and 1; a refused first trial is simulated with its Jacobian), so its per-iteration ratio counts them; the work
ratio does not. Again 27 Nov (merged, loaded, --repeat 3): L = 100 1.08x, L = 500 1.08x, L = 2500 1.82x (work 1.27x,
1.20x, 1.54x); with --iterations 20 (both stop on their own: single shooting after 12 iterations, 17 Jacobians and
16 residuals; L = 2500 after 17) L = 2500 1.21-1.34x (work 1.09-1.14x), L = 100 2.6x (6 iterations, 14 refused
trials).

Why the segmented fits refused more trials (per-trial traces, 27 Nov, the branch shootiter): before the fits
converge, L = 100 and L = 500 refuse no trial and single shooting one; L = 2500 refuses 5 (3 within 5 iterations).
Its first two steps have poor gain ratios (0.43, 0.28) and triple the shaft damping d; coming back, each good gain
ratio (1.1-1.3) doubles the radius, the doubled step drives d 66-99.5 % of the way to its bound and is refused, the
radius becomes a quarter of that step, and again. Not the free starts: the first radius computed from theta alone,
or one column scale shared by all free starts, give the same trace; the continuity weight is constant within a
stage (and 1 here); a radius grown 1.5x instead of 2x refuses 3 instead of 5 but changes single shooting's path too
(not kept). After converging (convergence tests off) both runs refused trial after trial whose cost changed by
rounding only (L = 100: 14 after 5 iterations), the first of each with its Jacobian: the 2.6x. Fixed in fit.lm,
with the same iterates: a trust-radius fit stops as converged when the Gauss-Newton step fits the radius (or a
trial follows a refusal) and predicts a decrease below 1e-12 of the cost (COST_ROUNDING); a trial more than 1.5x
the last accepted step (LONG_STEP: the doubled radius) is simulated without its Jacobian (6 of 9 such trials were
refused), a trial after a refusal (a quarter of the refused step: 5 of 5 accepted) with it; JᵀJ of a CSR Jacobian
takes its wide columns by BLAS (4.8 ms against 8.3 at 250 segments). Then (four runs, load 3.5-6, --repeat 3; one
thread, in brackets 2 threads, slower than one on a machine that busy): --iterations 5: single shooting 6 Jacobians
and 1 residual; L = 100 1.27-1.38x (6 Jacobians, no residual; 1.32-1.61x); L = 500 1.29-1.34x (6 and 2;
1.31-1.55x); L = 2500 1.36-1.43x (6 and 4; 1.47-1.56x). --iterations 20 (every run converges on its own: single
shooting after 10 iterations, 11 Jacobians, 1 residual): L = 100 1.46-1.58x (1.46, 1.49, 1.48, 1.58: at the edge; 5
iterations, 6 Jacobians and no residual, so the start's Jacobian weighs twice as much per iteration as in single
shooting's 10, and each Jacobian costs 1.2x: the free start's sensitivity column, the CSR products; 1.51-1.59x); L
= 500 1.28-1.40x (9 iterations, 10 and 2; 1.40-1.50x); L = 2500 1.34-1.38x (13 iterations, 14 and 8; 1.40-1.80x).
The work of an iteration (one Jacobian, two residuals): 1.18-1.30x at L = 100, 1.06-1.16x at L = 500 and 2500.

The rough-start bench (bench_rough_init.py, coulomb, 30 s, draws 0-7) takes the same iterates and ends at the same
minima (costs equal to 7 digits; one fewer iteration on 6 draws: the rounding stop) with 143 Jacobian and 59
residual simulations against 165 and 29 before (166 Jacobian-equivalents against 176, a residual costing 0.39 of a
Jacobian); timed, draw by draw alternating with the code before (one process per draw and tree, load 3.5-4): 0.91x
trf's seconds per draw (0.50-1.55) against 0.98x (0.74-1.52), a lower ratio on 7 of 8 draws (draw 6: 5.8 s in both),
sums of seconds 0.95x and 1.12x trf's.

Profiled 27 Nov (the branch shoot2; L = 100, --iterations 20, one thread, per iteration of 6 Jacobians in 5): the
kernels 44.3 ms (a segmented Jacobian's kernel costs 1.04-1.09x single shooting's: the free start's ninth
sensitivity column pads the rows from 8 to 12 lanes), writing e and J's values segment by segment in Python 7.0 ms,
JᵀJ 8.1 ms (6.7 a call: scipy's column slicing 2.5 ms and a count of every column's nonzeros 0.7 ms besides the
products), the column scale's loop over 257 groups 1.2 ms; single shooting spends 4.6 ms an iteration outside its
kernels. Fixed, with the same iterates (x, costs and radii bitwise equal at L = 100, 500, 2500, 5 and 20
iterations, 1 and 2 threads): the CSR pattern's places are built once per stage (runs of like segments copied by
one strided copy each, index arrays for the continuity rows), theta's columns written dense beside it and the
other columns as their own CSR for the trainer (fit.lm.WideFirstCSR), so JᵀJ takes no slicing (2.0 ms a call);
the histories built once per chunk; the column scale's groups by one pass; a dense J (L = 2500) written in place
instead of CSR then toarray (2.4-3.2 ms a call). Then: fun's own work 4.8 ms an iteration (in the fit: cache
misses and ~200 page faults a call on its fresh arrays; 1.3 ms a call outside it), JᵀJ 2.5, the column scale 0.3;
58.6 against 65.6 ms an iteration. What remains is the count of Jacobians (6 in 5 iterations against 11 in 10), the
kernels' ninth column, and the dense normal equations of 257 quantities (Cholesky factorizations, 2 ms an iteration).
The segments' first call is now outside the timings (as single shooting's), which matters with --repeat 1 only.
Measured (three rounds alternating with the code before in the same session, --repeat 2, one thread, load 1.4-1.9,
another job on one of the 2 cores): --iterations 20: L = 100 1.28-1.31x (before 1.45-1.47x), L = 500 1.18-1.19x
(1.30-1.35x), L = 2500 1.32-1.35x (1.33-1.37x); --iterations 5: L = 100 1.11-1.16x (1.23-1.32x), L = 500 1.17-1.18x
(1.26-1.31x), L = 2500 1.36-1.37x (1.38-1.43x); the work of an iteration (one Jacobian, two residuals) 1.06-1.09x at
every L (before 1.18-1.20x at L = 100). Two threads (one run): --iterations 20 1.23x, 1.16x, 1.35x; --iterations 5
1.07x, 1.17x, 1.44x (one thread in that run 1.11x, 1.17x, 1.41x). L = 2500 stays highest: its fits refuse more
trials (14 Jacobians and 8 residuals in 13 iterations against 11 and 1 in 10; with 5 iterations 6 and 4 against 6
and 1), and its Jacobian is dense, 17 columns against 8, in every product of the trainer.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_shooting_iteration.py [--seconds 25] [--length 100 --length
500 --length 2500] [--iterations 5] [--repeat 3] [--threads 2]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.api import dataset_from_frame  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.fit.lm import levenberg_marquardt  # noqa: E402
from flowchart2sdnn.identify.offline.optimize import lm_options  # noqa: E402
from flowchart2sdnn.identify.offline.problem import build_problem  # noqa: E402
from flowchart2sdnn.identify.settings import IdentifySettings  # noqa: E402
from flowchart2sdnn.identify.shooting.multiple import _state_scale  # noqa: E402
from flowchart2sdnn.identify.shooting.segmented import Segmented  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402


def per_iteration(fun, residual, x0, names, lo, hi, options, repeat: int) -> tuple[float, str]:
    """The best over `repeat` runs of seconds per LM iteration, and a run's counts."""
    best, counts = np.inf, ""
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = levenberg_marquardt(fun, x0, names, lo, hi, options, residual=residual)
        wall = time.perf_counter() - t0
        best = min(best, wall / max(1, r.iterations))
        counts = f"{r.iterations} iterations, {r.njev} Jacobians, {r.nfev - r.njev} residuals"
    return best, counts


def per_evaluation(fun, residual, x, repeat: int) -> float:
    """Seconds of one Jacobian and two residuals (a trial step and its geodesic correction): an iteration's
    work without the count of rejected trials, which differs between the runs (best of `repeat`)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fun(x)
        residual(x)
        residual(x)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=25.0)
    ap.add_argument("--length", type=int, action="append", help="segment lengths L (default 100, 500, 2500)")
    ap.add_argument("--iterations", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2, help="also run the segments on this many threads")
    args = ap.parse_args()
    lengths = args.length or [100, 500, 2500]

    plant = load_diagram(ROOT / "diagrams" / "two_mass_coulomb_plant.yaml")
    chart = load_diagram(ROOT / "diagrams" / "two_mass_coulomb.yaml")
    frame = excite(plant, ExcitationSettings(seconds=args.seconds, seed=1, noise_std=0.01))
    data = dataset_from_frame(frame, time="time", inputs=list(plant.input_names), outputs=list(plant.output_names))
    problem = build_problem(chart, data, seed=1)
    theta0 = problem.compiled.theta0()
    lo, hi = problem.bounds()
    # no convergence test may end a run early: each must do `iterations` iterations
    options = dataclasses.replace(lm_options(IdentifySettings(seed=1), problem), max_iter=args.iterations,
                                  stall_decrease=0.0, min_grad=0.0, min_rel_step=0.0,
                                  min_rel_cost_change=0.0)
    problem.fun(theta0)  # numba compiles once, outside the timings

    q = len(problem.segments[0].inputs)
    print(f"two_mass_coulomb, Q = {q} samples ({problem.compiled.substeps} network steps per sample), "
          f"{args.iterations} LM iterations per run, best of {args.repeat}")
    base, counts = per_iteration(problem.fun, problem.residual, theta0, problem.names, lo, hi, options, args.repeat)
    work = per_evaluation(problem.fun, problem.residual, theta0, 3 * args.repeat)
    print(f"{'single shooting':>32}: {base * 1e3:8.1f} ms per iteration   ratio 1.00   ({counts}); "
          f"Jacobian + 2 residuals {work * 1e3:.1f} ms, ratio 1.00")
    for L, threads in [(L, t) for L in lengths for t in ((1, args.threads) if args.threads > 1 else (1,))]:
        seg = Segmented(problem, L, 1.0, threads=threads)
        seg.scale = _state_scale(problem, theta0, seg.free)
        seg.row_weight = seg.weight * np.sqrt(seg.length) / seg.scale
        x0 = seg.start(theta0)
        free = seg.n_x - seg.n_theta
        opts = dataclasses.replace(options, scale_groups=seg.scale_groups(options.scale_groups))
        seg.fun(x0)  # its pattern, index arrays and kernels' first call outside the timings, as problem.fun's above
        seg.residual(x0)
        t, counts = per_iteration(seg.fun, seg.residual, x0, seg.names,
                               np.concatenate([lo, np.full(free, -np.inf)]),
                               np.concatenate([hi, np.full(free, np.inf)]), opts, args.repeat)
        w = per_evaluation(seg.fun, seg.residual, x0, 3 * args.repeat)
        print(f"{f'L = {L} ({len(seg.pieces)} segments), {threads} thr.':>32}: {t * 1e3:8.1f} ms per iteration   "
              f"ratio {t / base:.2f}   ({counts}); Jacobian + 2 residuals {w * 1e3:.1f} ms, ratio {w / work:.2f}")


if __name__ == "__main__":
    main()
