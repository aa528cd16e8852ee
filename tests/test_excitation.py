"""The virtual test bench: APRBS statistics, the relay against a pure-Python closed loop, the noise."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from continuous_charts import block, chart, integrator_plant, two_mass

from flowchart2sdnn.simulate.continuous import simulate_continuous
from flowchart2sdnn.simulate.excitation import ExcitationSettings, aprbs, excite


def runs(x):
    """(levels, lengths) of the constant runs of x."""
    edges = np.flatnonzero(np.diff(x) != 0) + 1
    starts = np.concatenate([[0], edges])
    return x[starts], np.diff(np.concatenate([starts, [len(x)]]))


def test_aprbs_levels_and_hold_times():
    T = 1e-3
    x = aprbs(200_000, T, np.random.default_rng(11), amplitude=(-7.0, 7.0), hold=(0.010, 0.250))
    levels, lengths = runs(x)
    assert levels.min() >= -7.0 and levels.max() < 7.0
    assert levels.min() < -6.5 and levels.max() > 6.5  # the range is used
    assert abs(levels.mean()) < 0.6  # uniform on [-7, 7): std of the mean ~ 4 / sqrt(1500)
    inner = lengths[:-1]  # the last run is cut at the end
    assert inner.min() >= 10 and inner.max() <= 250
    assert inner.min() <= 12 and inner.max() >= 248
    assert abs(inner.mean() - 130) < 8  # uniform on 10..250 samples
    assert lengths[-1] <= 250


def test_aprbs_hold_in_whole_samples_and_seeds():
    T = 0.004
    x = aprbs(5000, T, np.random.default_rng(3), amplitude=(1.0, 2.0), hold=(0.010, 0.030))
    _, lengths = runs(x)
    assert set(lengths[:-1]) <= {3, 4, 5, 6, 7}  # 0.012 .. 0.028 s
    assert np.all((x >= 1.0) & (x < 2.0))
    again = aprbs(5000, T, np.random.default_rng(3), amplitude=(1.0, 2.0), hold=(0.010, 0.030))
    np.testing.assert_array_equal(x, again)
    other = aprbs(5000, T, np.random.default_rng(4), amplitude=(1.0, 2.0), hold=(0.010, 0.030))
    assert np.mean(x != other) > 0.9


def test_aprbs_errors():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="whole number of samples"):
        aprbs(10, 0.01, rng, hold=(0.012, 0.018))
    with pytest.raises(ValueError, match="amplitude"):
        aprbs(10, 0.01, rng, amplitude=(1.0, -1.0))
    assert aprbs(0, 0.01, rng).shape == (0,)


def relay_closed_loop(a, measured_noise, T, level, switch, band, scale):
    """The relay rule on speed = integral of u, written from the paper's text, sample by sample."""
    speed, state = 0.0, level
    us, speeds = [], []
    for k in range(len(a)):
        y = speed + measured_noise[k]
        if y > switch:
            state = -level
        elif y < -switch:
            state = level
        r = state * scale if abs(y) < band else state
        us.append(a[k] + r)
        speeds.append(speed)
        speed += T * us[-1]  # exact for a held input
    return np.array(us), np.array(speeds)


def test_relay_on_an_integrator_plant_sample_by_sample():
    T = 1e-3
    s = ExcitationSettings(seconds=20.0, seed=5, amplitude=(-1.0, 1.0), hold=(0.01, 0.1), relay_level=4.0,
                           relay_switch=3.0, relay_band=1.0, relay_band_scale=0.25, noise_std=0.05)
    data = excite(integrator_plant(T), s)
    assert list(data) == ["time", "u", "speed"]
    q = 20_000
    np.testing.assert_allclose(data["time"], np.arange(q) * T)
    rng = np.random.default_rng(5)  # the documented draw order: the APRBS, then the noise
    a = aprbs(q, T, rng, (-1.0, 1.0), (0.01, 0.1))
    noise = 0.05 * rng.standard_normal((q, 1))[:, 0]
    u, clean = relay_closed_loop(a, noise, T, 4.0, 3.0, 1.0, 0.25)
    np.testing.assert_allclose(data["u"], u, atol=1e-9)
    np.testing.assert_allclose(data["speed"], clean + noise, atol=1e-9)  # the relay saw the logged speed
    relay = data["u"] - a
    # the rule really fired both ways and the band scaled it
    assert {4.0, -4.0, 1.0, -1.0} <= set(np.round(relay, 9))
    assert np.max(np.abs(clean)) < 3.0 + 5.0 * T * 20  # the relay bounds the integrating plant


def test_relay_without_noise_matches_python_loop_exactly():
    T = 1e-3
    s = ExcitationSettings(seconds=8.0, seed=9, amplitude=(-2.0, 2.0), relay_level=3.0, relay_switch=1.5,
                           relay_band=0.5, relay_band_scale=0.2)
    data = excite(integrator_plant(T), s)
    a = aprbs(8000, T, np.random.default_rng(9), (-2.0, 2.0), (0.010, 0.250))
    u, speed = relay_closed_loop(a, np.zeros(8000), T, 3.0, 1.5, 0.5, 0.2)
    np.testing.assert_allclose(data["u"], u, atol=1e-12)
    np.testing.assert_allclose(data["speed"], speed, atol=1e-9)
    assert np.sum(np.abs(np.diff(np.sign(u - a))) > 0) >= 2  # the relay switched


def test_measurement_noise_std_and_reproducibility():
    T = 1e-3
    plant = chart(["u", "v"], ["y", "z"], [
        block("y", "integrator", "e", init=0.0),
        block("e", "sum", "u", "-y"),
        block("z", "gain", "y", k="2"),
        block("vv", "gain", "v", k="1"),
    ], sample_time=T)
    s = ExcitationSettings(seconds=20.0, seed=2, amplitude=(-1.0, 1.0), relay_level=0.0, noise_std=0.1)
    data = excite(plant, s)
    np.testing.assert_array_equal(data["v"], 0.0)  # inputs other than the excited one are zero
    clean = simulate_continuous(plant, np.column_stack([data["u"], data["v"]]))
    noise = np.column_stack([data["y"], data["z"]]) - clean
    assert np.all(np.abs(noise.std(axis=0) - 0.1) < 0.003)  # std of the std ~ 0.1 / sqrt(2 * 20000)
    assert np.all(np.abs(noise.mean(axis=0)) < 0.003)
    assert abs(np.corrcoef(noise.T)[0, 1]) < 0.03
    again = excite(plant, s)
    for key in data:
        np.testing.assert_array_equal(data[key], again[key])
    quiet = excite(plant, dataclasses.replace(s, noise_std=0.0))
    np.testing.assert_array_equal(quiet["u"], data["u"])  # the noise level never changes the input
    np.testing.assert_allclose(quiet["y"], clean[:, 0], atol=1e-12)


def test_two_mass_bench_runs_with_paper_defaults():
    data = excite(two_mass(), ExcitationSettings(seconds=1.0, seed=1))
    assert list(data) == ["time", "M1", "w2", "w1"]
    assert all(v.shape == (1000,) and np.all(np.isfinite(v)) for v in data.values())
    a = aprbs(1000, 1e-3, np.random.default_rng(1))
    relay = data["M1"] - a
    # the speed starts inside the band, so the relay starts at 0.2 * 4
    assert relay[0] == pytest.approx(0.8)
    assert set(np.round(relay, 9)) <= {4.0, -4.0, 0.8, -0.8}


def test_excite_errors():
    plant = integrator_plant()
    with pytest.raises(ValueError, match="not a chart input"):
        excite(plant, ExcitationSettings(seconds=1.0, input="torque"))
    with pytest.raises(ValueError, match="shorter than one sample"):
        excite(plant, ExcitationSettings(seconds=1e-5))
    with pytest.raises(ValueError, match="noise_std"):
        excite(plant, ExcitationSettings(seconds=1.0, noise_std=-1.0))


@pytest.mark.parametrize("args, code, words", [
    (["--noise", "-1"], 2, "--noise` must be >= 0"),
    (["--amplitude", "5", "-5"], 2, "--amplitude` must be (low, high) with low <= high"),
    (["--hold", "0.5", "0.1"], 2, "--hold` must be 0 <= min <= max"),
    (["--input", "Q"], 2, "'Q' is not an input of"),
    (["--speed", "zz"], 1, "error[EXC001] relay measured signal 'zz' is not a chart signal"),
    (["--hold", "0.0001", "0.0002"], 1, "contains no whole number of samples of 0.001 s"),
])
def test_bad_excitation_options_are_named_errors_not_internal_ones(tmp_path, args, code, words):
    from click.testing import CliRunner

    from flowchart2sdnn.cli import main

    out = tmp_path / "x.csv"
    plant = str(Path(__file__).resolve().parent.parent / "diagrams" / "two_mass_plant.yaml")
    res = CliRunner().invoke(main, ["excite", plant, "--seconds", "0.1", "-o", str(out), *args])
    assert res.exit_code == code, res.output
    assert words in res.output and "internal error" not in res.output and "Traceback" not in res.output
    assert not out.exists()


def test_excitation_settings_refuse_bad_values_in_their_own_words():
    with pytest.raises(ValueError, match="^`noise_std` must be >= 0"):
        ExcitationSettings(seconds=1.0, noise_std=-0.1)
    with pytest.raises(ValueError, match="finite"):
        ExcitationSettings(seconds=float("nan"))
