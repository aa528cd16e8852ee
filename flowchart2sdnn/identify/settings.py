"""One home for the trainer's settings: identify's, with their defaults, validated in library words.

The command line maps its flags onto these names (``--max-iter`` -> ``max_iter``); a bad value raises ValueError
naming the setting. The first Levenberg-Marquardt damping has one default per use, here, with the reason.

Layer: identify (imports nothing of ours).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["IdentifySettings", "IDENTIFY_TAU", "REFIT_TAU", "ONLINE_TAU", "MIN_REL_COST_CHANGE",
           "CONVERGED_DECREASE"]

#: First LM damping mu = tau * max diag(JᵀJ) (Madsen-Nielsen-Tingleff) for a fit from a chart's rough `init`:
#: with trainlm's fixed 1e-3 a single start from the paper's Table 1 reached J1 in 2 of 5 seeds, with this 5/5.
IDENTIFY_TAU = 1e-3
#: ... and trainlm's fixed first damping (tau = 0) for diagnose's brief refits, which start next to a fit, where
#: the scaled damping spends their few iterations on short steps (backlash bench: validation RMS down 3.2x with
#: 0, 2.2x with 1e-3).
REFIT_TAU = 0.0
#: ... and tau = 1 for the quasi-online window's iterations: with it (and 2 tries, blocks of 500 samples) the
#: window mode met the paper experiment's acceptance from three of its four starts (docs/paper_experiment.md).
#: trainlm's own first damping (mu0 = 1e-3) lives with the schedule, in fit/damping.py.
ONLINE_TAU = 1.0
#: An LM iteration that gains less than this fraction of the cost ends the fit: further ones only polish noise.
MIN_REL_COST_CHANGE = 1e-10
#: A fit has converged when its last 10 iterations together lowered the cost E by less than this many times
#: E/N (N residuals): a change of the cost is told from noise from about E/N on
#: (one unit of -2 log-likelihood = N dE/E), so 0.01 means "1 % of what the data could ever show".
CONVERGED_DECREASE = 0.01


def _need(ok: bool, text: str) -> None:
    if not ok:
        raise ValueError(text)


@dataclass(frozen=True)
class IdentifySettings:
    """How :func:`~flowchart2sdnn.identify.run.identify` fits.

    Attributes
    ----------
    starts : int             multi-start: the chart's `init` and starts-1 seeded draws within the bounds
    seed : int               seed of the draws (and of learned curves' initial weights)
    max_iter : int           LM iterations per start (offline): a safety limit; fits stop on convergence
    alignment : str          "zoh" (input sample k acts on [t_k, t_k+1)) or "direct"
    split : float or None    fit on this leading fraction of the record, validate on the whole
    online : bool            quasi-online (sliding window) instead of offline
    window, average, every, online_start : int   quasi-online window Q, samples averaged K, step every N
                             samples, first sample
    fixed_from : tuple of str  names fixed from an earlier result (reported only)
    ranges : {name: (lo, hi)}  where to draw starts, per parameter (default: the bounds)
    lm_tau : float           first LM damping factor (see :data:`IDENTIFY_TAU`); 0 gives trainlm's fixed 1e-3
    converged_decrease : float  converged when 10 iterations together gain less than this many times E/N
                             (see :data:`CONVERGED_DECREASE`); 0 runs to ``max_iter``
    """

    starts: int = 1
    seed: int = 0
    max_iter: int = 1000
    alignment: str = "zoh"
    split: float | None = None
    online: bool = False
    window: int = 25000
    average: int = 25000
    every: int = 1
    online_start: int = 0
    fixed_from: tuple[str, ...] = ()
    ranges: dict = field(default_factory=dict)
    lm_tau: float = IDENTIFY_TAU
    converged_decrease: float = CONVERGED_DECREASE

    def __post_init__(self):
        _need(self.starts >= 1, f"starts must be at least 1, got {self.starts}")
        _need(self.max_iter >= 0, f"max_iter must not be negative, got {self.max_iter}")
        _need(self.alignment in ("zoh", "direct"), f"alignment must be 'zoh' or 'direct', got {self.alignment!r}")
        _need(self.split is None or 0 < self.split < 1, f"split must lie strictly between 0 and 1, got {self.split}")
        _need(self.window >= 2, f"window must be at least 2, got {self.window}")
        _need(self.average >= 1 and self.every >= 1, "average and every must be at least 1")
        _need(self.online_start >= 0, f"online_start must not be negative, got {self.online_start}")
        _need(0 <= self.converged_decrease < 1e6 and math.isfinite(self.converged_decrease),
              f"converged_decrease must be a finite number >= 0, got {self.converged_decrease}")
        _need(self.lm_tau >= 0 and math.isfinite(self.lm_tau), f"lm_tau must be a finite number >= 0, got {self.lm_tau}")
