"""The rule book: every numeric threshold of fit/, identify/ and diagnose/, with its principle, where it acts and
its one default.

A module reads its default from here (``FLOOR_WARN = rules.value("floor_warn")``) and keeps the name it always
had, so callers and tests that reach ``floor.FLOOR_WARN`` see the same number. Two places that apply the same
rule share one entry (``far_above_noise``: identify's warning and diagnose's second look); values that merely
coincide stay apart and say so in ``note`` (``stage_max_iter`` and ``lm_max_iter`` are both 100). A value's
measurements and history stay in the comment beside the name that reads it; here is the principle in one
sentence. ``docs/guide/rules.md`` is this table, generated (tests/test_rules.py keeps it in step).

Layer: the bottom (imports nothing of ours, nor numpy: the command line reads its help texts' defaults here).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["Rule", "RULES", "value", "rule"]


@dataclass(frozen=True)
class Rule:
    """One threshold: ``value`` in ``unit``, why it is that (``principle``), the code it acts in (``where``:
    ``package.module.name``), the command-line flags that show it (``flags``: ``"command --option"``) and, for a
    value equal to another rule's by coincidence, which one (``note``)."""

    name: str
    value: Any
    unit: str
    principle: str
    where: tuple[str, ...]
    flags: tuple[str, ...] = ()
    note: str = ""


def _r(name, value, unit, principle, *where, flags=(), note=""):
    return Rule(name, value, unit, principle, tuple(where), tuple(flags), note)


_BOOK: tuple[Rule, ...] = (
    # --- the generic trainer (fit.lm.LMOptions): trainlm's names and defaults; 0 switches a rule off ---
    _r("lm_max_iter", 100, "iterations", "MATLAB trainlm's iteration limit, the generic trainer's safety stop.",
       "fit.lm.LMOptions.max_iter",
       note="equal to crawl_iterations, stage_max_iter, tracked_window by coincidence"),
    _r("trainlm_mu0", 1e-3, "damping", "trainlm's first damping: a Gauss-Newton step slightly shortened.",
       "fit.damping.TRAINLM_MU0", "fit.lm.LMOptions.mu0",
       note="equal to identify_tau, initstate_tau by coincidence"),
    _r("lm_mu_inc", 10.0, "factor", "trainlm's schedule: a refused step raises the damping tenfold.",
       "fit.lm.LMOptions.mu_inc", note="equal to weight_growth by coincidence"),
    _r("lm_mu_dec", 0.1, "factor", "trainlm's schedule: an accepted step lowers the damping tenfold.",
       "fit.lm.LMOptions.mu_dec", note="equal to geodesic_h, negligible_gain by coincidence"),
    _r("lm_mu_max", 1e10, "damping", "A damping this large makes steps of nothing: no step lowers the cost.",
       "fit.lm.LMOptions.mu_max"),
    _r("lm_mu_min", 1e-20, "damping", "A floor that keeps the damping from underflowing, so a later refusal "
       "can raise it to a useful size within max_mu_tries.", "fit.lm.LMOptions.mu_min"),
    _r("lm_max_mu_tries", 20, "trials", "Twenty refusals in a row (mu x 1e20 with trainlm's schedule) mean no "
       "damped step lowers the cost.", "fit.lm.LMOptions.max_mu_tries",
       note="equal to oracle_min, bias_iter, rows_per_quantity by coincidence"),
    _r("lm_min_grad", 1e-10, "gradient norm", "trainlm's gradient tolerance: a stationary point in floating "
       "point.", "fit.lm.LMOptions.min_grad", note="equal to min_rel_cost_change by coincidence"),
    _r("lm_cost_goal", 0.0, "cost", "Off: a physical fit has no cost it is told to reach.",
       "fit.lm.LMOptions.cost_goal"),
    _r("lm_min_rel_step", 1e-12, "relative step", "A step below this share of the parameters' size is rounding, "
       "not movement.", "fit.lm.LMOptions.min_rel_step",
       note="equal to cost_rounding, initstate_min_rel_cost_change, rcond by coincidence"),
    _r("lm_min_rel_cost_change", 0.0, "fraction of the cost", "Off in the generic trainer; identify sets "
       "min_rel_cost_change.", "fit.lm.LMOptions.min_rel_cost_change"),
    _r("lm_stall_decrease", 0.0, "fraction of the cost", "Off in the generic trainer; identify sets it from "
       "converged_decrease.", "fit.lm.LMOptions.stall_decrease"),
    _r("lm_stall_iterations", 10, "iterations", "The stall rule's window: one iteration's gain says little, ten "
       "in a row do.", "fit.lm.LMOptions.stall_iterations",
       note="equal to pace_iterations, validation_segments by coincidence"),
    _r("lm_crawl_decrease", 0.0, "fraction of the cost", "Off in the generic trainer; identify sets it from "
       "crawl_decrease.", "fit.lm.LMOptions.crawl_decrease"),
    _r("lm_crawl_cost", float("inf"), "cost", "No noise floor known to the generic trainer: the crawl rule "
       "applies at any cost once switched on.", "fit.lm.LMOptions.crawl_cost"),
    _r("lm_negligible_gain", 0.0, "units of -2 log-likelihood", "Off in the generic trainer; identify sets "
       "negligible_gain.", "fit.lm.LMOptions.negligible_gain"),
    _r("lm_negligible_pace", 0.0, "units of -2 log-likelihood", "Off in the generic trainer; identify sets "
       "negligible_pace.", "fit.lm.LMOptions.negligible_pace"),
    _r("pace_left", 3.84, "units of -2 log-likelihood", "What a test at the 5 % level can see (chi-square, one "
       "degree of freedom): less left than that is not worth a descent at a negligible pace.",
       "fit.lm.LMOptions.pace_left"),
    _r("lm_residual_stride", 0, "outputs", "Off: the residual's entries count as its independent samples.",
       "fit.lm.LMOptions.residual_stride"),
    _r("lm_tau", 0.0, "factor", "Off: trainlm's fixed first damping mu0, not one scaled by max diag(JᵀJ).",
       "fit.lm.LMOptions.tau", note="equal to refit_tau by coincidence"),
    _r("lm_geodesic", 0.0, "fraction of the step", "Off: plain steps, as trainlm.", "fit.lm.LMOptions.geodesic"),
    _r("lm_bound_width", 0.0, "fraction of the start's distance", "Off: the unit transform of one-sided bounds.",
       "fit.lm.LMOptions.bound_width"),
    _r("wide_column", 0.5, "fraction of the rows", "A sparse column this full is cheaper in dense products.",
       "fit.steps.WIDE_COLUMN", note="equal to held_chatter, bias_warn, follow_fraction by coincidence"),
    _r("long_step", 1.5, "ratio of scaled steps", "A trust-radius trial longer than this is mostly refused, so "
       "its Jacobian is not simulated with it.", "fit.lm.LONG_STEP",
       note="equal to local_factor by coincidence"),
    _r("cost_rounding", 1e-12, "fraction of the cost", "A predicted decrease below the cost's rounding cannot be "
       "seen: the trust-radius fit has converged.", "fit.stopping.COST_ROUNDING",
       note="equal to lm_min_rel_step, initstate_min_rel_cost_change, rcond by coincidence"),
    _r("trust_poor_gain", 0.25, "gain ratio", "A step whose actual decrease is below a quarter of the model's "
       "was poorly predicted: the trust radius shrinks (Moré 1978).", "fit.steps.TRUST_POOR",
       "diagnose.choice.ONE_STEP_TRUST (a candidate's one Gauss-Newton step, simulated, says where its refit goes "
       "only when so predicted)", "diagnose.fitstate._TRUST (an unfinished first fit moves only as far as its "
       "step is so predicted)",
       note="equal to trust_shrink, linearity_tol, dense_fraction by coincidence"),
    _r("trust_good_gain", 0.75, "gain ratio", "A step whose actual decrease is above three quarters of the "
       "model's was well predicted: the trust radius grows (Moré 1978).", "fit.steps.TRUST_GOOD",
       note="equal to identify_geodesic by coincidence"),
    _r("trust_shrink", 0.25, "fraction of the step", "After a poor gain or a refusal the radius becomes a "
       "quarter of the step (Moré 1978).", "fit.steps.TRUST_SHRINK", "fit.lm._trials", "diagnose.choice.ONE_STEP_SHRINK",
       "diagnose.fitstate._SHRINK",
       note="equal to trust_poor_gain, linearity_tol, dense_fraction by coincidence"),
    _r("trust_grow", 2.0, "multiple of the step", "After a good gain the radius becomes twice the step (Moré "
       "1978).", "fit.steps.TRUST_GROW", note="equal to noise_margin, spread_z by coincidence"),
    _r("radius_tolerance", 1e-6, "fraction of the radius", "The trust-radius step's length is solved to this "
       "accuracy (MINPACK's lmpar takes 0.1).", "fit.steps.RADIUS_TOLERANCE",
       note="equal to fd_step by coincidence"),
    _r("geodesic_h", 0.1, "fraction of the step", "The finite-difference step of the second directional "
       "derivative of geodesic acceleration.", "fit.steps.GEODESIC_H",
       note="equal to lm_mu_dec, negligible_gain by coincidence"),
    _r("box_theta", 0.995, "fraction of the room", "A step covers at most this share of a quantity's room to its "
       "bound, keeping every iterate strictly feasible (as scipy's trf).", "fit.boxstep.BOX_THETA"),
    _r("bound_nudge", 1e-4, "internal distance", "A start exactly on a bound moves inside by this much in the "
       "transform's coordinates, where the transform has a slope.", "fit.transforms.BOUND_NUDGE"),
    _r("rank_rtol", 1e-8, "fraction of the largest singular value", "A direction the scaled Jacobian shrinks "
       "below this is one the data do not determine.", "fit.uncertainty.RANK_RTOL"),
    _r("correlation_limit", 0.999, "correlation", "Parameters this correlated are practically interchangeable.",
       "fit.uncertainty.CORRELATION_LIMIT"),
    _r("null_part", 1e-2, "projector diagonal", "A quantity takes part in an undetermined direction from this "
       "share of the null-space projector on.", "fit.uncertainty._NULL_PART",
       note="equal to converged_decrease by coincidence"),
    _r("near_best", 1.01, "ratio of costs", "Starts within 1 % of the best cost reached the same minimum.",
       "fit.multistart.NEAR_BEST", note="equal to growth_limit by coincidence"),
    _r("local_factor", 1.5, "ratio of costs", "Starts 1.5x above the best cost are flagged as local minima.",
       "fit.multistart.LOCAL_FACTOR", note="equal to long_step by coincidence"),
    _r("zero_cost", 1e-14, "fraction of the largest start cost", "Costs this small are an exact fit, never a "
       "local minimum.", "fit.multistart._ZERO_COST"),
    _r("whiteness_max_lag", 25, "lags", "The residual correlation test's lags (as MATLAB's resid).",
       "fit.correlation.MAX_LAG"),
    _r("whiteness_level", 0.99, "probability", "The confidence band's level for a correlation of white noise.",
       "fit.correlation.LEVEL"),
    # --- identify: its settings and the rules of its modules ---
    _r("fit_max_iter", 1000, "iterations", "A safety limit, not a stopping rule: identify's and diagnose's full "
       "fits stop on convergence well before it.", "identify.settings.IdentifySettings.max_iter",
       "diagnose.fitting.DiagnoseSettings.max_iter", "cli.options.max_iter_option",
       flags=("identify --max-iter", "diagnose --max-iter", "batch --max-iter")),
    _r("identify_tau", 1e-3, "factor", "The first damping scaled to the problem (Madsen-Nielsen-Tingleff's "
       "suggestion), for a fit from a chart's rough init.", "identify.settings.IDENTIFY_TAU",
       note="equal to trainlm_mu0, initstate_tau by coincidence"),
    _r("refit_tau", 0.0, "factor", "Off (trainlm's fixed first damping) for brief refits that start next to a "
       "fit.", "identify.settings.REFIT_TAU", "diagnose.fitting.DiagnoseSettings.lm_tau"),
    _r("online_tau", 1.0, "factor", "The quasi-online window's first damping, measured on the paper "
       "experiment.", "identify.settings.ONLINE_TAU",
       note="equal to crawl_decrease, negligible_pace, step_level by coincidence"),
    _r("identify_geodesic", 0.75, "fraction of the step", "Geodesic acceleration refuses a bend larger than "
       "this share of the step (Transtrum and Sethna's 0.75).", "identify.settings.IDENTIFY_GEODESIC",
       note="equal to trust_good_gain by coincidence"),
    _r("min_rel_cost_change", 1e-10, "fraction of the cost", "An iteration that gains less than this only "
       "polishes noise.", "identify.settings.MIN_REL_COST_CHANGE",
       note="equal to lm_min_grad by coincidence"),
    _r("converged_decrease", 0.01, "E/N (N residuals)", "Ten iterations that together gain 1 % of one unit of "
       "-2 log-likelihood gain nothing the data could show.", "identify.settings.CONVERGED_DECREASE",
       "identify.settings.IdentifySettings.converged_decrease", note="equal to null_part by coincidence"),
    _r("crawl_decrease", 1.0, "E/N (N residuals)", "At the noise floor, one unit of -2 log-likelihood in "
       "crawl_iterations iterations is a crawl along a direction the data barely determine.",
       "identify.settings.CRAWL_DECREASE",
       note="equal to online_tau, negligible_pace, step_level by coincidence"),
    _r("crawl_iterations", 100, "iterations", "The crawl rule's window (a long one: the fit is already at the "
       "noise floor).", "identify.settings.CRAWL_ITERATIONS", "fit.lm.LMOptions.crawl_iterations",
       note="equal to lm_max_iter, stage_max_iter, tracked_window by coincidence"),
    _r("crawl_noise", 1.2, "ratio of RMS", "A residual RMS within 1.2x the records' noise is at the noise floor, "
       "where the crawl rule applies.", "identify.settings.CRAWL_NOISE"),
    _r("negligible_gain", 0.1, "units of -2 log-likelihood", "What the Gauss-Newton step predicts is left moves "
       "every parameter by less than 0.32 standard errors: a 95 % interval's coverage by about a point.",
       "identify.settings.NEGLIGIBLE_GAIN", note="equal to lm_mu_dec, geodesic_h by coincidence"),
    _r("negligible_pace", 1.0, "units of -2 log-likelihood", "At less than one unit per pace_iterations, forty "
       "more iterations would not reach the 3.84 units a 5 % test needs.", "identify.settings.NEGLIGIBLE_PACE",
       note="equal to online_tau, crawl_decrease, step_level by coincidence"),
    _r("pace_iterations", 10, "iterations", "The negligible-pace rule's window.",
       "identify.settings.PACE_ITERATIONS", "fit.lm.LMOptions.pace_iterations",
       note="equal to lm_stall_iterations, validation_segments by coincidence"),
    _r("held_chatter", 0.5, "amplitude kept per step", "A network mode that alternates and keeps half its "
       "amplitude a step is the explicit step's, not the chart's: auto sub-steps refit at 4x N.",
       "identify.settings.HELD_CHATTER",
       note="equal to wide_column, bias_warn, follow_fraction by coincidence"),
    _r("far_above_noise", 5.0, "ratio of RMS", "A complete chart at its minimum ends within about 4x the noise "
       "(the discretization floor included); 5x means an effect is missing or the fit is in a local minimum.",
       "identify.settings.FAR_ABOVE_NOISE", "identify.offline.run (the far-above-noise warning)",
       "diagnose.choice.SECOND_LOOK", "diagnose.choice.one_step_relevant (within it, one Gauss-Newton step is "
       "trusted to say what a refit reaches)", flags=("diagnose --second-look",)),
    _r("online_window", 25000, "samples", "The paper's quasi-online window Q.",
       "identify.settings.IdentifySettings.window", flags=("identify --window",),
       note="equal to online_average by coincidence"),
    _r("online_average", 25000, "samples", "The paper's quasi-online mean over the last K steps.",
       "identify.settings.IdentifySettings.average", flags=("identify --average",),
       note="equal to online_window by coincidence"),
    _r("stick_fraction", 0.3, "fraction of the chatter slope", "A learned curve's stick-slip start has the "
       "slope that gave the lowest cost on the two-mass bench.", "identify.offline.curvestart.STICK_FRACTION"),
    _r("curve_brief_iterations", 50, "iterations", "Enough brief iterations to move the physical values the "
       "chatter limit depends on before the step is re-sloped.", "identify.offline.curvestart.BRIEF_ITERATIONS"),
    _r("step_level", 1.0, "curve output unit", "The stick-slip step's starting output weight (only its slope "
       "is kept).", "identify.offline.curvestart.STEP_LEVEL",
       note="equal to online_tau, crawl_decrease, negligible_pace by coincidence"),
    _r("grid_tops", (1.0, 3.0), "input RMS", "The second neuron's input weights tried, the lower cost kept.",
       "identify.offline.curvestart.GRID_TOPS"),
    _r("slope_bracket", (1e-9, 1e12), "slope", "The bisection range of a curve's slope at zero.",
       "identify.offline.curvestart._SLOPES"),
    _r("chatter_warn", 0.9, "amplitude kept per step", "A network this close to chattering at rest is warned "
       "about.", "identify.assess.evidence.CHATTER_WARN"),
    _r("floor_warn", 0.2, "fraction of the residual RMS", "Above it the network's own step error is a visible "
       "part (4 %) of what the fit calls model error.", "identify.assess.floor.FLOOR_WARN",
       note="equal to lag_zero_min by coincidence"),
    _r("oracle_per_step", 4, "RK4 steps per network step", "RK4's error on any mode the network resolves is "
       "then 1e-8 of the signal.", "identify.assess.floor._ORACLE_PER_STEP",
       note="equal to segment_growth by coincidence"),
    _r("oracle_min", 20, "RK4 steps per sample", "At least as fine as `simulate --continuous`.",
       "identify.assess.floor._ORACLE_MIN",
       note="equal to lm_max_mu_tries, bias_iter, rows_per_quantity by coincidence"),
    _r("bias_iter", 20, "iterations", "The bias refit starts a fraction of a standard error from its optimum on "
       "noise-free data and converges in a few steps.", "identify.assess.floorbias.BIAS_ITER",
       note="equal to lm_max_mu_tries, oracle_min, rows_per_quantity by coincidence"),
    _r("beta_settled", 0.05, "fraction of beta", "A bias that moves less than this over the second half of a "
       "long refit has settled.", "identify.assess.floorbias.BETA_SETTLED", note="equal to alpha by coincidence"),
    _r("bias_warn", 0.5, "standard errors", "From here a 95 % interval centred on the estimate misses the truth "
       "visibly more often than 1 in 20.", "identify.assess.floorbias.BIAS_WARN",
       note="equal to wide_column, held_chatter, follow_fraction by coincidence"),
    _r("fd_step", 1e-6, "relative step", "Central differences' step: truncation and rounding errors balanced.",
       "identify.offline.initstate.FD_STEP", note="equal to radius_tolerance by coincidence"),
    _r("initstate_max_iter", 200, "iterations", "The states' own fit has few unknowns and converges long "
       "before this.", "identify.offline.initstate._OPTIONS"),
    _r("initstate_tau", 1e-3, "factor", "The first damping scaled to the problem, for states started from the "
       "record.", "identify.offline.initstate._OPTIONS",
       note="equal to trainlm_mu0, identify_tau by coincidence"),
    _r("initstate_min_rel_cost_change", 1e-12, "fraction of the cost", "The states' fit stops when an "
       "iteration only polishes rounding.", "identify.offline.initstate._OPTIONS",
       note="equal to lm_min_rel_step, cost_rounding, rcond by coincidence"),
    _r("lag_zero_z", 4.0, "standard deviations", "The lag-0 correlation must exceed chance by this much.",
       "identify.assess.lagzero.LAG_ZERO_Z", note="equal to suspect_peak, reseat_ratio by coincidence"),
    _r("lag_zero_min", 0.2, "correlation", "... and be at least this large: a long record makes tiny "
       "correlations significant and harmless.", "identify.assess.lagzero.LAG_ZERO_MIN",
       note="equal to floor_warn by coincidence"),
    _r("lag_zero_max_lag", 500, "lags", "The lags summed in Bartlett's variance.", "identify.assess.lagzero.MAX_LAG",
       note="equal to horizon by coincidence"),
    _r("linearity_tol", 0.25, "fraction of the predicted change", "A window trial is accepted while its output "
       "change stays this close to first order.", "identify.online.kernel.LINEARITY_TOL",
       note="equal to trust_poor_gain, trust_shrink, dense_fraction by coincidence"),
    _r("chatter_limit", 1.0 + 1e-9, "amplitude kept per step", "A network that chatters at rest (a mode beyond "
       "the unit circle, rounding aside) is refused.", "identify.offline.problem.CHATTER_LIMIT"),
    _r("growth_limit", 1.01, "growth per sample", "A drift away from rest faster than 1 % a sample (e-fold in "
       "100 samples) is no drive's: the trial is refused.", "identify.offline.problem.GROWTH_LIMIT",
       note="equal to near_best by coincidence"),
    _r("growth_bound", 1000.0, "state RMS", "A moved start grown this much ends the predictable horizon.",
       "identify.shooting.auto.GROWTH_BOUND"),
    _r("suspect_peak", 4.0, "growth", "Beyond the stable charts' 95th percentile (3.9): auto's second look.",
       "identify.shooting.auto.SUSPECT_PEAK", note="equal to lag_zero_z, reseat_ratio by coincidence"),
    _r("probe_delta", 1e-7, "state RMS", "The moved start stays linear up to growth_bound.",
       "identify.shooting.auto.DELTA"),
    _r("max_segments", 256, "segments", "The Jacobian has free states x segments extra dense columns.",
       "identify.shooting.segmented.MAX_SEGMENTS"),
    _r("segment_growth", 4, "factor", "Segments grow fourfold a stage; a stage's boundaries are the last one's, "
       "so its free starts carry over.", "identify.shooting.multiple.GROWTH",
       flags=("identify --shooting", "diagnose --shooting", "batch --shooting"),
       note="equal to oracle_per_step by coincidence"),
    _r("weight_growth", 10.0, "factor", "The continuity weight grows tenfold a stage.",
       "identify.shooting.multiple.WEIGHT_GROWTH", note="equal to lm_mu_inc by coincidence"),
    _r("dense_fraction", 0.25, "fraction of the columns", "A Jacobian this full is handed to the trainer dense.",
       "identify.shooting.segmented.DENSE_FRACTION",
       note="equal to trust_poor_gain, trust_shrink, linearity_tol by coincidence"),
    _r("stage_max_iter", 100, "iterations", "A stage only warms the next one up.",
       "identify.shooting.multiple.STAGE_MAX_ITER",
       note="equal to lm_max_iter, crawl_iterations, tracked_window by coincidence"),
    _r("reseat_ratio", 4.0, "ratio of MSE", "A segment at twice the median segment's RMS has its start reseated.",
       "identify.shooting.multiple.RESEAT_RATIO", note="equal to lag_zero_z, suspect_peak by coincidence"),
    _r("reseat_rounds", 3, "refits", "Reseat and refit a stage at most this often.",
       "identify.shooting.multiple.RESEAT_ROUNDS", note="equal to cutoff_pace, rounds by coincidence"),
    _r("merge_rise", 1.44, "ratio of cost per sample", "A merge that raises the RMS by more than 20 % is "
       "refused.", "identify.shooting.multiple.MERGE_RISE"),
    _r("noise_margin", 2.0, "ratio of RMS", "... from a stage within twice the noise.",
       "identify.assess.noise.NOISE_MARGIN", note="equal to trust_grow, spread_z by coincidence"),
    _r("noise_orders", (3, 4, 6, 8), "difference orders", "The higher differences the noise is read from "
       "besides the second.", "identify.assess.noise.NOISE_ORDERS"),
    _r("noise_bands", 16, "bands", "The frequency bands of the spectral noise reading.",
       "identify.assess.noise.NOISE_BANDS"),
    # --- diagnose ---
    _r("default_split", 0.7, "fraction of the record", "Without validation records, fit on the leading 70 % and "
       "validate on the rest.", "diagnose.fitting.DEFAULT_SPLIT", flags=("diagnose --split",)),
    _r("validation_segments", 10, "parts", "A gain is weighed against its spread over this many parts of the "
       "validation records.", "diagnose.fitting.VALIDATION_SEGMENTS",
       note="equal to lm_stall_iterations, pace_iterations by coincidence"),
    _r("cutoff_pace", 3, "iterations", "A brief refit's pace is the mean fall of its last three iterations.",
       "diagnose.fitting.CUTOFF_PACE", note="equal to reseat_rounds, rounds by coincidence"),
    _r("rounds", 3, "effects", "At most this many effects are added.", "diagnose.fitting.DiagnoseSettings.rounds",
       flags=("diagnose --rounds",), note="equal to reseat_rounds, cutoff_pace by coincidence"),
    _r("top", 5, "places", "Places refitted per round.", "diagnose.fitting.DiagnoseSettings.top",
       flags=("diagnose --top",)),
    _r("top_options", 3, "options", "A non-neutral candidate's options that get the full score test (an RTRL "
       "pass each), ranked by their cost after the current chart's own step: the best and the runners_up "
       "a refit may need.", "diagnose.fitting.DiagnoseSettings.top_options", "diagnose.score.screen",
       note="equal to rounds, reseat_rounds, cutoff_pace by coincidence; runners_up + 1 by design"),
    _r("runners_up", 2, "options", "Further options of the best place's scan (a "
       "dead time's n, a cogging harmonic) refitted too: refits, not the score, decide a discrete choice.",
       "diagnose.fitting.DiagnoseSettings.runners_up"),
    _r("refit_iter", 40, "iterations", "A brief refit starts next to a fit and needs tens of iterations.",
       "diagnose.fitting.DiagnoseSettings.refit_iter", flags=("diagnose --refit-iter",)),
    _r("alpha", 0.05, "probability", "The score test's significance level per round, shared by every candidate "
       "scored (Bonferroni): at most a 5 % chance that a round refits a place where the chart lacks nothing.",
       "diagnose.fitting.DiagnoseSettings.alpha", "diagnose.choice._significant", flags=("diagnose --alpha",),
       note="equal to beta_settled by coincidence"),
    _r("min_gain", 0.02, "fraction of the validation RMS", "An effect must lower the validation RMS by 2 %.",
       "diagnose.fitting.DiagnoseSettings.min_gain", "diagnose.choice.passes_gain (acceptance, the control's "
       "need, one_step_relevant)", flags=("diagnose --min-gain",)),
    _r("horizon", 500, "samples", "The growing horizon's first stage: shorter than the time a chaotic drive's "
       "trajectories take to part.", "diagnose.fitting.DiagnoseSettings.horizon", flags=("diagnose --horizon",),
       note="equal to lag_zero_max_lag by coincidence"),
    _r("spread_z", 2.0, "standard errors", "A gain must exceed its spread over the validation parts by two "
       "standard errors.", "diagnose.fitting.DiagnoseSettings.spread_z", flags=("diagnose --spread-z",),
       note="equal to trust_grow, noise_margin by coincidence"),
    _r("rcond", 1e-12, "relative singular value", "The score test's least squares treat smaller singular values "
       "as zero.", "diagnose.gauss_newton.RCOND",
       note="equal to lm_min_rel_step, cost_rounding, initstate_min_rel_cost_change by coincidence"),
    _r("noise_lag_window", 1 / 30, "fraction of a record", "The score test's noise spectrum: the residual's "
       "covariances up to 1/30 of the record (1 s of 30 s), far past a sensor's or a speed estimate's memory, "
       "averaged over about 30 windows so the variance estimate itself is steady.",
       "diagnose.noise.NOISE_LAG_WINDOW"),
    _r("neutral_roundoff", 1e-8, "fraction of the largest residual", "A chart holding every neutral patch is "
       "neutral when it moves the residual by no more than float round-off over a long run (1e-11 seen on 10^5 "
       "steps), far below any sensor's resolution.", "diagnose.score.NEUTRAL_ROUNDOFF",
       note="equal to rank_rtol by coincidence"),
    _r("tracked_window", 100, "rows", "White noise's running mean square over 100 rows spreads by 14 %, far "
       "inside follow_fraction.", "diagnose.tracked.WINDOW",
       note="equal to lm_max_iter, crawl_iterations, stage_max_iter by coincidence"),
    _r("follow_fraction", 0.5, "fraction of the residual RMS", "The tracked part ends where the running RMS "
       "reaches half the record's.", "diagnose.tracked.FOLLOW_FRACTION",
       note="equal to wide_column, held_chatter, bias_warn by coincidence"),
    _r("rows_per_quantity", 20, "rows", "The tracked part's floor per fitted quantity.",
       "diagnose.tracked.ROWS_PER_QUANTITY",
       note="equal to lm_max_mu_tries, oracle_min, bias_iter by coincidence"),
)

#: name -> Rule
RULES: dict[str, Rule] = {r.name: r for r in _BOOK}
if len(RULES) != len(_BOOK):  # pragma: no cover - a name written twice
    raise RuntimeError("rules.py: a rule name is used twice")


def rule(name: str) -> Rule:
    """The rule called ``name`` (KeyError naming it when there is none)."""
    try:
        return RULES[name]
    except KeyError:
        raise KeyError(f"no rule {name!r} in flowchart2sdnn.rules") from None


def value(name: str) -> Any:
    """The default of the rule called ``name``."""
    return rule(name).value
