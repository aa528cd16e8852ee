"""Multi-start on local workers: 16 starts of the paper's two-mass identification, serial vs N processes.

The data come from the virtual test bench (``excite`` on diagrams/two_mass_plant.yaml); the fitted chart is
diagrams/two_mass.yaml on the paper's network (tests/data/two_mass_euler.yaml: physical J2, c, d and two learned
friction curves, one step per sample). Both runs must give bit-identical
results; the speed-up is the serial wall time over the parallel one, measured once with the pool's start-up
included and then, in interleaved serial / parallel pairs, with a pool that is already running. The load
average is printed with every measurement: on a shared machine other processes take cores away. Linux with
autogroup scheduling shares the CPU between sessions, not processes: on a busy machine all workers of this
session then split one session's share and no speed-up can show; ``--sessions`` starts each worker in a
session of its own, so that each competes like a separate program (what it would get on an idle machine).

Run: ``python benchmarks/bench_parallel.py [--starts 16] [--workers 2] [--seconds 4] [--max-iter 60] [--rounds 3]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from flowchart2sdnn.data.csvdata import Dataset, read_csv, write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.executors import ProcessExecutor
from flowchart2sdnn.identify.offline.problem import required_columns
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

REPO = Path(__file__).resolve().parents[1]


def _data(seconds: float, directory: Path) -> tuple:
    plant = load_diagram(str(REPO / "diagrams" / "two_mass_plant.yaml"))
    chart = load_diagram(str(REPO / "tests" / "data" / "two_mass_euler.yaml"))
    path = directory / "two_mass.csv"
    write_csv(path, excite(plant, ExcitationSettings(seconds=seconds, seed=1, noise_std=0.01)), "%.17g")
    return chart, read_csv(str(path), required_columns(chart), None, chart.sample_time)


def _own_session() -> None:
    """Worker initializer for --sessions: a session of its own, hence (Linux autogroup) its own CPU share."""
    os.setsid()


def _autogroup() -> str:
    try:
        return "on" if Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1" else "off"
    except OSError:
        return "unknown"


def _worker_cpu(pool: ProcessExecutor) -> dict[int, float]:
    """CPU seconds (user + system) used so far by each worker process (Linux /proc; empty elsewhere)."""
    out = {}
    tick = os.sysconf("SC_CLK_TCK")
    for pid in list(getattr(pool._pool, "_processes", {}) or {}):
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[pid] = (int(fields[11]) + int(fields[12])) / tick
    return out


def _load() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def _timed(chart, data: Dataset, settings: IdentifySettings, executor=None):
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    out = identify(chart, data, None, settings, executor=executor)
    return out, time.perf_counter() - t0, time.process_time() - cpu0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=4.0, help="record length (1 kHz)")
    ap.add_argument("--max-iter", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=3, help="serial / parallel pairs, interleaved")
    ap.add_argument("--sessions", action="store_true",
                    help="start each worker in its own session: with Linux autogroup scheduling on a busy "
                         "machine, the workers of one session share that session's CPU share")
    args = ap.parse_args()
    settings = IdentifySettings(starts=args.starts, seed=args.seed, max_iter=args.max_iter)
    print(f"cpus {os.cpu_count()}, load average {_load()} (1, 5, 15 min), autogroup scheduling {_autogroup()}, "
          f"workers in {'their own sessions' if args.sessions else 'this session'}")
    with tempfile.TemporaryDirectory() as tmp:
        chart, data = _data(args.seconds, Path(tmp))
    print(f"two-mass: {data.n_rows} samples, {args.starts} starts, max {args.max_iter} iterations")
    identify(chart, data.slice(0, 200), None, IdentifySettings(max_iter=1))  # load the compiled kernels once

    t0 = time.perf_counter()
    pool = ProcessExecutor(args.workers, initializer=_own_session if args.sessions else None)
    first, _, _ = _timed(chart, data, settings, pool)
    t_cold = time.perf_counter() - t0
    print(f"{args.workers} workers, cold pool (start-up included): {t_cold:6.2f} s wall   load {_load()}")
    serial = None
    same = True
    ratios, idle = [], []
    # interleaved pairs: on a shared machine the load changes from minute to minute
    for k in range(args.rounds):
        serial, t_serial, cpu_serial = _timed(chart, data, settings)
        before = _worker_cpu(pool)
        par, t_par, _ = _timed(chart, data, settings, pool)
        after = _worker_cpu(pool)
        busiest = max((after[p] - before.get(p, 0.0) for p in after), default=float("nan"))
        ratios.append(t_serial / t_par)
        idle.append(cpu_serial / busiest)
        same &= all(np.array_equal(serial.x, r.x) and
                    serial.result["multistart"]["costs"] == r.result["multistart"]["costs"] for r in (first, par))
        print(f"round {k + 1}: serial {t_serial:6.2f} s wall ({cpu_serial:.2f} s CPU = "
              f"{100 * cpu_serial / t_serial:.0f} % of a core), {args.workers} workers {t_par:6.2f} s wall: "
              f"{t_serial / t_par:.2f}x; busiest worker {busiest:.2f} s CPU -> {cpu_serial / busiest:.2f}x "
              f"with a free core per worker   load {_load()}")
    pool.close()
    print(f"speed-up (warm pool): median {np.median(ratios):.2f}x, best {max(ratios):.2f}x wall (target >= 1.8x "
          f"on 2 cores); in CPU time (serial CPU / busiest worker's CPU: the wall-time speed-up with a free core "
          f"per worker) median {np.median(idle):.2f}x; cold pool: {t_serial / t_cold:.2f}x; "
          f"results bit-identical: {same}")
    ms = serial.result["multistart"]
    print(f"best start {ms['best_index']}, costs {[round(c, 4) if c is not None else None for c in ms['costs']]}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
