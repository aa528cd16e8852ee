"""The score test's significance under the residual's own noise: its spectrum, estimated from the residual.

``2·score/σ²`` is chi-square only for a white residual. A fitted chart's residual never is: sensor noise is
filtered or quantised, the network's step error and an effect the chart lacks are smooth. On a 30 s record at
1 kHz every candidate then reads "significant" (the two-mass drive without its load friction: a cogging
harmonic at p = 1e-180, the right place at 0). Here the variance of a score is computed under a stationary
noise whose spectrum is estimated from the residual itself: the auto- and cross-covariances of the outputs
up to ``noise_lag_window`` of each record, under Bartlett's lag window (whose spectrum is never negative:
the smoothed periodogram), the heteroscedasticity-and-autocorrelation-consistent variance of econometrics.

* The variance of xᵀv for noise v with covariances γ is Σ_ij Σ_l γ_ij(l) Σ_t x_i,t x_j,t+l, computed in the
  frequency domain as Σ_f X(f)ᴴ S(f) X(f) / n_fft (zero-padded past the window: no wrap-around).
* A neutral candidate (new quantities acting through new Jacobian columns): its efficient score
  g = J⊥ᵀe (J⊥: the new columns with the current ones projected out) against Ω = Var(J⊥ᵀv):
  gᵀΩ⁺g is chi-square with rank(Ω) degrees of freedom.
* A candidate that changes the model at once (a scanned dead time, a clip): its score is the total gain
  Σ ½(ê_t² - ê'_t²) of the patched fit ê' = ê - δ; without an effect it fluctuates as Σ ê'_t δ_t:
  z = gain / sqrt(Var(δᵀv)), one-sided normal.
The spectrum is estimated from the residual after the candidate's own step (ê'), so that a strong effect does
not count its own signal as noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.fft import fft, ifft, next_fast_len, rfft
from scipy.linalg import eigh
from scipy.stats import chi2, norm

from .. import rules
from .gauss_newton import RCOND, current_basis

__all__ = ["NOISE_LAG_WINDOW", "Layout", "NoiseSpectrum", "noise_spectrum", "step_residual", "score_test",
           "gain_test"]

#: the covariances are estimated up to this fraction of each record's rows (rules.py)
NOISE_LAG_WINDOW = rules.value("noise_lag_window")


@dataclass(frozen=True)
class Layout:
    """A problem's residual layout: records one after the other, each (rows, outputs) flattened row by row."""

    rows: tuple[int, ...]
    outputs: int

    def records(self, x: np.ndarray):
        """Each record's part of `x` ((M,) or (M, k)) as (rows, outputs, k)."""
        cols = np.asarray(x, dtype=float).reshape(x.shape[0], -1)
        start = 0
        for n in self.rows:
            yield cols[start:start + n * self.outputs].reshape(n, self.outputs, -1)
            start += n * self.outputs

    @property
    def size(self) -> int:
        return sum(self.rows) * self.outputs


@dataclass(frozen=True)
class NoiseSpectrum:
    """Per record: the lag-window estimate S(f) of the noise's spectral matrix at the non-negative frequencies
    (n_fft // 2 + 1, outputs, outputs; the negative ones are its conjugates: the signals are real), and n_fft."""

    layout: Layout
    spectra: tuple[np.ndarray, ...]
    n_fft: tuple[int, ...]

    def covariance(self, x: np.ndarray) -> np.ndarray:
        """Var(xᵀv) of the columns of `x` ((M,) or (M, k)): a (k, k) matrix."""
        out = 0.0
        for block, s, n_fft in zip(self.layout.records(x), self.spectra, self.n_fft, strict=True):
            X = rfft(block, n=n_fft, axis=0)  # (n_fft // 2 + 1, outputs, k)
            # each frequency but 0 (and n_fft / 2) stands for its negative too, whose term is the conjugate
            w = np.full(X.shape[0], 2.0)
            w[0] = 1.0
            if n_fft % 2 == 0:
                w[-1] = 1.0
            for i in range(X.shape[1]):  # Σ_f X_i(f)ᴴ Σ_j S_ij(f) X_j(f), as matrix products
                mixed = np.einsum("fj,fjb->fb", s[:, i, :] * w[:, None], X)
                out = out + (X[:, i, :].conj().T @ mixed).real / n_fft
        return np.atleast_2d(out)


def noise_spectrum(e: np.ndarray, layout: Layout, window: float = NOISE_LAG_WINDOW) -> NoiseSpectrum:
    """The spectrum of `e`'s noise, per record, from its covariances up to `window` x the record's rows."""
    if e.size != layout.size:
        raise ValueError(f"the residual has {e.size} entries, the layout {layout.size}")
    spectra, sizes = [], []
    for block in layout.records(e):
        v = block[:, :, 0] - block[:, :, 0].mean(axis=0)
        n = v.shape[0]
        lags = max(1, min(n - 1, int(round(window * n))))
        n_fft = next_fast_len(n + lags)
        V = fft(v, n=n_fft, axis=0)
        # circ[m, i, j] = (1/n) Σ_t v_i,t v_j,t+l at lag l = m (m < n_fft/2) or m - n_fft: every lag at once
        circ = ifft(V.conj()[:, :, None] * V[:, None, :], axis=0).real / n
        lag = np.minimum(np.arange(n_fft), n_fft - np.arange(n_fft))
        circ *= np.clip(1.0 - lag / lags, 0.0, None)[:, None, None]  # Bartlett: zero from `lags` on
        spectra.append(rfft(circ, axis=0).conj())
        sizes.append(n_fft)
    return NoiseSpectrum(layout, tuple(spectra), tuple(sizes))


def step_residual(X: np.ndarray, e: np.ndarray) -> np.ndarray:
    """The residual after the full (unbounded) Gauss-Newton step: e with its least-squares projection on X's
    columns taken out (directions below RCOND dropped, as in the score: :func:`~.gauss_newton.current_basis`)."""
    basis = current_basis(X)
    return e - basis @ (basis.T @ e)


def score_test(layout: Layout, J_perp: np.ndarray, e: np.ndarray, e_current: np.ndarray
               ) -> tuple[float, int, float]:
    """(statistic, rank, p) of new columns `J_perp` (orthogonal to the current ones) on residual `e`;
    `e_current` is the residual after the current chart's full step, from which the candidate's own step is
    taken before the noise's spectrum is read."""
    noise = noise_spectrum(step_residual(J_perp, e_current), layout)
    g = J_perp.T @ e
    w, V = eigh(noise.covariance(J_perp), check_finite=False)
    if not w.size or not w[-1] > 0:
        return 0.0, 0, 1.0
    keep = w > RCOND * w[-1]
    c = V[:, keep].T @ g
    stat, k = float(np.sum(c * c / w[keep])), int(np.sum(keep))
    return stat, k, float(chi2.sf(stat, k))


def gain_test(layout: Layout, gain: float, e_patched: np.ndarray, change: np.ndarray) -> tuple[float, float]:
    """(z, one-sided p) of a total `gain` of a patched fit whose residual is `e_patched` and that changed the
    residual by `change` (δ = ê - ê')."""
    var = float(noise_spectrum(e_patched, layout).covariance(change)[0, 0])
    if not var > 0:
        return (math.inf, 0.0) if gain > 0 else (0.0, 1.0)
    z = gain / math.sqrt(var)
    return z, float(norm.sf(z))
