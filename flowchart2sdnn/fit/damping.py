"""The Levenberg-Marquardt damping schedule (MATLAB ``trainlm``), one definition for every trainer.

Plain scalar functions on floats, written in the subset of Python that numba compiles: the offline trainer
(:mod:`.lm`) calls them as they are, the quasi-online kernel (:mod:`flowchart2sdnn.identify.online.kernel`)
compiles the same functions with ``numba.njit``. So fit/ stays free of numba and both trainers move mu alike.

* accepted trial: ``mu = max(mu * mu_dec, mu_min)`` (``mu_min`` keeps mu from underflowing, so that a later
  refusal can raise it back within a few tries);
* refused trial: ``mu = min(mu * mu_inc, cap)``; the offline trainer passes no cap (it stops once mu exceeds
  ``mu_max``), the quasi-online run caps at ``mu_max`` (it never stops);
* Nielsen's schedule (the offline trainer's ``damping="nielsen"``; H. B. Nielsen, *Damping parameter in
  Marquardt's method*, IMM-REP-1999-05; Madsen, Nielsen & Tingleff 2004, eq. 2.21): on an accepted trial with
  gain ratio rho (actual over predicted cost decrease) ``mu *= max(1/3, 1 - (2 rho - 1)**3)`` and ``nu = 2``;
  on a refused one ``mu *= nu`` and ``nu *= 2``. mu settles where steps are accepted instead of swinging by
  10x between a refused and an accepted value;
* first damping: ``mu = min(mu_max, max(mu0, tau * max diag(JᵀJ)))`` for ``tau > 0`` (Madsen, Nielsen &
  Tingleff, *Methods for non-linear least squares problems*, 2004, section 3.2), ``mu0`` for ``tau = 0``;
  a non-finite ``max diag(JᵀJ)`` (JᵀJ overflowed near a divergence) gives ``mu_max``.
"""

from __future__ import annotations

import math

from .. import rules

__all__ = ["mu_accepted", "mu_refused", "first_mu", "nielsen_accepted", "nielsen_refused", "TRAINLM_MU0"]

#: trainlm's first damping, every trainer's ``mu0`` unless told otherwise.
TRAINLM_MU0 = rules.value("trainlm_mu0")


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


def nielsen_accepted(mu: float, rho: float, mu_min: float) -> float:
    """mu after an accepted trial whose gain ratio (actual / predicted decrease) is `rho`: Nielsen's update."""
    factor = 1.0 - (2.0 * rho - 1.0) ** 3 if rho < 1.0 else 0.0  # a rho above 1 gives the largest cut, 1/3
    return max(mu * max(1.0 / 3.0, factor), mu_min)


def nielsen_refused(mu: float, nu: float, cap: float) -> tuple[float, float]:
    """(mu, nu) after a refused trial: mu grows by nu, and nu doubles (refusals in a row raise mu ever faster)."""
    return min(mu * nu, cap), 2.0 * nu
