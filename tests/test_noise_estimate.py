"""The noise estimate every "x the noise" decision reads (identify.assess.noise.noise_variance / noise_level) on a
smooth record with 10 samples per resonance period: the second difference holds the record's curvature, the
estimate must still find the noise. Oracle: scipy's solve_ivp run of a hardening-spring oscillator with a
smooth input (tests/smooth_oracle.py), white noise of a known sigma added."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import smooth_oracle as so

from flowchart2sdnn.data.csvdata import Dataset
from flowchart2sdnn.identify.assess.noise import noise_level, noise_variance
from flowchart2sdnn.identify.offline.problem import build_problem


@functools.cache
def _smooth(band: float = so.BAND):
    return so.record(n=3000, noise=1e-3, band=band)


def _second_difference_reading(x: np.ndarray) -> float:
    d2 = np.diff(x, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6))


def test_smooth_low_oversampled_record_reads_the_noise_not_the_curvature():
    # the intersample tests' record: input below 2.5 Hz, resonance at 10 Hz = 10 samples per period
    _, _, x, sigma = _smooth()
    assert _second_difference_reading(x) > 5 * sigma  # the old reading: the curvature
    estimate = float(np.sqrt(noise_variance(x[:, None])[0]))
    assert 0.8 * sigma < estimate < 1.3 * sigma


def test_input_up_to_the_resonance_reads_within_a_few_times_the_noise():
    # input lines up to 12 Hz: the hardening spring's harmonics fill every band of the spectrum with signal,
    # so no reading of the record alone finds the bare noise; the old one was 200x off
    _, _, x, sigma = _smooth(12.0)
    assert _second_difference_reading(x) > 100 * sigma
    assert sigma < float(np.sqrt(noise_variance(x[:, None])[0])) < 3 * sigma


def test_fast_sampled_record_keeps_the_second_difference_reading():
    rng = np.random.default_rng(3)
    t = np.arange(20000) * 1e-3
    y = np.sin(2 * np.pi * 0.5 * t) + 0.01 * rng.standard_normal(len(t))
    estimate = float(np.sqrt(noise_variance(y[:, None])[0]))
    assert estimate == pytest.approx(_second_difference_reading(y), rel=1e-12)
    assert estimate == pytest.approx(0.01, rel=0.05)


def test_white_noise_alone_reads_its_sigma():
    y = 0.3 * np.random.default_rng(5).standard_normal((8000, 2))
    assert np.sqrt(noise_variance(y)) == pytest.approx([0.3, 0.3], rel=0.05)


def test_noise_level_of_a_problem_on_the_smooth_record(tmp_path):
    t, u, x, sigma = _smooth()
    chart = tmp_path / "spring.yaml"
    chart.write_text(so.chart_text())
    from flowchart2sdnn.diagram.validate import load_diagram

    data = Dataset(path="smooth", columns={"u": u, "x": x}, time=t, n_rows=len(t), sample_time=so.T,
                   max_step_deviation=0.0, sha256="", source_columns={"u": "u", "x": "x"})
    problem = build_problem(load_diagram(chart), data)
    assert 0.8 * sigma < np.sqrt(noise_level(problem)) < 1.3 * sigma
