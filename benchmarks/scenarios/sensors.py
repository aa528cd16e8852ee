"""What the sensors make of the oracle's clean outputs: white or coloured noise, or a quantised encoder.

* ``white``: Gaussian, std = ``fraction`` x the clean output's range (max - min), ``fraction`` 0.3-3 %;
* ``ar``: the same std, coloured by an AR(1) filter ``e_k = a e_k-1 + sqrt(1 - a^2) eps_k`` (stationary, so
  its std is that of eps), ``a`` 0.5-0.95;
* ``encoder``: each angle is quantised to ``2 pi / counts`` (with an unknown zero inside one count), a position
  output is that quantised angle, a speed output is the difference quotient of its quantised angle
  ``(q_k - q_k-1) / T`` (``0`` at ``k = 0``, where the plant is at rest): a speed averaged over the last
  sample, i.e. half a sample late, as a drive's speed estimate is.

Then the sensor-stage missing effects: a zero offset (``measured = physical + o``) and a range limit (the reading
clipped at ``+-L``, L a fraction of the clean output's largest |value|), in that order.

A Sensor draws its noise from its own seed on every call, so measuring twice gives the same noise: the
closed loop and the relay are simulated once more with the noise the logged output carries (draw.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter

from .plants import log_uniform

__all__ = ["SENSORS", "Sensor", "draw_sensor", "quantise", "difference_quotient"]

SENSORS = ("white", "ar", "encoder")


@dataclass(frozen=True)
class Sensor:
    kind: str
    seed: int
    fraction: float = 0.0  # white, ar: std / range
    ar: float = 0.0  # ar: the AR(1) coefficient
    counts: int = 0  # encoder: counts per revolution
    zero: float = 0.0  # encoder: the zero's position inside one count, in counts
    offsets: Mapping[str, float] = field(default_factory=dict)  # sensor_offset: output -> o
    limits: Mapping[str, float] = field(default_factory=dict)  # sensor_limit: output -> fraction of max |clean|

    def as_dict(self) -> dict:
        return {"kind": self.kind, "seed": self.seed, "fraction": self.fraction, "ar": self.ar,
                "counts": self.counts, "zero": self.zero, "offsets": dict(self.offsets), "limits": dict(self.limits)}

    def measure(self, clean: Mapping[str, np.ndarray], outputs: tuple[str, ...], sample_time: float,
                angles: Mapping[str, np.ndarray], ranges: Mapping[str, tuple[float, float]]) -> dict[str, np.ndarray]:
        """The logged outputs. `angles[y]` is the angle an encoder reads for output y (y itself for a position);
        `ranges[y]` = (max - min, max |value|) of the clean output, which sizes the noise and the limits."""
        rng = np.random.default_rng(self.seed)
        out = {}
        for y in outputs:
            spread, peak = ranges[y]
            if self.kind == "encoder":
                q = quantise(angles[y], self.counts, self.zero)
                value = q if y.startswith("phi") else difference_quotient(q, sample_time)
            else:
                eps = rng.standard_normal(len(clean[y]))
                if self.kind == "ar":
                    eps = lfilter([math.sqrt(1 - self.ar**2)], [1.0, -self.ar], eps,
                                  zi=[self.ar * eps[0]])[0]
                value = clean[y] + self.fraction * spread * eps
            value = value + self.offsets.get(y, 0.0)
            if y in self.limits:
                limit = self.limits[y] * peak
                value = np.clip(value, -limit, limit)
            out[y] = value
        return out


def quantise(angle: np.ndarray, counts: int, zero: float = 0.0) -> np.ndarray:
    """The angle an incremental encoder of `counts` per revolution reports (floor to a whole count)."""
    step = 2 * math.pi / counts
    return step * np.floor(np.asarray(angle) / step + zero)


def difference_quotient(angle: np.ndarray, sample_time: float) -> np.ndarray:
    out = np.zeros(len(angle))
    out[1:] = np.diff(angle) / sample_time
    return out


def draw_sensor(rng: np.random.Generator, kind: str | None = None) -> Sensor:
    """A sensor kind (uniform unless given) and its numbers; the noise seed comes from `rng` too."""
    kind = kind or SENSORS[int(rng.integers(0, len(SENSORS)))]
    seed = int(rng.integers(0, 2**31))
    if kind == "encoder":
        # 2^12 (a plain incremental encoder) .. 2^20 counts (an interpolated sin/cos one)
        counts = int(round(2 ** rng.uniform(12, 20)))
        return Sensor(kind, seed, counts=counts, zero=float(rng.uniform()))
    fraction = log_uniform(rng, 0.003, 0.03)
    a = float(rng.uniform(0.5, 0.95)) if kind == "ar" else 0.0
    if kind not in SENSORS:
        raise ValueError(f"unknown sensor {kind!r}; one of {', '.join(SENSORS)}")
    return Sensor(kind, seed, fraction=fraction, ar=a)
