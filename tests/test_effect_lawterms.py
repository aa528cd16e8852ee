"""The linear_term and input_offset effects (flowchart2sdnn.diagnose.lawterms): the patched chart against
scipy's solution of the ODE it should be, neutral at its start values, offered where it belongs, and
linear_term and input_offset found by diagnose on virtual benches (a laminar share of the lower outflow, a pump
that delivers only above 0.3 V)."""

from __future__ import annotations

import numpy as np
import pytest
from diagnose_bench import chart, record
from scipy.integrate import solve_ivp

from flowchart2sdnn.diagnose.effects import BUILTIN_EFFECTS, InputOffset, LinearTerm
from flowchart2sdnn.diagnose.loop import DiagnoseSettings, diagnose
from flowchart2sdnn.simulate.continuous import simulate_continuous

K1, K3, K4, X10 = 0.6, 0.32, 0.8, 2.0  # tests/data/diagnose/tanks.yaml


def _u(n: int = 60) -> np.ndarray:
    t = np.arange(n)
    return (1.0 + 0.5 * np.sin(0.2 * t))[:, None]


def _scipy_tanks(u: np.ndarray, y0: float, lin1: float = 0.0, lin2: float = 0.0, offset: float = 0.0):
    """The two-tank ODE with the effects written out, zero-order-hold input, sampled at T = 1 s."""
    x, out = np.array([X10, y0]), [y0]
    for k in range(len(u) - 1):
        def f(_t, s, uk=u[k, 0]):
            q1 = K1 * np.sqrt(s[0]) + lin1 * s[0]
            return [K4 * (uk + offset) - q1, q1 - K3 * np.sqrt(s[1]) - lin2 * s[1]]
        x = solve_ivp(f, (0.0, 1.0), x, rtol=1e-10, atol=1e-12).y[:, -1]
        out.append(x[1])
    return np.array(out)


def _at(effect, diagram, name):
    return next(p for p in effect.places(diagram) if p.at == name)


@pytest.mark.parametrize("law, c1, c2", [("r1", 0.05, 0.0), ("r2", 0.0, 0.08)])
def test_linear_term_is_the_ode_with_k_sqrt_x_plus_c_x(law, c1, c2):
    tanks = chart("tanks")
    patched = LinearTerm().patch(tanks, _at(LinearTerm(), tanks, law))
    u = _u()
    got = simulate_continuous(patched, u, parameters={f"{law}_lin": c1 or c2}, init={"y": 1.5}, substeps=40)[:, 0]
    assert got == pytest.approx(_scipy_tanks(u, 1.5, c1, c2), abs=1e-6)
    neutral = simulate_continuous(patched, u, init={"y": 1.5}, substeps=40)[:, 0]
    assert neutral == pytest.approx(simulate_continuous(tanks, u, init={"y": 1.5}, substeps=40)[:, 0], abs=1e-12)


def test_input_offset_is_the_ode_with_u_plus_o():
    tanks = chart("tanks")
    patched = InputOffset().patch(tanks, _at(InputOffset(), tanks, "u"))
    u = _u()
    got = simulate_continuous(patched, u, parameters={"u_zero": -0.3}, init={"y": 1.5}, substeps=40)[:, 0]
    assert got == pytest.approx(_scipy_tanks(u, 1.5, offset=-0.3), abs=1e-6)
    assert patched.parameter("u_zero").init == 0.0


def test_places_are_power_laws_and_inputs_only():
    tanks = chart("tanks")
    assert [p.at for p in LinearTerm().places(tanks)] == ["r1", "r2"]
    assert [p.via for p in LinearTerm().places(tanks)] == ["x1", "y"]
    ovf = BUILTIN_EFFECTS["overflow"]
    clipped = ovf.patch(tanks, ovf.places(tanks)[0], ovf.options(tanks, ovf.places(tanks)[0], _scales())[0])
    assert [p.at for p in LinearTerm().places(clipped)] == ["r1", "r2"]  # not the overflow's sat block
    assert [p.at for p in InputOffset().places(tanks)] == ["u"]
    assert {"linear_term", "input_offset"} <= set(BUILTIN_EFFECTS)


def _scales():
    from flowchart2sdnn.diagnose.effects import Scales
    return Scales(lo={"x1dev": 0.0}, hi={"x1dev": 4.0})


def _first_round(plant_name: str) -> tuple[dict, dict]:
    """diagnose's first round (one round) on the tanks chart against `plant_name`'s records, and the final values."""
    plant = chart(plant_name)
    settings = {"amplitude": (0.0, 2.0), "hold": (20.0, 80.0), "relay_level": 0.0}
    train, val = record(plant, 1200.0, 1, 0.01, **settings), record(plant, 600.0, 2, 0.01, **settings)
    r = diagnose(chart("tanks"), train, [val], DiagnoseSettings(rounds=1)).report
    return r["rounds"][0], {k: v["value"] for k, v in r["final"]["parameters"].items()}


def test_diagnose_finds_the_laminar_share_of_the_lower_outflow():
    first, p = _first_round("tanks_laminar_plant")
    assert first["accepted"] and (first["effect"], first["at"]) == ("linear_term", "r2"), first
    assert first["validation_rms_after"] < first["validation_rms_before"] / 10
    # measured: r2_lin 0.094, k1 -3.3 %, k3 -5.0 %, k4 -5.4 % (the y start is the first noisy sample), RMS 0.405
    # -> 0.018 (noise 0.01)
    assert p["r2_lin"] == pytest.approx(0.1, rel=0.1)
    for name, truth in (("k1", 0.5), ("k3", 0.4), ("k4", 1.0)):
        assert p[name] == pytest.approx(truth, rel=0.08)


def test_diagnose_finds_the_pump_zero():
    """Bench: the pump delivers k4 (u - 0.3); the chart's pump k4 u. Measured: u_zero -0.3000, k1 -2.5 %, k3 and
    k4 +1.1 %, validation RMS 0.640 -> 0.025 (noise 0.01)."""
    first, p = _first_round("tanks_pump_zero_plant")
    assert first["accepted"] and (first["effect"], first["at"]) == ("input_offset", "u"), first
    assert first["validation_rms_after"] < first["validation_rms_before"] / 10
    assert p["u_zero"] == pytest.approx(-0.3, rel=0.05)
    for name, truth in (("k1", 0.5), ("k3", 0.4), ("k4", 1.0)):
        assert p[name] == pytest.approx(truth, rel=0.05)
