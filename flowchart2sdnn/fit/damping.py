"""The Levenberg-Marquardt damping schedule (MATLAB ``trainlm``), one definition for every trainer.

Plain scalar functions on floats, written in the subset of Python that numba compiles: the offline trainer
(:mod:`.lm`) calls them as they are, the quasi-online kernel (:mod:`flowchart2sdnn.identify.online_kernel`)
compiles the same functions with ``numba.njit``. So fit/ stays free of numba and both trainers move mu alike.

* accepted trial: ``mu = max(mu * mu_dec, mu_min)`` (``mu_min`` keeps mu from underflowing, so that a later
  refusal can raise it back within a few tries);
* refused trial: ``mu = min(mu * mu_inc, cap)``; the offline trainer passes no cap (it stops once mu exceeds
  ``mu_max``), the quasi-online run caps at ``mu_max`` (it never stops);
* first damping: ``mu = min(mu_max, max(mu0, tau * max diag(JᵀJ)))`` for ``tau > 0`` (Madsen, Nielsen &
  Tingleff, *Methods for non-linear least squares problems*, 2004, section 3.2), ``mu0`` for ``tau = 0``;
  a non-finite ``max diag(JᵀJ)`` (JᵀJ overflowed near a divergence) gives ``mu_max``.
"""

from __future__ import annotations

import math

__all__ = ["mu_accepted", "mu_refused", "first_mu", "TRAINLM_MU0"]

#: trainlm's first damping, every trainer's ``mu0`` unless told otherwise.
TRAINLM_MU0 = 1e-3


def mu_accepted(mu: float, mu_dec: float, mu_min: float) -> float:
    """mu after an accepted trial."""
    return max(mu * mu_dec, mu_min)


def mu_refused(mu: float, mu_inc: float, cap: float) -> float:
    """mu after a refused (or diverged) trial, at most `cap` (``math.inf`` for none)."""
    return min(mu * mu_inc, cap)


def first_mu(peak: float, mu0: float, tau: float, mu_max: float) -> float:
    """The first damping from ``peak = max diag(JᵀJ)`` in the trainer's internal coordinates."""
    if not tau > 0.0:
        return mu0
    if not math.isfinite(peak):
        return mu_max
    return min(mu_max, max(mu0, tau * peak))
