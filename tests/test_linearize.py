"""`sdnn linearize` and Identification.linearize against hand formulas, scipy and python-control.

Oracles: the mass-spring-damper's A, B, C and its poles written out by hand; the two-mass drive's mode
omega = sqrt(c (1/J1 + 1/J2)), zeta = d (1/J1 + 1/J2) / (2 omega) from the identified J1, J2, c, d; scipy's
StateSpace.freqresp for the frequency response; python-control's poles (skipped when it is absent).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import signal

from flowchart2sdnn.analysis.linearize import linearize, parse_operating_point
from flowchart2sdnn.analysis.response import empirical_response
from flowchart2sdnn.cli import main
from flowchart2sdnn.data.csvdata import write_csv
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.simulate.excitation import ExcitationSettings, excite

ROOT = Path(__file__).resolve().parents[1]
MSD = ROOT / "diagrams" / "mass_spring_damper.yaml"
m, k, b = 2.0, 800.0, 4.0  # the chart's values


def test_mass_spring_damper_by_hand():
    lin = linearize(load_diagram(MSD))
    assert lin.states == ("v", "x")
    np.testing.assert_allclose(lin.A, [[-b / m, -k / m], [1, 0]], rtol=1e-12)
    np.testing.assert_allclose(lin.B, [[1 / m], [0]], rtol=1e-12)
    np.testing.assert_allclose(lin.C, [[0, 1]])
    np.testing.assert_allclose(lin.D, [[0]])
    (mode,) = lin.damp()
    assert mode["wn"] == pytest.approx(math.sqrt(k / m), rel=1e-12)
    assert mode["zeta"] == pytest.approx(b / (2 * math.sqrt(k * m)), rel=1e-12)
    assert lin.units == {"v": "m/s", "x": "m", "F": "N"}


@pytest.mark.filterwarnings("ignore::scipy.signal.BadCoefficients")  # scipy converts to a transfer function
def test_frequency_response_matches_scipy():
    lin = linearize(load_diagram(MSD))
    f = np.array([0.5, 3.0, 20.0, 80.0])
    _, h = signal.StateSpace(lin.A, lin.B, lin.C, lin.D).freqresp(2 * np.pi * f)
    np.testing.assert_allclose(lin.frequency_response(f)[:, 0, 0], h, rtol=1e-10)


def test_the_welch_estimate_finds_the_resonance(tmp_path):
    """White-ish excitation of the continuous plant: H1 at the resonance within 10 % of the model's."""
    diagram = load_diagram(MSD)
    cols = excite(diagram, ExcitationSettings(seconds=40, seed=2, amplitude=(-50, 50), hold=(0.001, 0.004),
                                              relay_level=0.0))
    lin = linearize(diagram)
    est = empirical_response(cols["F"], cols["x"], diagram.sample_time, "F", "x", nperseg=8192)
    f0 = math.sqrt(k / m) / (2 * math.pi)
    # the flanks (the peak itself is smeared by the segments' frequency resolution)
    near = (est.f > 0.4 * f0) & (est.f < 2.5 * f0) & (np.abs(est.f - f0) > 0.15 * f0)
    model = np.abs(lin.frequency_response(est.f[near])[:, 0, 0])
    assert np.min(est.coherence[near]) > 0.9
    np.testing.assert_allclose(np.abs(est.h[near]), model, rtol=0.1)
    assert abs(est.f[np.argmax(np.abs(est.h))] - f0) < 2 * (est.f[1] - est.f[0])


def test_coulomb_kink_zero_or_smooth():
    chart = load_diagram(ROOT / "diagrams" / "real" / "flexible_drive.yaml")
    p = chart.parameter_values()
    zero = linearize(chart)
    i = zero.states.index("v1")
    assert zero.A[i, i] == pytest.approx(-p["b1"] / p["m1"], rel=1e-12)  # Coulomb leaves the dynamics
    smooth = linearize(chart, kink="smooth")
    eps = 2.0  # the chart's sign_smooth eps
    assert smooth.A[i, i] == pytest.approx(-(p["b1"] + p["d1"] / eps) / p["m1"], rel=1e-12)
    # away from the kink both agree (tanh(v/eps) is flat there)
    moving = {"v1": 200.0, "v2": 200.0}
    np.testing.assert_allclose(linearize(chart, moving).A, linearize(chart, moving, "smooth").A, rtol=1e-9)
    assert any("Coulomb kink 's1'" in n for n in zero.notes)


def test_operating_point_parsing():
    assert parse_operating_point(["w1=0,w2=5", " M1 = -1.5 "]) == {"w1": 0.0, "w2": 5.0, "M1": -1.5}
    for bad in ("w1", "w1=abc", "=3", "w1=nan"):
        with pytest.raises(ValueError, match="NAME=NUMBER"):
            parse_operating_point([bad])
    with pytest.raises(ValueError, match="neither states nor inputs"):
        linearize(load_diagram(MSD), {"q": 1.0})


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """The two-mass bench identified (short record, few iterations: the oracle reads whatever was found)."""
    tmp = tmp_path_factory.mktemp("lin")
    cols = excite(load_diagram(ROOT / "diagrams" / "two_mass_plant.yaml"),
                  ExcitationSettings(seconds=4.0, seed=1, noise_std=0.01))
    write_csv(tmp / "bench.csv", cols, float_format="%.17g")
    # started near the truth so that one short fit finds the flexible mode (the README's stage 2 needs starts)
    chart = (ROOT / "tests" / "data" / "two_mass_euler.yaml").read_text()  # two_mass.yaml at N = 1: quick
    for old, new in (("J2: {init: 0.7", "J2: {init: 0.4"), ("c:  {init: 100", "c:  {init: 450"),
                     ("d:  {init: 0.4", "d:  {init: 0.3")):
        assert old in chart
        chart = chart.replace(old, new)
    (tmp / "two_mass.yaml").write_text(chart)
    res = CliRunner().invoke(main, ["identify", str(tmp / "bench.csv"), "--diagram", str(tmp / "two_mass.yaml"),
                                    "--max-iter", "20", "--quiet", "-o", str(tmp / "r.json")])
    assert res.exit_code == 0, res.output
    return tmp


def test_two_mass_mode_matches_the_hand_formula(identified):
    result = json.loads((identified / "r.json").read_text())
    J1, J2, c, d = (result["parameters"][n]["value"] for n in ("J1", "J2", "c", "d"))

    def slope(curve, w):  # d/dw of sum v tanh(a w), by hand
        a, v = np.array(result["nonlinear"][curve]["a"]), np.array(result["nonlinear"][curve]["v"])
        return float(np.sum(v * a * (1.0 - np.tanh(a * w) ** 2)))

    # at a moving point (at rest the curves hold the drive); the curves' slopes there act as viscous terms
    # (the fit may trade d against them), so the hand model is the chart's equations with both, states w1, w2, phi
    b1, b2 = slope("MR1", 5.0), slope("MR2", 5.0)
    A = np.array([[-(d + b1) / J1, d / J1, -c / J1], [d / J2, -(d + b2) / J2, c / J2], [1.0, -1.0, 0.0]])
    (pole,) = [p for p in np.linalg.eigvals(A) if p.imag > 0]
    wn, zeta = abs(pole), -pole.real / abs(pole)
    res = CliRunner().invoke(main, ["linearize", str(identified / "r.json"), "--at", "w1=5,w2=5",
                                    "--format", "json", "--control", str(identified / "ss.npz")])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # stderr says what was written
    (mode,) = [p for p in doc["damp"] if p["damped_hz"] > 0]
    assert mode["wn"] == pytest.approx(wn, rel=0.01)
    assert mode["damped_hz"] == pytest.approx(wn * math.sqrt(1 - zeta**2) / (2 * math.pi), rel=0.01)
    assert mode["zeta"] == pytest.approx(zeta, abs=0.01)
    saved = np.load(identified / "ss.npz")
    assert list(saved["states"]) == ["w1", "dphi", "w2"] and saved["A"].shape == (3, 3)


def test_python_control_gives_the_same_poles(identified):
    control = pytest.importorskip("control")
    from flowchart2sdnn.identify.document import read_model

    chart, result = read_model(identified / "r.json")
    lin = result.linearize({"w1": 5.0, "w2": 5.0})
    sys = lin.to_control()
    assert isinstance(sys, control.StateSpace)
    np.testing.assert_allclose(np.sort_complex(sys.poles()), np.sort_complex(lin.poles()), rtol=1e-9)
    saved = np.load(identified / "ss.npz")
    loaded = control.ss(saved["A"], saved["B"], saved["C"], saved["D"])
    wn, zeta, _ = control.damp(loaded, doprint=False)
    mode = next(p for p in lin.damp() if p["damped_hz"] > 0)
    assert np.min(np.abs(wn - mode["wn"])) < 1e-9 * mode["wn"]
    assert np.min(np.abs(zeta - mode["zeta"])) < 1e-9


def test_cli_errors(identified, tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["linearize", str(identified / "r.json"), "--at", "w9=1"])
    assert res.exit_code == 2 and "w9" in res.output
    res = runner.invoke(main, ["linearize", str(identified / "r.json"), "--at", "w1=fast"])
    assert res.exit_code == 2
    res = runner.invoke(main, ["linearize", str(ROOT / "diagrams" / "two_mass.yaml")])
    assert res.exit_code == 1 and "LIN002" in res.output and len(res.output.strip().splitlines()) == 1
    res = runner.invoke(main, ["linearize", str(MSD), str(tmp_path / "x.csv")])
    assert res.exit_code == 2  # data without --bode
    pytest.importorskip("matplotlib")
    fig = tmp_path / "bode.png"
    res = runner.invoke(main, ["linearize", str(identified / "r.json"), str(identified / "bench.csv"), "--at",
                               "w1=5,w2=5", "--bode", str(fig)])
    assert res.exit_code == 0, res.output
    assert fig.read_bytes()[:4] == b"\x89PNG" and "damping ratio" in res.output
