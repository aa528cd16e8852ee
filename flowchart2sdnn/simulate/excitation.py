"""The virtual test bench: the paper's excitation (section 6.1) applied to a chart simulated in continuous time.

The excited input is an APRBS (levels uniform in ``amplitude``, hold times uniform in ``hold``) plus the
bias of a digital hysteresis relay on the measured speed, which keeps a globally integrating plant in a
bounded range and, scaled down near zero speed, gives the fit more data around the friction's zero
crossing. Every number of the paper is an option of :class:`ExcitationSettings`.

Reproducibility: one ``numpy.random.Generator`` seeded with ``settings.seed`` draws, in this order,

1. the APRBS, segment by segment: the level (``uniform(*amplitude)``), then the hold length in samples
   (``integers(lo, hi + 1)``, see :func:`aprbs`), until the segments cover all samples;
2. the measurement noise, ``noise_std * standard_normal((Q, n_outputs))``, column j for output j (drawn
   even when ``noise_std`` is 0, so changing the noise level never changes the input).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..diagram.model import Diagram, NonlinearWeights
from .continuous import RelayFeedback, simulate_continuous

__all__ = ["ExcitationSettings", "aprbs", "excite"]


@dataclass(frozen=True)
class ExcitationSettings:
    """Options of the excitation; the defaults are the paper's (torque in Nm, speed in rad/s, times in s).

    `input` is the excited chart input (default: the first); every other input is zero. `speed` is the
    signal the relay measures (default: the first output). The relay is described in
    :class:`~flowchart2sdnn.simulate.continuous.RelayFeedback`; ``relay_level = 0`` switches it off.
    """

    seconds: float
    seed: int = 0
    amplitude: tuple[float, float] = (-7.0, 7.0)
    hold: tuple[float, float] = (0.010, 0.250)
    relay_level: float = 4.0
    relay_switch: float = 10.0
    relay_band: float = 2.0
    relay_band_scale: float = 0.2
    noise_std: float = 0.0
    input: str | None = None
    speed: str | None = None

    def __post_init__(self) -> None:
        def need(ok: bool, text: str) -> None:
            if not ok:
                raise ValueError(text)

        finite = all(math.isfinite(float(v)) for v in (self.seconds, self.noise_std, self.relay_level,
                                                        self.relay_switch, self.relay_band, self.relay_band_scale,
                                                        *self.amplitude, *self.hold))
        need(finite, "every excitation setting must be a finite number")
        need(self.seconds > 0, f"`seconds` must be > 0, got {self.seconds}")
        need(self.noise_std >= 0, f"`noise_std` must be >= 0, got {self.noise_std}")
        need(len(self.amplitude) == 2 and self.amplitude[0] <= self.amplitude[1],
             f"`amplitude` must be (low, high) with low <= high, got {tuple(self.amplitude)}")
        need(len(self.hold) == 2 and 0 <= self.hold[0] <= self.hold[1],
             f"`hold` must be 0 <= min <= max, got {tuple(self.hold)}")
        need(self.relay_switch >= 0 and self.relay_band >= 0,
             f"`relay_switch` and `relay_band` must be >= 0, got {self.relay_switch} and {self.relay_band}")


def _hold_range(sample_time: float, hold: tuple[float, float]) -> tuple[int, int]:
    lo_s, hi_s = (float(h) for h in hold)
    if not (0 <= lo_s <= hi_s) or not math.isfinite(hi_s):
        raise ValueError(f"`hold` must be 0 <= min <= max, got {hold}")
    # the range in whole samples that lies inside [lo_s, hi_s] (tolerant to float round-off)
    lo = max(1, math.ceil(lo_s / sample_time - 1e-9))
    hi = math.floor(hi_s / sample_time + 1e-9)
    if hi < lo:
        raise ValueError(f"`hold` {hold} s contains no whole number of samples of {sample_time} s")
    return lo, hi


def aprbs(
    n_samples: int,
    sample_time: float,
    rng: np.random.Generator,
    amplitude: tuple[float, float] = (-7.0, 7.0),
    hold: tuple[float, float] = (0.010, 0.250),
) -> np.ndarray:
    """An amplitude-modulated pseudo-random binary sequence (APRBS).

    Parameters
    ----------
    n_samples : int
        Length of the signal.
    sample_time : float
        Sample time in s.
    rng : numpy.random.Generator
        Source of randomness; per segment it draws the level, then the hold length.
    amplitude : (low, high)
        Levels are uniform in ``[low, high)``.
    hold : (min, max)
        Hold times in s. Lengths are uniform over the whole numbers of samples whose duration lies in
        ``[min, max]`` (at least one sample); the last segment is cut at `n_samples`.

    Returns
    -------
    ndarray, shape (n_samples,)
    """
    if n_samples < 0:
        raise ValueError(f"`n_samples` must be >= 0, got {n_samples}")
    if not sample_time > 0:
        raise ValueError(f"`sample_time` must be > 0, got {sample_time}")
    low, high = (float(a) for a in amplitude)
    if not low <= high:
        raise ValueError(f"`amplitude` must be (low, high) with low <= high, got {amplitude}")
    lo, hi = _hold_range(sample_time, hold)
    out = np.empty(int(n_samples))
    k = 0
    while k < n_samples:
        level = rng.uniform(low, high)
        length = int(rng.integers(lo, hi + 1))
        out[k:k + length] = level
        k += length
    return out


def excite(
    diagram: Diagram,
    settings: ExcitationSettings,
    parameters: Mapping[str, float] | None = None,
    substeps: int = 20,
    *,
    init: Mapping[str, float] | None = None,
    nonlinear: Mapping[str, NonlinearWeights] | None = None,
) -> dict[str, np.ndarray]:
    """Excite a chart as the paper does and log it: APRBS plus relay bias in, noisy outputs out.

    Parameters
    ----------
    diagram : Diagram
        The plant chart (its nonlinear blocks need weights, or pass `nonlinear`).
    settings : ExcitationSettings
        Length, seed, APRBS, relay and noise options.
    parameters, init, nonlinear, substeps
        As in :func:`~flowchart2sdnn.simulate.continuous.simulate_continuous`.

    Returns
    -------
    dict of name -> ndarray (Q,)
        ``"time"`` (``k * sample_time``), then every chart input (the applied values: APRBS plus relay
        on the excited input, zeros elsewhere), then every output with measurement noise, in chart order,
        with ``Q = round(seconds / sample_time)``. The relay acts on the same noisy speed that is logged.
    """
    s = settings
    T = float(diagram.sample_time)
    if not T > 0:
        raise ValueError(f"sample_time must be > 0, got {diagram.sample_time}")
    if not diagram.inputs or not diagram.outputs:
        raise ValueError("the chart needs at least one input and one output to be excited")
    q = int(round(s.seconds / T))
    if q < 1:
        raise ValueError(f"`seconds` = {s.seconds} is shorter than one sample of {T} s")
    if s.noise_std < 0:
        raise ValueError(f"`noise_std` must be >= 0, got {s.noise_std}")
    name_in = s.input if s.input is not None else diagram.input_names[0]
    if name_in not in diagram.input_names:
        raise ValueError(f"excited input '{name_in}' is not a chart input ({', '.join(diagram.input_names)})")
    speed = s.speed if s.speed is not None else diagram.output_names[0]

    rng = np.random.default_rng(s.seed)
    u = np.zeros((q, len(diagram.inputs)))
    u[:, diagram.input_names.index(name_in)] = aprbs(q, T, rng, s.amplitude, s.hold)
    noise = s.noise_std * rng.standard_normal((q, len(diagram.outputs)))
    seen = noise[:, diagram.output_names.index(speed)] if speed in diagram.output_names else None
    relay = RelayFeedback(input=name_in, measured=speed, level=s.relay_level, switch=s.relay_switch,
                          band=s.relay_band, band_scale=s.relay_band_scale, noise=seen)
    sig = simulate_continuous(diagram, u, parameters=parameters, init=init, substeps=substeps, signals=True,
                              nonlinear=nonlinear, controller=relay)
    data = {"time": np.arange(q) * T}
    for name in diagram.input_names:
        data[name] = sig[name]
    for j, name in enumerate(diagram.output_names):
        data[name] = sig[name] + noise[:, j]
    return data
