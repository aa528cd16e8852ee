"""A mass on a hardening spring driven by a smooth input, simulated in continuous time by scipy (solve_ivp,
tight tolerances): the independent oracle of the intersample, fractional-delay and noise-estimate tests.

    m x'' + d x' + k x + k3 x^3 = u(t - tau)

u is a multisine plus low-pass noise, both sums of sinusoids, so u(t) exists between the samples and
u(t - tau) is exact for any dead time tau. With T = 10 ms and k / m = (2 pi 10 Hz)^2 the resonance has
10 samples per period (the issue's real record had about 9).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

T = 0.01
#: the input's band (Hz): linear interpolation at 10 ms misses a line of f Hz by about (2 pi f T)^2 / 12 of
#: itself in the step means (0.3 % at 3 Hz), so the band stays well below the 10 Hz resonance
BAND = 2.5
SCALE = 3000.0
RAMP = 0.5
TRUE = {"m": 1.0, "k": (2 * np.pi * 10.0) ** 2, "d": 2 * 0.05 * 2 * np.pi * 10.0, "k3": 1200.0}

CHART = """\
sdnn: 1
name: hardening_spring
sample_time: 0.01
{extra}inputs:
  u: {{unit: N{input_keys}}}
outputs:
  x: {{unit: m}}
parameters:
  m: {{init: 1.0, unit: kg, fixed: true}}
  k: {{init: {k:.6g}, unit: N/m, min: 0}}
  d: {{init: {d:.6g}, unit: N*s/m, min: 0}}
  k3: {{init: {k3:.6g}, unit: N/m^3, min: 0}}
{more_parameters}blocks:
  F:  {{type: sum, in: [u, -Fk, -Fd, -Fc], unit: N}}
  a:  {{type: gain, in: F, k: 1/m}}
  v:  {{type: integrator, in: a, unit: m/s}}
  x:  {{type: integrator, in: v, unit: m}}
  Fk: {{type: gain, in: x, k: k}}
  Fd: {{type: gain, in: v, k: d}}
  Fc: {{type: product, in: [x, x, x], k: k3}}
"""


def chart_text(start: float = 1.1, input_keys: str = "", extra: str = "", more_parameters: str = "") -> str:
    """The chart, its free parameters started at `start` x the truth."""
    return CHART.format(k=TRUE["k"] * start, d=TRUE["d"] * start, k3=TRUE["k3"] * start, input_keys=input_keys,
                        extra=extra, more_parameters=more_parameters)


def smooth_input(seed: int = 0, scale: float = SCALE, band: float = BAND):
    """u(t): a multisine (5 lines up to `band` Hz) plus low-pass noise (40 random lines below it, amplitude
    falling with frequency), scaled so that x has an RMS of about 1 m."""
    rng = np.random.default_rng(seed)
    noise_f = rng.uniform(0.1, band, 40)
    f = np.concatenate([band * np.array([0.25, 0.45, 0.65, 0.85, 1.0]), noise_f])
    a = np.concatenate([np.full(5, 0.25), 0.15 * np.exp(-noise_f / band)])
    ph = rng.uniform(0, 2 * np.pi, len(f))

    def u(t):
        t = np.asarray(t, dtype=float)
        # faded in from 0 over the first RAMP s: a record that starts at rest, whatever the dead time
        ramp = np.where(t <= 0, 0.0, np.where(t < RAMP, 0.5 * (1 - np.cos(np.pi * t / RAMP)), 1.0))
        return scale * ramp * np.sum(a[:, None] * np.sin(2 * np.pi * f[:, None] * t.ravel()[None, :] + ph[:, None]),
                                     axis=0).reshape(t.shape)

    return u


def record(n: int = 3000, seed: int = 0, noise: float = 1e-3, tau: float = 0.0, params=None, band: float = BAND,
           scale: float = SCALE):
    """(t, u samples, x samples with noise, noise sigma): the oracle sampled every T, the input sampled at t_k
    (the delay acts inside the plant); `noise` is relative to the RMS of x."""
    p = {**TRUE, **(params or {})}
    u = smooth_input(seed, scale, band)

    def rhs(t, s):
        x, v = s
        return [v, (u(t - tau) - p["d"] * v - p["k"] * x - p["k3"] * x ** 3) / p["m"]]

    t = np.arange(n) * T
    sol = solve_ivp(rhs, (0.0, t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-12)
    x = sol.y[0]
    sigma = noise * float(np.sqrt(np.mean(x ** 2)))
    rng = np.random.default_rng(seed + 1000)
    return t, u(t), x + sigma * rng.standard_normal(n), sigma


def write(path, t, u, x) -> None:
    np.savetxt(path, np.column_stack([t, u, x]), delimiter=",", header="time,u,x", comments="", fmt="%.12g")
