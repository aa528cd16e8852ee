"""One home for the trainer's settings: identify's, with their defaults, validated in library words.

The command line maps its flags onto these names (``--max-iter`` -> ``max_iter``); a bad value raises ValueError
naming the setting. The first Levenberg-Marquardt damping has one default per use, here, with the reason.

Layer: identify (imports only the rule book, flowchart2sdnn.rules, where its numbers live).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .. import rules

__all__ = ["IdentifySettings", "SHOOTING", "SHOOTING_STARTS", "IDENTIFY_TAU", "REFIT_TAU", "ONLINE_TAU", "MIN_REL_COST_CHANGE",
           "CONVERGED_DECREASE", "NEGLIGIBLE_GAIN", "NEGLIGIBLE_PACE", "PACE_ITERATIONS", "HELD_CHATTER", "IDENTIFY_SCALE", "IDENTIFY_DAMPING", "LM_DAMPING", "LM_BOUNDS", "FLOOR_BIAS", "CURVE_START"]

#: First LM damping mu = tau * max diag(JᵀJ) (Madsen-Nielsen-Tingleff) for a fit from a chart's rough `init`:
#: with trainlm's fixed 1e-3 a single start from the paper's Table 1 reached J1 in 2 of 5 seeds, with this 5/5.
IDENTIFY_TAU = rules.value("identify_tau")
#: ... and trainlm's fixed first damping (tau = 0) for diagnose's brief refits, which start next to a fit, where
#: the scaled damping spends their few iterations on short steps (backlash bench: validation RMS down 3.2x with
#: 0, 2.2x with 1e-3).
REFIT_TAU = rules.value("refit_tau")
#: ... and tau = 1 for the quasi-online window's iterations: with it (and 2 tries, blocks of 500 samples) the
#: window mode met the paper experiment's acceptance from three of its four starts (docs/paper_experiment.md).
#: trainlm's own first damping (mu0 = 1e-3) lives with the schedule, in fit/damping.py.
ONLINE_TAU = rules.value("online_tau")
#: LM damps each quantity by its own curvature, (JᵀJ + mu D²) with D the Jacobian's column norms (fit.lm,
#: MINPACK's and scipy's x_scale='jac'), instead of trainlm's mu I: with mu I a stiffness of ~500 N·m/rad and an
#: inertia of ~0.4 kg·m² share one damping and rough starts crawl (benchmarks/bench_rough_init.py, 10 s bench:
#: 167-668 iterations and 2 of 3 rough starts at the minimum with mu I, 22-27 iterations and 3 of 3 with D²).
IDENTIFY_SCALE = "jac"
#: ... and bends each step along the cost's valley (geodesic acceleration, fit.lm.LMOptions.geodesic: one extra
#: simulation per step, refused when the bend exceeds this fraction of the step, Transtrum & Sethna's 0.75).
#: A learned friction curve's weights and the damping d lie along a narrow curved valley where plain steps are cut
#: back to a crawl (benchmarks/bench_rough_init.py, learned chart, docs/rough_init.md).
IDENTIFY_GEODESIC = rules.value("identify_geodesic")
#: LM moves its damping by Nielsen's rule (fit.damping: mu *= max(1/3, 1 - (2 rho - 1)^3) on an accepted step with gain
#: ratio rho, x2, x4, ... on refusals in a row) instead of trainlm's x0.1 / x10, which near a minimum swings between a
#: refused and an accepted mu every iteration (benchmarks/bench_rough_init.py, coulomb: 16 refused trials in 23
#: iterations with trainlm's, 7 in 21 with Nielsen's), with the first trial of an iteration simulated with its
#: Jacobian (fit.lm.LMOptions.trial_jacobian; it pays only where refusals are rare). Not where learned curves are
#: fitted: there trainlm's schedule stays (and residual-only trials). Nielsen's descends further along the learned
#: chart's valley (seed-1 bench: costs 1.116-1.117 against 1.120-1.121) but then the stall rule does not stop it
#: within 1000 iterations (3 of 8 draws at the limit against none).
IDENTIFY_DAMPING = "nielsen"
#: IdentifySettings.lm_damping's default: "auto" is IDENTIFY_DAMPING where no learned curve is fitted and the
#: bounds are kept by the transform, "trust" (a trust radius) where they are kept in the box (LM_BOUNDS), trainlm's
#: where learned curves are fitted. diagnose's refits keep "trainlm": its brief refits (tens of iterations from next to a fit) and its
#: benches were measured with it, and with Nielsen's slower cut of mu (/3 at most, not /10) the tanks bench's first
#: round credited a saturation of u instead of the upper tank's overflow (tests/test_diagnose_overflow.py).
LM_DAMPING = "auto"
#: IdentifySettings.lm_bounds's default: "auto" handles the bounds without a transform ("box": plain steps in the
#: physical, column-scaled coordinates held inside the bounds, fit.boxstep; their length set by a trust radius,
#: fit.lm damping "trust", as scipy's trf does) where no learned curve is fitted, by the transform of
#: fit.transforms elsewhere: a learned curve starts flat, so the physical parameters may first have to move by
#: decades (the engine example from Table 1's J1 = 0.01, 19x below the machine: the box's trust radius collapsed
#: at J1 0.010, the transform's log-like coordinates reach 0.191), and free-slope curves' valley needs the
#: geodesic steps measured with it. Coulomb bench
#: (benchmarks/bench_rough_init.py, 30 s, 8 rough draws, one run): 0.88x scipy trf's seconds per draw (median 16
#: iterations), the transform's geodesic steps 1.95x (22); same minima, every draw converged (docs/rough_init.md).
LM_BOUNDS = "auto"
#: An LM iteration that gains less than this fraction of the cost ends the fit: further ones only polish noise.
MIN_REL_COST_CHANGE = rules.value("min_rel_cost_change")
#: A fit has converged when its last 10 iterations together lowered the cost E by less than this many times
#: E/N (N residuals): a change of the cost is told from noise from about E/N on
#: (one unit of -2 log-likelihood = N dE/E), so 0.01 means "1 % of what the data could ever show".
CONVERGED_DECREASE = rules.value("converged_decrease")
#: ... and, once the residual RMS is within CRAWL_NOISE of the noise read off the records' second differences
#: (identify.assess.noise.noise_level), when its last CRAWL_ITERATIONS iterations together lowered E by less than
#: CRAWL_DECREASE times E/N: one unit of -2 log-likelihood in 100 iterations. A fit at the noise floor that
#: still creeps is moving along a direction the data barely determine; the three-mass learned chart's draw 9
#: (benchmarks/bench_rough_init.py, 10 s, seed 1) crept 0.3-0.7 E/N per 100 iterations from iteration 300 to
#: 1750 (b3 and a curve's slope traded, b3's standard error 6x its value), and a run to 3000 iterations in other
#: coordinates was still creeping (docs/rough_init.md, "The crawl at the noise floor").
CRAWL_DECREASE = rules.value("crawl_decrease")
CRAWL_ITERATIONS = rules.value("crawl_iterations")
CRAWL_NOISE = rules.value("crawl_noise")
#: A fit has converged, wherever it is (at the noise floor or far above it, a chart that lacks an effect), when the
#: undamped Gauss-Newton step would lower -2 log-likelihood by less than this many units at the residual's own
#: variance and the last step gained less too (fit.lm.LMOptions.negligible_gain): the remaining move is then
#: within sqrt(0.1) = 0.32 standard errors in every direction, which moves a 95 % interval's coverage by about
#: one point.
NEGLIGIBLE_GAIN = rules.value("negligible_gain")
#: ... or when its last 10 iterations together gained less than one unit (a descent held by a bound, the stability
#: guard or the trust radius, which the unconstrained Gauss-Newton step does not see): at that pace forty more
#: iterations would not reach the 3.84 units a test at the 5 % level needs. Units count the residual's effective
#: samples (fit.effective): a residual that is mostly a missing effect holds far fewer than its length.
NEGLIGIBLE_PACE = rules.value("negligible_pace")
PACE_ITERATIONS = rules.value("pace_iterations")
#: With `substeps: auto` (N read from the modes at the chart's init, compiler.substeps) a fit whose network's own
#: step error against the continuous chart exceeds the floor warning's share of the residual (identify.assess.floor.
#: FLOOR_WARN) is refitted from its values at 4x N (up to the cap): the learned friction the data gave the chart is
#: stiffer than its flat init, and the warning would otherwise name the sub-steps auto should have taken.
#: So is a fit whose network, linearized at rest, has an alternating mode (a negative eigenvalue, 1 - s h/J
#: for a friction slope s) that keeps more than this share of its amplitude a step: the continuous chart's mode
#: decays without alternating, so that mode is the explicit step's, and the curve's slope is held near the step's
#: limit 2J/h (the guard's chatter radius 1) by the scheme rather than by the data.
HELD_CHATTER = rules.value("held_chatter")
#: An offline fit whose training residual RMS exceeds this many times the noise read off the records' second
#: differences says so (a missing effect or a local minimum; issue 14): the benches' complete charts end within
#: 4x the noise even at the paper's one step per sample, the cut diagnose's second look uses too (5x). The
#: three-mass learned chart's 30 s draw 3 ended "converged" at 18 000x the minimum's cost before identify's own
#: second look moved it (docs/rough_init.md).
FAR_ABOVE_NOISE = rules.value("far_above_noise")
#: identify's (and batch's) multiple shooting by default: "auto" (identify.shooting.auto) is off wherever a free run of
#: the chart at its `init` forgets a moved start. The whole test suite with auto as the default, first run: 580
#: fits, a length chosen in 64 (62 fuzz charts of 39 samples whose start diverges within a sample, the start
#: that grows like (1 + T g/J)^k in tests/test_identify_hardening.py, now pinned to off, and one 1199-sample
#: fit), 3 tests failed (that one, test_shooting's "no key when off", and an inf in RESULT.json, fixed); the
#: probe cost 5.4 s of 466 s (4.3 s one compile). Final run: 1509 passed, 360 fits, 10 lengths (fuzz charts),
#: probe 1.6 s of 458 s. diagnose keeps "off" (diagnose.fitting.DiagnoseSettings): its acceptance and benches
#: were measured single shooting.
SHOOTING = "auto"
#: where multiple shooting's segments start the measured states: "data" (the sample before the segment, the
#: default) or "free" (fitted like the unmeasured ones, starting from that sample). Measured on the backlash
#: bench (README, Multiple shooting): a noisy sample as a start keeps short segments off the noise floor (the
#: truth's 200 stage 1.4x the noise with "data", 1.0x with "free"). "auto" (the default): "free" where `shooting`
#: "auto" chose a length (a chaotic record, whose short segments' starts the noise would spoil; the backlash
#: bench's default run 0.0110/0.0110 on the 3 s validation with it), "data" otherwise (an L given by hand keeps
#: what it was measured with)
SHOOTING_STARTS = "auto"
#: identify estimates the discretization's bias on each parameter and widens ci95 by it (identify.assess.floorbias): with
#: 0.01 rad/s noise (Coulomb benches, auto N, seeds 1-10) the noise-only intervals covered the truth 8 in 10 times
#: for 13 of 21 parameters (three-mass c1 3 of 10), the widened ones for 21 of 21, at x1.24-1.33 the fit's time
#: (benchmarks/bench_floor_acceptance.py).
FLOOR_BIAS = True
#: Learned curves in a feedback loop start as a stick-slip step at 0.3 of the slope the network's step allows,
#: a log grid for the other neurons, three brief fits and the step re-sloped (identify.offline.curvestart): on the
#: two-mass learned-curve bench (10 s, 20 rough draws x/3) single starts from the chart's random +-0.5 weights
#: reached the lowest minimum 0 of 20 times, from this start 20 of 20 (docs/rough_init.md). "random": the chart's
#: seeded weights.
CURVE_START = "stick"


def _need(ok: bool, text: str) -> None:
    if not ok:
        raise ValueError(text)


@dataclass(frozen=True)
class IdentifySettings:
    """How :func:`~flowchart2sdnn.identify.offline.run.identify` fits.

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
    lm_scale : str           "jac": damping scaled per quantity by the Jacobian's column norms (see
                             :data:`IDENTIFY_SCALE`); "none": trainlm's mu I
    lm_geodesic : float      geodesic acceleration's largest bend (see :data:`IDENTIFY_GEODESIC`); 0: plain steps
    lm_damping : str         LM's damping schedule: "auto" (see :data:`LM_DAMPING`; "trust" where lm_bounds resolves
                             to "box"), "nielsen" (Nielsen's, with the first trial of each iteration simulated with
                             its Jacobian), "trainlm" (x0.1 / x10) or "trust" (a trust radius sets each step's length)
    lm_bounds : str          how LM keeps the bounds: "auto" (see :data:`LM_BOUNDS`), "transform" (a change of
                             variables, fit.transforms) or "box" (plain steps held inside them; lm_geodesic unused)
    converged_decrease : float  converged when 10 iterations together gain less than this many times E/N
                             (see :data:`CONVERGED_DECREASE`); 0 runs to ``max_iter``
    init_window : int        > 0: the validation record's initial state is fitted on its first init_window
                             samples (parameters fixed), the free run scored from that row on (identify.offline.initstate)
    shooting : "off", "auto" or int  an int L >= 2: multiple shooting first, segments of L samples merged (x4)
                             until single shooting over whole records, whose fit is the result (identify.shooting.multiple;
                             a merge that raises the cost per sample more than MERGE_RISE is refused and the
                             stage before is the result); "off": single shooting only; "auto": L or off chosen
                             from how fast a moved start grows along the records, with a second look after off
                             when single shooting ends off the noise floor (identify.shooting.auto)
    shooting_starts : str    "auto", "data" or "free": the measured states' start at each segment (:data:`SHOOTING_STARTS`)
    threads : int            threads for multiple shooting's segments within one fit in this process (the kernels
                             release the GIL); fits in worker processes (an executor) use one
    floor_bias : bool        estimate the discretization's bias beta on each parameter by refitting the network to
                             the continuous oracle's run of the identified chart (identify.assess.floorbias) and widen
                             ci95 by |beta| (see :data:`FLOOR_BIAS`); offline fits only (quasi-online skips it)
    floor : bool             measure the discretization floor on the training records (identify.assess.floor) and,
                             with ``substeps: auto``, refit at a finer N where it shows the step too coarse; False
                             skips both (diagnose's brief refits, which compare training costs only: the continuous
                             oracle's run of a 30 s record cost as much as a refit's iterations)
    curve_start : str        "stick": learned curves without stored weights in a feedback loop start from a
                             stick-slip step and a brief fit (identify.offline.curvestart, :data:`CURVE_START`); "random": the
                             chart's seeded +-init_range weights. Offline fits only.
    """

    starts: int = 1
    seed: int = 0
    max_iter: int = rules.value("fit_max_iter")
    alignment: str = "zoh"
    split: float | None = None
    online: bool = False
    window: int = rules.value("online_window")
    average: int = rules.value("online_average")
    every: int = 1
    online_start: int = 0
    fixed_from: tuple[str, ...] = ()
    ranges: dict = field(default_factory=dict)
    lm_tau: float = IDENTIFY_TAU
    lm_scale: str = IDENTIFY_SCALE
    lm_geodesic: float = IDENTIFY_GEODESIC
    lm_damping: str = LM_DAMPING
    lm_bounds: str = LM_BOUNDS
    converged_decrease: float = CONVERGED_DECREASE
    init_window: int = 0
    shooting: str | int = SHOOTING
    shooting_starts: str = SHOOTING_STARTS
    floor_bias: bool = FLOOR_BIAS
    floor: bool = True
    threads: int = 1
    curve_start: str = CURVE_START

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
        _need(isinstance(self.init_window, int) and self.init_window >= 0,
              f"init_window must be a whole number >= 0, got {self.init_window!r}")
        _need(not (self.init_window and self.split is not None),
              "init_window applies to a separate validation record, not to split (the validation part of a split "
              "continues the training run's state)")
        _need(self.shooting in ("off", "auto") or (isinstance(self.shooting, int) and not isinstance(self.shooting, bool)
                                          and self.shooting >= 2),
              f"shooting must be 'off', 'auto' or a segment length of at least 2 samples, got {self.shooting!r}")
        _need(self.shooting_starts in ("auto", "data", "free"),
              f"shooting_starts must be 'auto', 'data' or 'free', got {self.shooting_starts!r}")
        _need(not (self.online and self.shooting not in ("off", "auto")),  # auto: off for the window
              "shooting applies to offline fits, not to the quasi-online window")
        _need(isinstance(self.threads, int) and not isinstance(self.threads, bool) and self.threads >= 1,
              f"threads must be a whole number >= 1, got {self.threads!r}")
        _need(self.curve_start in ("stick", "random"),
              f"curve_start must be 'stick' or 'random', got {self.curve_start!r}")
        _need(self.lm_scale in ("jac", "none"), f"lm_scale must be 'jac' or 'none', got {self.lm_scale!r}")
        _need(0 <= self.lm_geodesic < 2, f"lm_geodesic must be in [0, 2), got {self.lm_geodesic}")
        _need(self.lm_damping in ("auto", "nielsen", "trainlm", "trust"),
              f"lm_damping must be 'auto', 'nielsen', 'trainlm' or 'trust', got {self.lm_damping!r}")
        _need(self.lm_bounds in ("auto", "transform", "box"),
              f"lm_bounds must be 'auto', 'transform' or 'box', got {self.lm_bounds!r}")
        _need(self.lm_tau >= 0 and math.isfinite(self.lm_tau), f"lm_tau must be a finite number >= 0, got {self.lm_tau}")
