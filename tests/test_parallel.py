"""The executor layer: same seed -> bit-identical multi-start results serial, in local processes and on Dask."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from fleet_data import TRUTH, sleep_then, write_chart, write_log

from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import read_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.executors import (
    DASK_HINT,
    DaskExecutor,
    ProcessExecutor,
    SerialExecutor,
    make_executor,
)
from flowchart2sdnn.fit.lm import LMOptions, levenberg_marquardt
from flowchart2sdnn.identify.offline.problem import build_problem, required_columns
from flowchart2sdnn.identify.offline.run import IdentifySettings, identify
from flowchart2sdnn.identify.offline.workers import fit_start, fit_task, problem_of

SETTINGS = IdentifySettings(starts=4, seed=7, max_iter=12)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("par")
    chart = write_chart(d)
    data = write_log(d / "drive_day001.csv", seed=3, seconds=1.0)
    diagram = load_diagram(str(chart))
    ds = read_csv(str(data), required_columns(diagram), None, diagram.sample_time)
    return {"chart": chart, "data": data, "diagram": diagram, "ds": ds}


@pytest.fixture(scope="module")
def serial(case):
    return identify(case["diagram"], case["ds"], None, SETTINGS)


@pytest.fixture(scope="module")
def processes():
    ex = ProcessExecutor(2)
    yield ex
    ex.close()


@pytest.fixture(scope="module")
def local_cluster():
    distributed = pytest.importorskip("distributed")
    # two single-threaded workers in this process: fast to start; pickling is covered by the process pool tests
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def _same(a, b):
    """Bit-identical fits: the best point, every start's cost and the whole parameter table."""
    np.testing.assert_array_equal(a.x, b.x)
    assert a.result["multistart"]["costs"] == b.result["multistart"]["costs"]
    assert a.result["parameters"] == b.result["parameters"]
    assert a.result["optimizer"] == b.result["optimizer"]


def test_serial_fit_is_a_real_fit(serial):
    # the oracle is the plant the data came from, not the code: the starts must reach it
    for name, true in TRUTH.items():
        p = serial.result["parameters"][name]
        assert abs(p["value"] - true) < max(4 * p["stderr"], 0.01 * true), (name, p)
    assert len(serial.result["multistart"]["costs"]) == SETTINGS.starts


def test_rebuilt_problem_in_this_process_is_identical(case, serial):
    _same(serial, identify(case["diagram"], case["ds"], None, SETTINGS, executor=SerialExecutor()))


def test_local_processes_are_identical(case, serial, processes):
    out = identify(case["diagram"], case["ds"], None, SETTINGS, executor=processes)
    _same(serial, out)
    # results come back as frozen LMResult objects: arrays read-only again after unpickling
    assert not out.lm.x.flags.writeable and not out.lm.jac.flags.writeable


def test_dask_local_cluster_is_identical(case, serial, local_cluster):
    out = identify(case["diagram"], case["ds"], None, SETTINGS, executor=DaskExecutor(client=local_cluster))
    _same(serial, out)
    assert not out.lm.residual.flags.writeable


@pytest.mark.parametrize("kind", ["serial", "processes", "dask"])
def test_map_keeps_input_order_and_submit_works(kind, processes, request):
    ex = {"serial": SerialExecutor, "processes": lambda: processes,
          "dask": lambda: DaskExecutor(client=request.getfixturevalue("local_cluster"))}[kind]()
    assert list(ex.map(sleep_then, [0, 1, 2, 3])) == [0, 1, 2, 3]
    futures = [ex.submit(sleep_then, k) for k in range(3)]
    assert sorted(ex.result(f) for f in ex.as_completed(futures)) == [0, 1, 2]


def test_worker_problem_is_the_callers_problem(case, tmp_path):
    """Every Problem field travels: the guard's stability floor and further training records included."""
    from dataclasses import replace

    second = write_log(tmp_path / "drive_day009.csv", seed=9, seconds=0.5)
    more = read_csv(str(second), required_columns(case["diagram"]), None, case["diagram"].sample_time)
    problem = build_problem(case["diagram"], case["ds"], more=[more])
    problem = replace(problem, stability_floor=(0.5, 1.5))
    names = problem.names
    lo, hi = np.zeros(len(names)), np.full(len(names), np.inf)
    options = LMOptions(max_iter=4)
    task = fit_task(problem, lo, hi, options)
    rebuilt = problem_of(task)
    assert rebuilt is problem_of(task)  # built once per worker
    assert rebuilt.stability_floor == (0.5, 1.5) and len(rebuilt.segments) == 2
    x0 = problem.compiled.theta0()
    direct = levenberg_marquardt(problem.fun, x0, names, lo, hi, options, guard=problem.guard,
                                 residual=problem.residual)
    via_task = fit_start(task, x0)
    np.testing.assert_array_equal(direct.x, via_task.x)
    assert direct.cost_history == via_task.cost_history


def test_make_executor_choices(processes):
    assert isinstance(make_executor(), SerialExecutor)
    assert isinstance(make_executor(workers=1), SerialExecutor)
    with pytest.raises(ValueError):
        make_executor(workers=0)
    assert processes.method in ("forkserver", "spawn")  # never a plain fork: numba and fork do not mix


def test_missing_dask_is_one_clear_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(SdnnError) as err:
        make_executor(scheduler="tcp://127.0.0.1:8786")
    text = str(err.value)
    assert DASK_HINT in text and "\n" not in text


def test_cli_identify_with_workers_writes_the_same_result(case, tmp_path):
    runner = CliRunner()
    args = ["identify", str(case["data"]), "--diagram", str(case["chart"]), "--starts", "3", "--seed", "2",
            "--max-iter", "8", "--quiet"]
    a = runner.invoke(main, args + ["-o", str(tmp_path / "a.json")])
    b = runner.invoke(main, args + ["-o", str(tmp_path / "b.json"), "--workers", "2"])
    assert a.exit_code == 0, a.output
    assert b.exit_code == 0, b.output
    ra, rb = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    assert ra["parameters"] == rb["parameters"] and ra["multistart"] == rb["multistart"]


def test_batch_tables_identical_serial_processes_dask(case, processes, local_cluster, tmp_path):
    from flowchart2sdnn.batch.results import read_results
    from flowchart2sdnn.batch.run import BatchSettings, run_batch

    files = [str(case["data"])]
    for day, fc in ((2, 0.7), (3, 0.8)):
        files.append(str(write_log(tmp_path / f"drive_day{day:03d}.csv", seed=day, Fc=fc)))
    settings = BatchSettings(identify=IdentifySettings(starts=2, seed=1, max_iter=15))
    tables = []
    for name, ex in (("serial", None), ("processes", processes), ("dask", DaskExecutor(client=local_cluster))):
        out = tmp_path / f"{name}.csv"
        summary = run_batch(case["diagram"], files, str(out), settings, executor=ex)
        assert summary.identified == 3
        tables.append([{k: v for k, v in r.items() if k != "seconds"} for r in read_results(out)[1]])
    assert tables[0] == tables[1] == tables[2]
