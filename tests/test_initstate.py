"""--init-window n: a record's initial state fitted on its first n samples, parameters fixed, then a free run.

Oracles: a continuous plant (RK4) started in motion with a known state, and scipy's least_squares on the same
window residual (its own finite differences); never numbers taken from this code's output.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.optimize import least_squares

import flowchart2sdnn as sd
from flowchart2sdnn.cli import main
from flowchart2sdnn.compiler import compile_diagram
from flowchart2sdnn.diagram.validate import load_diagram
from flowchart2sdnn.errors import SdnnError
from flowchart2sdnn.identify.offline.initstate import estimate_initial_state, state_neurons
from flowchart2sdnn.network.alignment import run_aligned
from flowchart2sdnn.network.runtime import CompiledNetwork
from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import aprbs

ROOT = Path(__file__).resolve().parent.parent
PLANT = ROOT / "diagrams" / "two_mass_coulomb_plant.yaml"
STATE = {"w1": 3.0, "w2": 2.6, "dphi": 0.004}  # a record that starts in motion, the shaft twisted


def _record(q: int, seed: int, noise: float = 0.0, state=STATE):
    plant = load_diagram(PLANT)
    rng = np.random.default_rng(seed)
    u = aprbs(q, plant.sample_time, rng, (-3.0, 3.0))
    y = simulate_continuous(plant, u[:, None], init=state)
    y = y + noise * rng.standard_normal(y.shape)
    frame = {"time": np.arange(q) * plant.sample_time, "M1": u, "w1": y[:, 0], "w2": y[:, 1]}
    return plant, sd.dataset_from_frame(frame, time="time", inputs=["M1"], outputs=["w1", "w2"])


@pytest.fixture(scope="module")
def compiled():
    return CompiledNetwork(compile_diagram(load_diagram(PLANT)).network)


def test_the_states_are_the_integrators(compiled):
    assert sorted(name for _, name in state_neurons(compiled)) == ["dphi", "w1", "w2"]


def test_the_state_of_a_plant_started_in_motion_is_found_from_20_samples(compiled):
    _, data = _record(300, seed=3)
    fit = estimate_initial_state(compiled, compiled.theta0(), data, "zoh", 20)
    assert fit.window == 20 and fit.status in ("small_cost_change", "min_grad", "small_step", "mu_max")
    # the network's discretization floor on this plant is about 3 mrad/s: the state within that
    assert abs(fit.values["w1"] - STATE["w1"]) < 0.01 and abs(fit.values["w2"] - STATE["w2"]) < 0.01
    assert abs(fit.values["dphi"] - STATE["dphi"]) < 2e-4
    # and the free run from it follows the plant far beyond the window (from rest it would not)
    u = np.column_stack([data.columns["M1"]])
    y = np.column_stack([data.columns["w1"], data.columns["w2"]])
    fitted = run_aligned(compiled, compiled.theta0(), u, "zoh", history=fit.history)
    at_rest = run_aligned(compiled, compiled.theta0(), u, "zoh")
    assert np.sqrt(np.mean((fitted[20:] - y[20:]) ** 2)) < 0.01
    assert np.sqrt(np.mean((at_rest[20:] - y[20:]) ** 2)) > 0.3


def test_same_state_as_scipy_least_squares_on_the_window(compiled):
    _, data = _record(300, seed=4, noise=0.01)
    theta = compiled.theta0()
    fit = estimate_initial_state(compiled, theta, data, "zoh", 20)
    u = np.column_stack([data.columns["M1"]])[:20]
    y = np.column_stack([data.columns["w1"], data.columns["w2"]])[:20]
    index = [k for k, _ in state_neurons(compiled)]
    names = [n for _, n in state_neurons(compiled)]

    def res(s):
        h = compiled.initial_history(None)
        h[index] = s
        return (run_aligned(compiled, theta, u, "zoh", history=h) - y).ravel()

    ref = least_squares(res, np.zeros(len(index)), method="trf", x_scale="jac", jac="3-point", xtol=1e-14,
                        ftol=1e-14, gtol=1e-14)
    for i, n in enumerate(names):
        assert fit.values[n] == pytest.approx(ref.x[i], rel=1e-5, abs=1e-8)
    assert fit.cost == pytest.approx(ref.cost, rel=1e-8)
    assert all(fit.stderr[n] is not None and fit.stderr[n] > 0 for n in names)


def test_identify_scores_validation_after_the_window_and_writes_the_state(tmp_path):
    plant, train = _record(1500, seed=5, noise=0.01, state={"w1": 0.0, "w2": 0.0, "dphi": 0.0})
    _, val = _record(800, seed=6, noise=0.01)
    chart = plant  # the exact chart: only the initial state differs between the records
    plain = sd.identify(chart, train, val, max_iter=3)
    windowed = sd.identify(chart, train, val, max_iter=3, init_window=20)
    assert windowed.fit.validation.rows == 800 - 20 and plain.fit.validation.rows == 800 - 1
    assert "first 20 samples" in windowed.fit.validation.note
    assert windowed.fit.validation.rms["w2"] < 0.3 * plain.fit.validation.rms["w2"]
    doc = json.loads(windowed.to_json())
    state = doc["initial_states"]["validation"]
    assert state["window"] == 20 and set(state["values"]) == {"w1", "w2", "dphi"}
    assert abs(state["values"]["w1"] - 3.0) < 0.05
    assert "initial_states" not in json.loads(plain.to_json())


def test_bad_windows_are_refused_in_words(compiled):
    _, data = _record(30, seed=7)
    with pytest.raises(SdnnError, match="window of 40 samples needs at least 40 rows"):
        estimate_initial_state(compiled, compiled.theta0(), data, "zoh", 40)
    with pytest.raises(ValueError, match="init_window applies to a separate validation record"):
        sd.IdentifySettings(split=0.5, init_window=5)
    with pytest.raises(ValueError, match="init_window must be a whole number"):
        sd.IdentifySettings(init_window=-1)


def test_cli_init_window(tmp_path):
    plant, train = _record(1000, seed=8, noise=0.01, state={"w1": 0.0, "w2": 0.0, "dphi": 0.0})
    _, val = _record(400, seed=9, noise=0.01)
    paths = []
    for name, d in (("train.csv", train), ("val.csv", val)):
        p = tmp_path / name
        cols = ["M1", "w1", "w2"]
        np.savetxt(p, np.column_stack([d.time] + [d.columns[c] for c in cols]), delimiter=",",
                   header="time," + ",".join(cols), comments="")
        paths.append(str(p))
    out = tmp_path / "r.json"
    r = CliRunner().invoke(main, ["identify", paths[0], "--diagram", str(PLANT), "--validate", paths[1],
                                  "--init-window", "20", "--max-iter", "2", "--quiet", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert json.loads(out.read_text())["initial_states"]["validation"]["window"] == 20
    r = CliRunner().invoke(main, ["identify", paths[0], "--diagram", str(PLANT), "--init-window", "0"])
    assert r.exit_code == 2
    r = CliRunner().invoke(main, ["identify", paths[0], "--diagram", str(PLANT), "--split", "0.5",
                                  "--init-window", "5"])
    assert r.exit_code == 2 and "--init-window" in r.output
