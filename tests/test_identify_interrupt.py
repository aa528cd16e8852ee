"""Ctrl-C during `sdnn identify`: the best result so far is written, marked interrupted, and the exit code is 1.

A real subprocess gets a real SIGINT once its LM loop is running (its first progress line on stderr). A
SIGINT that lands inside a numba kernel comes out of the dispatcher as a SystemError whose cause is the
KeyboardInterrupt; the unit test below checks that the fitting problem turns it back into the trainer's
clean stop.
"""

from __future__ import annotations

import json
import math
import os
import queue
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from flowchart2sdnn.data.csvdata import read_csv, write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.identify.offline.problem import build_problem, required_columns
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
DIAGRAMS = ROOT / "diagrams"

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child needs POSIX signals")


def _record(path: Path, seconds: float, seed: int) -> Path:
    columns = excite(load_diagram(DIAGRAMS / "engine_plant.yaml"),
                     ExcitationSettings(seconds=seconds, seed=seed, noise_std=0.01))
    write_csv(path, columns, float_format="%.17g")
    return path


def test_sigint_writes_the_best_result_so_far_marked_interrupted(tmp_path):
    data = _record(tmp_path / "engine.csv", 12.0, seed=3)
    out = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    # the paper's free-slope neurons: a fit long enough to interrupt (the default basis ends within seconds)
    proc = subprocess.Popen([sys.executable, "-m", "flowchart2sdnn", "identify", str(data), "--diagram",
                             str(ROOT / "tests" / "data" / "engine_neurons.yaml"), "-o", str(out), "--max-iter", "1000"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=env)
    lines: queue.Queue[str] = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(line) for line in proc.stderr], daemon=True)
    reader.start()
    seen = []
    try:
        # the LM loop is running once progress is reported (after about a second of iterations)
        while not any("LM iteration" in line for line in seen):
            seen.append(lines.get(timeout=120))
        proc.send_signal(signal.SIGINT)
        stdout = proc.stdout.read()  # stderr stays with the reader thread: one reader per pipe
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(timeout=10)
    while not lines.empty():
        seen.append(lines.get())
    stderr = "".join(seen)
    assert proc.returncode == 1, stderr
    assert f"interrupted: the best result so far is in {out}" in stderr
    assert "Traceback" not in stderr
    r = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    assert r["status"] == "interrupted" and r["interrupted"] is True
    assert 1 <= r["optimizer"]["iterations"] < 1000
    history = r["optimizer"]["cost_history"]
    assert all(math.isfinite(c) for c in history) and history[-1] <= history[0]
    assert all(math.isfinite(p["value"]) for p in r["parameters"].values())
    assert all(math.isfinite(v) for w in r["nonlinear"].values() for v in w["a"] + w["v"])
    assert math.isfinite(r["fit"]["train"]["cost"])
    assert r["fit"]["train"]["cost"] == pytest.approx(history[-1], rel=1e-9)  # the best point is the one kept
    chart = load_diagram(tmp_path / "r.chart.yaml")
    assert next(p for p in chart.parameters if p.name == "J1").init == r["parameters"]["J1"]["value"]
    assert "status: interrupted" in stdout


def test_keyboard_interrupt_inside_a_numba_kernel_stops_the_trainer_cleanly(tmp_path, monkeypatch):
    data = _record(tmp_path / "engine.csv", 1.0, seed=5)
    diagram = load_diagram(DIAGRAMS / "engine.yaml")
    problem = build_problem(diagram, read_csv(data, required_columns(diagram), None, diagram.sample_time))
    real = problem.compiled.jacobian
    calls = []

    def jacobian(*args, **kwargs):
        calls.append(1)
        if len(calls) == 12:  # what numba's dispatcher raises when SIGINT arrives during the kernel
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt as exc:
                raise SystemError("CPUDispatcher(...) returned a result with an exception set") from exc
        return real(*args, **kwargs)

    monkeypatch.setattr(problem.compiled, "jacobian", jacobian)
    x0 = problem.compiled.theta0()
    result = levenberg_marquardt(problem.fun, x0, problem.names, options=LMOptions(max_iter=50))
    assert result.status == "interrupted" and result.interrupted
    assert np.all(np.isfinite(result.x)) and result.iterations >= 1
    assert result.cost == pytest.approx(0.5 * float(problem.residual(result.x) @ problem.residual(result.x)))
    # any other SystemError is not swallowed
    monkeypatch.setattr(problem.compiled, "jacobian", lambda *a, **k: (_ for _ in ()).throw(SystemError("x")))
    with pytest.raises(SystemError):
        problem.fun(x0)
