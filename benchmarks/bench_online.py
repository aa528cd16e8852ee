"""Quasi-online LM on the paper's run: 100 s at 1 kHz, Q = 25 000 (section 3.1, 6).

The default window mode runs one exact LM iteration on the last Q samples every 500 samples (a window
simulation per trial, an RTRL pass over the window per accepted iteration; flowchart2sdnn/identify/online/kernel.py).
Measures the real-time factor (record length / wall time; target >= 20x), the GFLOP/s of the per-sample part
against the flop count below (that of the former trial mode, ``OnlineOptions(tries=0)``, one LM step per sample;
the window mode's window passes come on top and are not counted), and the peak memory (tracemalloc: every numpy allocation of the run) for Q = 5000 / 25 000 and
records of 50 s / 100 s. Memory must grow with Q, not with the record (apart from the decimated records).

Paper procedure: stage 1 identifies the motor (diagrams/engine.yaml: J1 + a 3-neuron friction) on the idling
motor bench (engine_plant.yaml); stage 2 identifies J2, c, d and the load friction of the two-mass network
(two_mass.yaml, 9 free quantities) on two_mass_plant.yaml with J1 and the motor friction of stage 1 fixed.
Start values of Tables 1-2: J1 = 0.6; J2 = 0.7, d = 0.4, c = 100; friction weights uniform in [-0.5, 0.5].

Flop count per sample (P free quantities, N neurons, C connections, C_n of them from neurons, D nonzero
d(connection)/d(theta) entries; a multiply-add is 2 flops):
    RTRL of the model and of the block sensitivities   2 * (2 P C_n + 2 D + P N)
    forward pass of the model and of the trial         2 * 2 C
    FIFO update (add the new row, remove the old one)  2 * P (P + 1)
    one LM step: g = b - A d, Cholesky, two solves     2 P^2 + P^3 / 3 + 2 P^2
Sub-steps (issue 13): stage 2 again with the network at h = T/N, for N = `auto` (resolved at the chart's
start values, as ``sdnn identify --online --substeps auto``) and the N that `auto` picks at the identified
parameters; every sample then costs N RTRL steps, every window pass N steps per row.

Run: ``python benchmarks/bench_online.py`` (a few minutes; ``--quick`` for 20 s records).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see benchmarks/README.md: BLAS threads thrash on a shared machine

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from flowchart2sdnn.compiler import compile_diagram, compile_file  # noqa: E402
from flowchart2sdnn.diagram.validate import load_diagram  # noqa: E402
from flowchart2sdnn.identify.online.run import OnlineOptions, quasi_online  # noqa: E402
from flowchart2sdnn.network.runtime import CompiledNetwork  # noqa: E402
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite  # noqa: E402


def flops_per_sample(cn: CompiledNetwork) -> float:
    f = cn._flat
    p, n, c = cn.n_theta, f.n_neurons, f.n_connections
    c_n = int((f.conn_kind == 0).sum())
    d = cn.weights.n_slots
    return 2 * (2 * p * c_n + 2 * d + p * n) + 4 * c + 2 * p * (p + 1) + 4 * p * p + p**3 / 3


def stage2_network(stage1: dict, substeps: int | str, delays: str | None = None) -> CompiledNetwork:
    """two_mass.yaml (tests/data/two_mass_euler.yaml: the paper's scheme) at `substeps` (1: the paper's network) with J1 and the motor friction of stage 1 fixed.

    `auto` reads the chart's modes at its start values (c = 100, J2 = 0.7), as `sdnn identify --fix-from ...
    --substeps auto` does; J1 is 0.1912 in the chart already, the value stage 1 finds."""
    if delays is None:
        net = compile_file(ROOT / "tests/data/two_mass_euler.yaml", substeps=substeps).network
    else:  # another delay rule than the chart's (the paper's search)
        chart = dataclasses.replace(load_diagram(ROOT / "tests/data/two_mass_euler.yaml"), delays=delays)
        net = compile_diagram(chart, substeps=substeps).network
    return CompiledNetwork(dataclasses.replace(
        net,
        parameters=tuple(dataclasses.replace(p, init=stage1.get(p.name, p.init)) for p in net.parameters),
        free_weights=tuple(dataclasses.replace(f, init=stage1.get(f.name, f.init), fixed=f.name in stage1)
                           for f in net.free_weights),
    ))


def auto_at(values: dict) -> int:
    """The N that `substeps: auto` picks for two_mass.yaml with its parameters at `values` (its fastest mode)."""
    d = load_diagram(ROOT / "tests/data/two_mass_euler.yaml")
    d = dataclasses.replace(d, parameters=tuple(dataclasses.replace(p, init=float(values.get(p.name, p.init)))
                                                for p in d.parameters))
    return compile_diagram(d, substeps="auto").network.substeps


def timed(cn, u, y, lower, opts):
    """The run, its wall time and its CPU time (one thread: on a shared machine the CPU time is the honest
    cost, the wall time also counts the waits for a core)."""
    t0, c0 = time.perf_counter(), time.process_time()
    res = quasi_online(cn, u, y, lower=lower, options=opts)
    return res, time.perf_counter() - t0, time.process_time() - c0


def peak_memory(cn, u, y, lower, opts) -> float:
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    quasi_online(cn, u, y, lower=lower, options=opts)
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return peak / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20 s records instead of 100 s (a smoke run)")
    args = ap.parse_args()
    seconds = 20.0 if args.quick else 100.0
    fs = 1000
    n = int(seconds * fs)
    opts = OnlineOptions(window=25000, every=1, average=25000, start=5000)

    print(f"data: {seconds:.0f} s of each bench at {fs} Hz (RK4, 20 substeps, APRBS + relay, seed 1) ...", flush=True)
    eng = excite(load_diagram(ROOT / "diagrams/engine_plant.yaml"), ExcitationSettings(seconds=seconds, seed=1))
    tms = excite(load_diagram(ROOT / "diagrams/two_mass_plant.yaml"), ExcitationSettings(seconds=seconds, seed=1))

    # stage 1: motor
    # the network these rows were measured on: one step per sample, the default delay rule (the chart itself
    # states what the bundled offline record needs, substeps 8 with midpoint torques)
    chart = dataclasses.replace(load_diagram(ROOT / "diagrams/engine.yaml"), delays=None)
    engine = CompiledNetwork(compile_diagram(chart, substeps=1).network)
    ue, ye = eng["M1"][:, None], eng["w1"]
    lower_e = [0.0] + [-np.inf] * (engine.n_theta - 1)
    quasi_online(engine, ue[:2000], ye[:2000], lower=lower_e, options=dataclasses.replace(opts, start=100))  # JIT
    res_e, wall_e, cpu_e = timed(engine, ue, ye, lower_e, opts)

    # stage 2: two-mass system with the motor of stage 1
    stage1 = dict(zip(res_e.names, res_e.theta_mean, strict=True))
    tms_net = stage2_network(stage1, 1)
    ut, yt = tms["M1"][:, None], tms["w2"]
    lower_t = [0.0, 0.0, 0.0] + [-np.inf] * (tms_net.n_theta - 3)
    res_t, wall_t, cpu_t = timed(tms_net, ut, yt, lower_t, opts)

    print("\nquasi-online LM, window mode (an exact LM iteration on the window every 500 samples), Q = 25000, "
          "estimate = mean over the last 25000 steps; flop/sample: the per-sample part only (see the docstring)")
    print(f"{'stage':<26}{'P':>3}{'samples':>9}{'wall [s]':>10}{'CPU [s]':>9}{'x real time':>13}{'target':>8}"
          f"{'flop/sample':>13}{'GFLOP/s':>9}")
    for name, cn, wall, cpu in (("1 motor (engine.yaml)", engine, wall_e, cpu_e),
                                ("2 two-mass (two_mass.yaml)", tms_net, wall_t, cpu_t)):
        fl = flops_per_sample(cn)
        print(f"{name:<26}{cn.n_theta:>3}{n:>9}{wall:>10.3f}{cpu:>9.3f}{seconds / cpu:>12.1f}x{'>= 20x':>8}"
              f"{fl:>13.0f}{fl * n / cpu / 1e9:>9.3f}")
    print("(x real time = record length / CPU time of the call)")
    print("\nestimates (truth = the bench's parameters; paper = Tables 1 and 2, first start values)")
    print(f"  J1 = {res_e.theta_mean[0]:.4f}  (truth 0.1912, paper 0.1912)   mean E = {res_e.mean_cost:.4g}"
          f"   [{res_e.accepted_blocks} trials accepted, {res_e.rejected_blocks} refused]")
    j2, c, d = res_t.theta_mean[:3]
    print(f"  J2 = {j2:.4f} (truth 0.3838, paper 0.3838)  c = {c:.1f} (477.2, 477.2)  d = {d:.4f} (0.2406, 0.2406)"
          f"   mean E = {res_t.mean_cost:.4g}   [{res_t.accepted_blocks} accepted, {res_t.rejected_blocks} refused]")

    # sub-steps (issue 13): the same stage 2 with the network stepping N times per sample
    n_auto = stage2_network(stage1, "auto").substeps
    n_fitted = auto_at(dict(zip(res_t.names, res_t.theta_mean, strict=True)))
    print(f"\nstage 2 with sub-steps (h = T/N; `auto` at the chart's start values gives N = {n_auto}, at the "
          f"parameters identified above N = {n_fitted})")
    print(f"{'substeps':<16}{'wall [s]':>10}{'CPU [s]':>9}{'x real time':>13}{'target':>8}{'J2':>9}{'c':>8}"
          f"{'d':>9}{'mean E':>10}")
    rows = [("1 (paper)", tms_net, res_t, wall_t, cpu_t)]
    n_mid = stage2_network(stage1, "auto", "midpoint").substeps
    for label, n_sub, delays in ((f"auto (N = {n_auto})", "auto", None), (f"N = {n_fitted}", n_fitted, None),
                                 (f"midpoint, auto (N = {n_mid})", "auto", "midpoint")):
        if n_sub == n_auto and label.startswith("N ="):
            continue
        cn = stage2_network(stage1, n_sub, delays)
        quasi_online(cn, ut[:2000], yt[:2000], lower=lower_t, options=dataclasses.replace(opts, start=100))  # JIT
        res, wall, cpu = timed(cn, ut, yt, lower_t, opts)
        rows.append((label, cn, res, wall, cpu))
    for label, _, res, wall, cpu in rows:
        j2, c, d = res.theta_mean[:3]
        print(f"{label:<16}{wall:>10.3f}{cpu:>9.3f}{seconds / cpu:>12.1f}x{'>= 20x':>8}{j2:>9.4f}{c:>8.1f}"
              f"{d:>9.4f}{res.mean_cost:>10.4g}")
    print("(truth J2 0.3838, c 477.2, d 0.2406; the quasi_online call, one thread; the cost per sample grows about "
          "linearly in N: every sample runs N RTRL steps, every window pass N steps per row)")

    print("\npeak memory of quasi_online (tracemalloc, two-mass stage), MiB")
    print(f"{'Q':>7}{'record [s]':>12}{'peak [MiB]':>12}{'window ring [MiB]':>19}")
    for q in (5000, 25000):
        for secs in (seconds / 2, seconds):
            m = int(secs * fs)
            o = dataclasses.replace(opts, window=q, average=q, start=min(5000, m // 4))
            peak = peak_memory(tms_net, ut[:m], yt[:m], lower_t, o)
            ring = q * tms_net.n_outputs * tms_net.n_theta * 8 * (1 + 2 / tms_net.n_theta) / 2**20
            print(f"{q:>7}{secs:>12.0f}{peak:>12.2f}{ring:>19.2f}")
    print("(window ring = the Q x n_out x P Jacobian rows plus 2 values per row; the average ring adds K x P;"
          " only the decimated records, record/record_every rows, grow with the record)")


if __name__ == "__main__":
    main()
