"""Offline LM on a plain GDNN: ours (fit/lm.py + numba RTRL) against pyrenn 0.1 (pure numpy RTRL), same run.

Network: 1 input with delays {0, 1}, 5 tanh neurons, 1 linear output, output feedback {1, 2}, internal delay
{1}: pyrenn's ``CreateNN([1, 5, 1], dIn=[0, 1], dIntern=[1], dOut=[1, 2])`` and our ``random_gdnn`` default,
57 weights. Both start from the same weights: a seeded uniform [-0.5, 0.5] vector in pyrenn's order, mapped
onto our named free weights (the script checks that both give the same start cost).

Data (Q = 25 000, seed 0): u is an APRBS in [-1, 1] (levels held 5-50 samples, u[0] = 0) and y the output of
the nonlinear second-order system y(t) = 1.5 y(t-1) - 0.7 y(t-2) + 0.25 tanh(2 u(t-1)) - 0.1 y(t-1)^3,
scaled to max |y| = 0.9. Both |u| <= 1 and |y| <= 1, so pyrenn's input/output normalisation is the identity,
and u[0] = 0 makes pyrenn's "zero before t = 0" and our "inputs held at u(0)" the same history.

LM settings are pyrenn's: damping 3.0 at the start, x10 after a failed step, /10 after a success; N
iterations each (pyrenn's pure-Python RTRL takes about 20 s per Jacobian at Q = 25 000, so N = 2 by default).
pyrenn (GPL) is installed only into a throwaway venv under /tmp and run in a subprocess; it is never imported
here. Cost = 1/2 sum e^2 for both (pyrenn reports sum e^2).

Flop count of one Jacobian (P = 57, N = 6 neurons, C = 57 connections, C_n = 41 from neurons, D = 57):
Q (2 P C_n + 2 D + P N + 2 C); one LM iteration adds 2 Q P^2 + 2 Q P (J^T J, J^T e), P^3 / 3 per solve and
2 Q C per trial simulation.
Run: ``python benchmarks/bench_pyrenn.py [--q 25000] [--iterations 2]`` (about two minutes).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see benchmarks/README.md: BLAS threads thrash on a shared machine

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # randomnet: the random GDNN is a test fixture

from randomnet import random_gdnn  # noqa: E402

from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt  # noqa: E402
from flowchart2sdnn.network.runtime import CompiledNetwork  # noqa: E402

VENV = Path("/tmp/sdnn-bench-venv")

# Runs inside the venv: times pyrenn's RTRL and calc_error by wrapping them, then train_LM.
CHILD = r"""
import json, sys, time
import numpy as np
import pyrenn
d = np.load(sys.argv[1])
P, Y, w0, iters = d["P"], d["Y"], d["w0"], int(d["iters"])
net = pyrenn.CreateNN([1, 5, 1], dIn=[0, 1], dIntern=[1], dOut=[1, 2])
net["w0"] = w0.copy()
net["w"] = w0.copy()
calls = {"RTRL": [0, 0.0], "calc_error": [0, 0.0]}
def wrap(name):
    f = getattr(pyrenn, name)
    def g(*a, **k):
        t = time.perf_counter()
        out = f(*a, **k)
        calls[name][0] += 1
        calls[name][1] += time.perf_counter() - t
        return out
    setattr(pyrenn, name, g)
wrap("RTRL")
wrap("calc_error")
data, net = pyrenn.prepare_data(P, Y, net)
E0 = pyrenn.calc_error(net, data)
calls["calc_error"] = [0, 0.0]
t0, c0 = time.perf_counter(), time.process_time()
net = pyrenn.train_LM(P, Y, net, k_max=iters, dampfac=3.0, dampconst=10.0)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
E = pyrenn.calc_error(net, data)
print(json.dumps({"E0": float(E0), "E": float(E), "wall": wall, "cpu": cpu, "calls": calls,
                  "normP": list(map(float, net["normP"])), "normY": list(map(float, net["normY"]))}))
"""


def make_data(q: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    u = np.empty(q)
    k = 0
    while k < q:
        n = int(rng.integers(5, 51))
        u[k:k + n] = rng.uniform(-1.0, 1.0)
        k += n
    u[0] = 0.0
    y = np.zeros(q)
    for t in range(2, q):
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.25 * np.tanh(2.0 * u[t - 1]) - 0.1 * y[t - 1] ** 3
    return u, 0.9 * y / np.abs(y).max()


def pyrenn_names() -> list[str]:
    """Our free-weight names in the order of pyrenn's weight vector (w2Wb: per layer IW, LW, b; matrices
    stored column-major)."""
    names = []
    for d in (0, 1):  # IW[1,1,d], 5 x 1
        names += [f"IW0_0_d{d}[{k}]" for k in range(5)]
    blocks = {1: [(1, (1,)), (2, (1, 2))], 2: [(1, (0,)), (2, (1,))]}  # layer m: (source l, delays)
    size = {1: 5, 2: 1}
    for m in (1, 2):
        for src, delays in blocks[m]:
            for d in delays:
                rows, cols = size[m], size[src]
                names += [f"LW{m - 1}_{src - 1}_d{d}[{r},{c}]" for c in range(cols) for r in range(rows)]
        names += [f"b{m - 1}[{r}]" for r in range(size[m])]
    return names


def ensure_venv() -> str | None:
    py = VENV / "bin" / "python"
    try:
        if not py.exists():
            subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True, capture_output=True, timeout=300)
        ok = subprocess.run([str(py), "-c", "import pyrenn, numpy"], capture_output=True, timeout=60)
        if ok.returncode != 0:
            subprocess.run([str(py), "-m", "pip", "install", "-q", "pyrenn", "numpy"], check=True,
                           capture_output=True, timeout=600)
        return str(py)
    except (subprocess.SubprocessError, OSError) as exc:
        print(f"pyrenn venv could not be made ({exc}); timing ours only")
        return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--q", type=int, default=25000)
    ap.add_argument("--iterations", type=int, default=2)
    args = ap.parse_args()
    q, iters = args.q, args.iterations
    u, y = make_data(q, seed=0)
    w0 = np.random.default_rng(1).uniform(-0.5, 0.5, 57)

    net = random_gdnn(0)
    order = pyrenn_names()
    assert sorted(order) == sorted(f.name for f in net.free_weights) and len(order) == 57
    init = dict(zip(order, w0, strict=True))
    net = dataclasses.replace(net, free_weights=tuple(dataclasses.replace(f, init=float(init[f.name]))
                                                      for f in net.free_weights))
    cn = CompiledNetwork(net)
    U = u[:, None]

    def fun(x):
        yhat, dy = cn.jacobian(x, U)
        return y - yhat[:, 0], dy[:, 0, :]

    def residual(x):
        return y - cn.simulate(x, U)[:, 0]

    fun(cn.theta0())  # JIT warm-up
    residual(cn.theta0())
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(3):
        fun(cn.theta0())
    t_jac = (time.perf_counter() - t0) / 3
    t0, c0 = time.perf_counter(), time.process_time()
    ours = levenberg_marquardt(fun, cn.theta0(), cn.names, residual=residual,
                               options=LMOptions(max_iter=iters, mu0=3.0, mu_inc=10.0, mu_dec=0.1))
    t_ours, c_ours = time.perf_counter() - t0, time.process_time() - c0

    py = ensure_venv()
    theirs = None
    if py is not None:
        with tempfile.TemporaryDirectory() as tmp:
            npz = Path(tmp) / "data.npz"
            np.savez(npz, P=u, Y=y, w0=w0, iters=iters)
            script = Path(tmp) / "child.py"
            script.write_text(CHILD)
            out = subprocess.run([py, str(script), str(npz)], capture_output=True, text=True, timeout=1800)
            if out.returncode != 0:
                print("pyrenn run failed:\n" + out.stderr[-2000:])
            else:
                theirs = json.loads(out.stdout.strip().splitlines()[-1])

    p, n_c = cn.n_theta, cn._flat.n_connections
    flops_jac = q * (2 * p * 41 + 2 * 57 + p * 6 + 2 * n_c)
    n_trials = ours.nfev - ours.njev
    flops = ours.njev * (flops_jac + 2 * q * p * p + 2 * q * p) + n_trials * (2 * q * n_c + p**3 / 3)
    print(f"\noffline LM, GDNN [1, 5, 1] with dIn {{0,1}}, dIntern {{1}}, dOut {{1,2}} (57 weights), Q = {q}, "
          f"{iters} iterations")
    print(f"{'':<30}{'start cost':>12}{'final cost':>12}{'wall s/it':>11}{'CPU s/it':>10}{'Jacobian s':>12}"
          f"{'GFLOP/s':>9}")
    it = max(ours.iterations, 1)
    print(f"{'ours (numba RTRL)':<30}{ours.cost_history[0]:>12.6g}{ours.cost:>12.6g}{t_ours / it:>11.4f}"
          f"{c_ours / it:>10.4f}{t_jac:>12.4f}{flops / c_ours / 1e9:>9.3f}")
    if theirs is not None:
        cj = theirs["calls"]["RTRL"]
        print(f"{'pyrenn 0.1 (numpy RTRL)':<30}{theirs['E0'] / 2:>12.6g}{theirs['E'] / 2:>12.6g}"
              f"{theirs['wall'] / iters:>11.3f}{theirs['cpu'] / iters:>10.3f}{cj[1] / max(cj[0], 1):>12.3f}")
        print(f"ratio pyrenn / ours per LM iteration: wall {theirs['wall'] / iters / (t_ours / it):.0f}x, "
              f"CPU {theirs['cpu'] / iters / (c_ours / it):.0f}x (target >= 100x; cost equal or lower: "
              f"{'yes' if ours.cost <= theirs['E'] / 2 * (1 + 1e-9) else 'no'})")
        print(f"pyrenn normalisation factors P {theirs['normP']}, Y {theirs['normY']} (1 = identity); "
              f"pyrenn calls: {theirs['calls']}")
    print(f"ours: {ours.njev} Jacobians, {n_trials} residual-only trials; {flops / 1e6:.0f} MFLOP "
          f"({flops_jac / 1e6:.1f} per Jacobian); mu history {ours.mu_history}")


if __name__ == "__main__":
    main()
