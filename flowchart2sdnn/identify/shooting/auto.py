"""``--shooting auto``: the segment length from how far a free run of the chart stays predictable on the record.

Why not the modes at rest. The sub-steps' auto reads the network's eigenvalues at rest; for shooting those do
not tell the charts that single shooting cannot fit from the ones it can. On the two-mass drive (the issue's
bench, J1 0.19, J2 0.38, c 477, d 0.24) the shaft mode at rest (the network's eigenvalues, N = 1) is 61 rad/s
with a 0.97 s memory, 59 rad of phase before it forgets, and single shooting fits its 30 s record from rough
starts (8 of 8, docs/rough_init.md); the same drive with motor cogging (0.4 sin 6 phi1) adds a 2.0 rad/s mode
with a 23 s memory (47 rad, less), yet single shooting from a 20 % rough init stays stuck (validation 20x the
noise, benchmarks/bench_chaotic.py); with shaft backlash the shaft is slack at rest (no oscillatory mode at
all, one undamped), and a free run at the truth misses the 30 s record by 12x the noise. What decides is how an
error of the state grows *along the record*: a finite-time Lyapunov growth, not a rest mode.

The rule. The chart at its `init` is run over every training record from the record's own initial state, and
again once per integrator state with that state's start moved by DELTA times the state's RMS over the run. The
amplification a(t) is the largest deviation of any state at t, in units of its own RMS, divided by DELTA. A
stable drive forgets the moved start (a(t) stays of order 1: over the test suite's 161 fits on records longer
than 100 samples its peak had median 1.0, 95th percentile 3.9, largest 8.0, and 12 on the backlash chart (N = 1) at its
rough init, where a moved speed shows in the small shaft twist); a chaotic one amplifies it exponentially. The
predictable horizon H is the first sample where a(t) reaches GROWTH_BOUND:

* a(t) < GROWTH_BOUND on every record: ``off`` (a free run follows the record; single shooting, unchanged);
* otherwise the growth is exponential, a(t) ~ exp(lambda t) with lambda = ln(GROWTH_BOUND) / H (a finite-time
  Lyapunov exponent), and one Lyapunov time H / ln(GROWTH_BOUND) samples, over which a start's error grows
  e-fold; ``off`` when that is not shorter than the longest record. Else the first stage's L is SHORTER times
  shorter, raised to the fewest samples that keep MAX_SEGMENTS segments, and the measured states start free
  (identify.settings.SHOOTING_STARTS "auto"). Why shorter: the rough chart's growth is not the truth's (the
  backlash bench's rough chart, N = 6: one Lyapunov time 1118 samples on seed 1's record, and single shooting
  from there ended at 13x the noise, 0.361/0.181 on the validation; from 118 with free starts the kept stage
  is at the noise, 0.0110/0.0110), and the merging stages find the predictable length from the data.
* after ``off``, :func:`second_look`: single shooting that ends off the noise floor on a chart whose growth
  exceeded SUSPECT_PEAK is tried again with multiple shooting (the probe said off on 6 of 8 of the backlash
  bench's records, where the truth is chaotic).

GROWTH_BOUND = 1000: a thousandfold growth of a start's error is well beyond the non-normal transients of the
stable charts (at most 12 measured, see above), and L depends on it only through the estimate of lambda.

Layer: identify (below it: network).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ... import rules
from ..assess.noise import NOISE_MARGIN, noise_cost
from ..offline.initstate import state_neurons
from ..offline.problem import Problem
from .multiple import GROWTH, stage_lengths
from .segmented import MAX_SEGMENTS

__all__ = ["ShootingChoice", "choose_shooting", "amplification", "GROWTH_BOUND", "DELTA", "SHORTER", "SUSPECT_PEAK",
           "second_look", "chaotic_at"]

#: A start's error grown this many times (in units of each state's RMS) ends the predictable horizon.
GROWTH_BOUND = rules.value("growth_bound")
#: The first stage is this many times shorter than one Lyapunov time of the chart at its `init` (two merges,
#: GROWTH ** 2): the rough chart's growth is not the truth's (module docstring), and the merging stages find the
#: predictable length from the data (identify.shooting.multiple's refusal rule).
SHORTER = GROWTH * GROWTH
#: auto's second look (:func:`second_look`) is for charts whose probe grew a moved start more than this: beyond
#: the stable charts' 95th percentile (3.9 over the test suite's fits; module docstring).
SUSPECT_PEAK = rules.value("suspect_peak")
#: The moved start: this many times the state's RMS (small enough to stay linear up to GROWTH_BOUND).
DELTA = rules.value("probe_delta")


@dataclass(frozen=True)
class ShootingChoice:
    """What ``--shooting auto`` chose and why (RESULT.json ``shooting.auto``)."""

    length: int | None  # None: off
    horizon: int | None  # samples until a start's error grew GROWTH_BOUND-fold (None: never on these records)
    peak: float  # the largest amplification met
    longest: int  # the longest training record, samples
    reason: str
    lyapunov: int | None = None  # one Lyapunov time of the chart at its init, samples (None: no growth found)
    second_look: dict | None = None  # after `off`: the multiple-shooting retry (:func:`second_look`), if any

    def to_dict(self) -> dict:
        return {"chose": self.length if self.length is not None else "off", "horizon_samples": self.horizon,
                "peak_amplification": self.peak if np.isfinite(self.peak) else None,  # None: it overflowed
                "growth_bound": GROWTH_BOUND, "longest_record": self.longest,
                "lyapunov_samples": self.lyapunov, "reason": self.reason,
                **({"second_look": self.second_look} if self.second_look is not None else {})}


def amplification(compiled, theta: np.ndarray, inputs: np.ndarray, init=None) -> np.ndarray:
    """a(t), (Q,): the largest growth of a moved start over the run (see the module docstring)."""
    ks = np.array([k for k, _ in state_neurons(compiled)], dtype=np.int64)
    if not len(ks):
        return np.zeros(len(inputs))
    n_out = compiled.n_outputs
    base = compiled.initial_history(init)
    with np.errstate(all="ignore"):
        ref = compiled.simulate(theta, inputs, history=base, states=ks)[:, n_out:]
        rms = np.sqrt(np.mean(ref ** 2, axis=0))
        rms = np.where(np.isfinite(rms) & (rms > 0), rms, 1.0)
        out = np.zeros(len(inputs))
        for j, k in enumerate(ks):
            h = base.copy()
            h[k] += DELTA * rms[j]
            run = compiled.simulate(theta, inputs, history=h, states=ks)[:, n_out:]
            a = np.max(np.abs(run - ref) / rms, axis=1) / DELTA
            out = np.maximum(out, np.where(np.isfinite(a), a, np.inf))
    return out


def choose_shooting(problem: Problem, theta: np.ndarray) -> ShootingChoice:
    """The segment length of ``--shooting auto`` for `problem` at `theta` (the chart's init)."""
    longest = max(len(s.inputs) for s in problem.segments)
    horizon, peak = None, 0.0
    if problem.compiled.estimates_starts or problem.record_params:  # shooting refuses them (FIT006)
        return ShootingChoice(None, None, 0.0, longest, "estimated initial states or per-record parameters: "
                              "multiple shooting does not combine with them yet, single shooting")
    for s in problem.segments:
        a = amplification(problem.compiled, theta, s.inputs, s.init)
        peak = max(peak, float(np.max(a)) if len(a) else 0.0)
        over = np.flatnonzero(a >= GROWTH_BOUND)
        if len(over):
            horizon = int(over[0]) if horizon is None else min(horizon, int(over[0]))
    if horizon is None:
        return ShootingChoice(None, None, peak, longest,
                              f"a free run forgets a moved start (largest growth {peak:.3g} < {GROWTH_BOUND:g}): "
                              "single shooting follows the records")
    total = sum(len(s.inputs) for s in problem.segments)
    fewest = -(-total // MAX_SEGMENTS)
    lyapunov = int(horizon / np.log(GROWTH_BOUND))
    why = (f"a moved start grows {GROWTH_BOUND:g}-fold after {horizon} samples")
    if not stage_lengths(max(2, lyapunov, fewest), longest):
        return ShootingChoice(None, horizon, peak, longest,
                              why + f", not shorter than the longest record ({longest} samples): single shooting",
                              lyapunov)
    length = max(2, lyapunov // SHORTER, fewest)
    why += (f" (one Lyapunov time: {horizon} / ln {GROWTH_BOUND:g} = {lyapunov}); the first stage "
            f"{SHORTER}x shorter, {lyapunov // SHORTER}")
    if length > lyapunov // SHORTER:
        why += f", raised to {length} to keep at most {MAX_SEGMENTS} segments"
    return ShootingChoice(length, horizon, peak, longest, why + f": segments of {length} samples, merged while "
                          "predictable", lyapunov)


def second_look(problem: Problem, choice: ShootingChoice | None, cost: float) -> int | None:
    """After auto chose ``off``: the segment length to fit again with multiple shooting, or None.

    The probe reads the chart at its rough `init`, and a rough chart need not be chaotic where the truth is: on
    the backlash bench (benchmarks/bench_chaotic.py, N = 6) the rough chart grew a moved start 4056-6688-fold on
    the 30 s records of seeds 1 and 3 but only 5.9-153-fold on seeds 5-15 (the truth: 9e6 at N = 1), and single
    shooting from it ends in a local minimum at 27x the noise (seed 5). So when single shooting (`cost`, 0.5 sum
    of squares) ends off the noise floor (its residual RMS more than NOISE_MARGIN times the noise estimated from
    the records' second differences, the refusal rule's floor) on a chart whose probe grew more than
    SUSPECT_PEAK, the fit is tried again from the `init` in segments of the shortest length that keeps
    MAX_SEGMENTS (the merging stages find the predictable length). The caller keeps it when it costs less per
    sample and, if its result is a segmented stage (a longer one refused), the chart at that stage's fit is
    chaotic by the probe's own rule (:func:`chaotic_at`): a wrong initial state also spoils the longer stages
    of a chart that forgets its start (tests/test_init_estimate.py's untwisted shaft: growth 8.0, single
    shooting 6.8x the noise, the 8-sample stage kept), and that is not chaos. Charts at the floor, and those
    whose probe stays with the stable ones, are left as they were.
    """
    if choice is None or choice.length is not None or not choice.peak > SUSPECT_PEAK:
        return None
    if problem.compiled.estimates_starts or problem.record_params:  # shooting refuses them (FIT006)
        return None
    m = sum(s.targets.size for s in problem.segments)
    if not cost / max(1, m) > noise_cost(problem, NOISE_MARGIN):
        return None
    total = sum(len(s.inputs) for s in problem.segments)
    length = max(2, -(-total // MAX_SEGMENTS))
    return length if stage_lengths(length, choice.longest) else None


def chaotic_at(problem: Problem, theta: np.ndarray) -> bool:
    """Whether a moved start grows GROWTH_BOUND-fold within the records at `theta` (auto's probe)."""
    return choose_shooting(problem, theta).horizon is not None
