"""The library computes on one BLAS thread unless the user chose a number (flowchart2sdnn/threads.py): in a
fresh interpreter where numpy already runs two BLAS threads (a notebook), identify's progress callback sees one,
and the user's two come back after it; with OPENBLAS_NUM_THREADS set, the library leaves them alone."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

SCRIPT = """
import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits
threadpool_limits(limits=2, user_api="blas")
import flowchart2sdnn as sd

def blas():
    return max(p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas")

seen = []
chart = sd.load_chart("diagrams/engine.yaml")
data = sd.read_csv("examples/data/engine_idle.csv", chart=chart)
sd.identify(chart, data, max_iter=2, progress=lambda text, fraction=None: seen.append(blas()))
print(sorted(set(seen)), blas())
"""


@pytest.mark.parametrize("user", [None, "2"])
def test_identify_runs_on_one_blas_thread_and_gives_the_users_back(user):
    pytest.importorskip("threadpoolctl")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                              "MKL_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    if user:
        env["OPENBLAS_NUM_THREADS"] = user
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    inside, after = done.stdout.split("]")
    # with the user's variable set the library leaves BLAS as the user has it (the script asked for two)
    assert inside.strip("[ ") == ("2" if user else "1") and after.strip() == "2"
