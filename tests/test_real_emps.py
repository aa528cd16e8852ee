"""EMPS (real measurements, ../shared/data/real/emps): the physical chart M q'' = F - Fv q' - Fc sign(q') - offset
identified on train.csv and scored by the official protocol (test.csv, initial state fitted on its first 20
samples, position RMSE from sample 20, in mm).

Oracles: the published IDIM-LS parameters (Janot, Gautier, Brunot 2019) put into the same charts and scored by the
same protocol (computed here, not copied), the published asymmetric viscous friction (Fv+ 166.7 < Fv- 240.4
N s/m), the test record's spread (BENCHMARKS.md: fit % = 100 (1 - RMSE / std q)), and the continuous RK4
simulation of the chart. Skipped when the data are absent.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from example_module import load_example
from realdata import real_dataset

import flowchart2sdnn as sd
from flowchart2sdnn.simulate.continuous import simulate_continuous

ROOT = Path(__file__).resolve().parents[1]
DATA, pytestmark = real_dataset("emps", "train.csv", "EMPS data not present")



def _example():
    return load_example("emps")


def _raw(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(force, position) straight from the CSV, not through the library's reader."""
    with open(DATA / name, newline="") as f:
        rows = list(csv.DictReader(f))
    return (np.array([float(r["force_N"]) for r in rows]), np.array([float(r["q_meas_m"]) for r in rows]))


@pytest.fixture(scope="module")
def runs():
    ex = _example()
    train, test = ex.records()
    chart, asymmetric = sd.load_chart(ex.CHART), sd.load_chart(ex.ASYMMETRIC)
    return {
        "published": ex.protocol(ex.with_values(chart, ex.IDIM_LS), train, test, fit=False),
        "published asymmetric": ex.protocol(ex.with_values(asymmetric, ex.IDIM_LS_ASYMMETRIC), train, test,
                                            fit=False),
        "symmetric": ex.protocol(chart, train, test),
        "asymmetric": ex.protocol(asymmetric, train, test),
    }


def test_network_follows_the_continuous_chart_at_its_substeps():
    """substeps 2 (h = 0.5 ms): the network of the chart at the published parameters within 0.1 mm RMS of its
    RK4 run over the first 8 s of test.csv (0.07 mm measured over the whole record; N = 1: 0.13 mm)."""
    ex = _example()
    chart = ex.with_values(sd.load_chart(ex.CHART), ex.IDIM_LS)
    assert chart.substeps == 2
    force, q = _raw("test.csv")
    force, q0 = force[:8000], float(q[0])
    from flowchart2sdnn.network.alignment import run_aligned
    from flowchart2sdnn.network.runtime import CompiledNetwork

    def network(c):
        cn = CompiledNetwork(sd.compile_chart(c).network)
        return run_aligned(cn, cn.theta0(), force[:, None], "zoh", {"q_meas_m": q0})[:, 0]

    y_ode = simulate_continuous(chart, force[:, None], init={"q_meas_m": q0}, substeps=40)[:, 0]
    assert 1000 * np.sqrt(np.mean((network(chart) - y_ode) ** 2)) < 0.1
    # one step per sample is measurably worse: the bound can tell the two apart
    assert 1000 * np.sqrt(np.mean((network(replace(chart, substeps=1)) - y_ode) ** 2)) > 0.1


def test_identified_chart_beats_the_published_physical_model_by_the_protocol(runs):
    """The identified symmetric chart must score better on test than the benchmark authors' own IDIM-LS
    parameters in the same chart (8.5 mm measured; ours 6.9 mm) and fit the test position above 90 %."""
    published, _ = runs["published"]
    rmse, result = runs["symmetric"]
    _, q = _raw("test.csv")
    spread = 1000 * float(np.std(q[20:]))  # 82.66 mm (BENCHMARKS.md)
    assert result.converged
    assert rmse < published
    assert rmse < 0.1 * spread
    p = result.values
    # the simulation-error fit near the published IDIM-LS (force-error) fit: M 95.1, Fv 203.5, Fc 20.4, off -3.16
    assert p["M"] == pytest.approx(95.11, rel=0.1)
    assert p["Fv"] == pytest.approx(203.5, rel=0.15)
    assert p["Fc"] == pytest.approx(20.39, rel=0.2)
    assert p["offset"] == pytest.approx(-3.165, abs=1.0)


def test_asymmetric_viscous_friction_is_found_and_lowers_the_test_error(runs):
    """Fv- > Fv+ as published (240.4 vs 166.7 N s/m, each within the fit's own 95 % interval), and the
    asymmetric chart lowers the test RMSE by at least 10 % (6.9 -> 5.7 mm measured) and beats the published
    asymmetric parameters run the same way."""
    rmse_sym, _ = runs["symmetric"]
    published, _ = runs["published asymmetric"]
    rmse, result = runs["asymmetric"]
    assert result.converged
    assert rmse < 0.9 * rmse_sym
    assert rmse < published
    fvp, fvm = result.parameters["Fvp"], result.parameters["Fvm"]
    assert fvm.value - fvp.value > 40
    assert fvp.ci95[0] < 166.7 < fvp.ci95[1] and fvm.ci95[0] < 240.4 < fvm.ci95[1]


def test_diagnose_from_the_viscous_only_chart_adds_friction_at_the_speed(runs):
    """Issue 16's before/after: one round of diagnose from the chart without Coulomb friction and offset, on
    train.csv alone (its validation: the last 30 % of train), accepts friction at the speed; refitted on all of
    train.csv it cuts the protocol's test RMSE by more than 10x and does at least as well as the hand-written
    asymmetric chart (88.1 -> 3.42 mm measured with a learned curve, the effect's option chosen since the
    trainer's geodesic steps; 5.70 mm before, with the physical `coulomb` option, which is then exactly that
    chart: Fv + dFv = Fvp, Fv = Fvm)."""
    ex = _example()
    train, test = ex.records()
    viscous = ex.viscous_only(sd.load_chart(ex.CHART))
    before, _ = ex.protocol(viscous, train, test)
    d = sd.diagnose(viscous, train, rounds=1)
    first = d.report["accepted"][0]
    assert (first["effect"], first["at"]) == ("friction", "v")
    after, result = ex.protocol(d.diagram, train, test)
    assert after < before / 10
    rmse_asym, asym = runs["asymmetric"]
    assert after <= 1.02 * rmse_asym
    if first["label"] == "coulomb":
        p, q = result.values, asym.values
        assert p["Fv"] + p["dFv_v"] == pytest.approx(q["Fvp"], rel=0.02)
        assert p["Fv"] == pytest.approx(q["Fvm"], rel=0.02)
