"""Cascaded Tanks: what keeps the hand-written physical chart (diagrams/real/cascaded_tanks_physical.yaml) above
the published 0.191 V (benchmarks/cascaded_tanks_limits.py measures it; benchmarks/notes/diagnose.md reports it).

Oracles: the records themselves (the rows where the test level leaves the estimation record's range, the
initial state fitted on the whole test record as the best start any window could give) and multi-start from
draws within the bounds. Skipped when the data are absent.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from example_module import load_benchmark
from realdata import real_dataset

import flowchart2sdnn as sd

ROOT = Path(__file__).resolve().parents[1]
DATA, pytestmark = real_dataset("cascaded_tanks", "estimation.csv", "cascaded tanks data not present")



@pytest.fixture(scope="module")
def records():
    return sd.read_csv(DATA / "estimation.csv"), sd.read_csv(DATA / "validation.csv")


@pytest.fixture(scope="module")
def fitted(records):
    return sd.identify(ROOT / "diagrams" / "real" / "cascaded_tanks_physical.yaml", records[0], starts=1, seed=0)


def _cost(result) -> float:
    return json.loads(result.to_json())["fit"]["train"]["cost"]


def test_one_start_already_reaches_the_estimation_minimum_of_eight(records, fitted):
    """The optimizer is not what keeps the chart above 0.191 V: 7 more starts drawn within the bounds find no
    lower estimation cost (measured 10.760 from 1, 8 and 32 starts)."""
    eight = sd.identify(ROOT / "diagrams" / "real" / "cascaded_tanks_physical.yaml", records[0], starts=8, seed=0)
    assert _cost(eight) > _cost(fitted) * (1 - 1e-3), (_cost(eight), _cost(fitted))


def test_the_five_sample_start_costs_under_0_01_volt(records, fitted):
    """The start fitted on the protocol's 5 samples against the start fitted on the whole test record (the best
    any window could give): measured 0.2423 against 0.2382 V."""
    limits = load_benchmark("cascaded_tanks_limits")
    y = records[1].columns["y_V"]
    five = limits.rms(limits.free_run(fitted.chart, records[1], 5)[5:] - y[5:])
    whole = limits.rms(limits.free_run(fitted.chart, records[1], records[1].n_rows)[5:] - y[5:])
    assert 0 <= five - whole < 0.01, (five, whole)
    assert five > 0.191  # the published grey-box's number is not reached


def test_the_error_beyond_the_estimation_range_is_a_third_of_the_test_error(records, fitted):
    """The test level falls below the estimation record's lowest level (2.91 V) only at its end (31 rows from
    row 967); rows 960-1023 hold about a third of the squared error (measured 0.31; RMSE 0.537 V there, 0.208 V
    on rows 5-959, still above 0.191 V)."""
    limits = load_benchmark("cascaded_tanks_limits")
    train, test = records
    y = test.columns["y_V"]
    below = np.flatnonzero(y < train.columns["y_V"].min())
    assert below.size == 31 and below[0] == 967
    e = limits.free_run(fitted.chart, test)[5:] - y[5:]
    tail = np.sum(e[limits.TAIL - 5:] ** 2) / np.sum(e ** 2)
    assert tail > 0.2, tail
    assert 0.191 < limits.rms(e[:limits.TAIL - 5]) < 0.23
