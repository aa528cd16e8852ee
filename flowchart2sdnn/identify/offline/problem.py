"""The fitting problem: a compiled chart, aligned measured data, and residual/Jacobian callbacks for LM."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np

from ... import rules
from ...compiler import compile_diagram
from ...data.csvdata import Dataset
from ...diagram.model import Diagram
from ...errors import SdnnError
from ...network.alignment import fitted_rows, network_inputs, run_aligned
from ...network.model import Network
from ...network.runtime import CompiledNetwork
from ...network.stability import rest_radii
from ...strictjson import finite_or_none
from .arrays import columns_of, data_init, network_input_names
from .curvespan import with_spans

__all__ = ["Problem", "columns_of", "Segment", "build_problem", "metrics", "combined_metrics", "data_init", "required_columns", "CHATTER_LIMIT",
           "interruptible"]

#: A trial step whose network chatters at rest (see network.stability) by more than this is rejected.
CHATTER_LIMIT = rules.value("chatter_limit")
#: ... or that drifts away from rest faster than 1 % a sample (e-fold in 100 samples: no drive does that).
GROWTH_LIMIT = rules.value("growth_limit")


def required_columns(diagram: Diagram) -> list[str]:
    return list(diagram.input_names) + [n for n in diagram.output_names if n not in diagram.input_names]


@contextmanager
def interruptible():
    """Let Ctrl-C inside a numba kernel surface as KeyboardInterrupt (the trainer's clean stop).

    A SIGINT that arrives while compiled code runs is raised when numba next calls back into Python, where it
    cannot propagate and comes out as a SystemError whose cause is the KeyboardInterrupt.
    """
    try:
        yield
    except SystemError as exc:
        cause = exc
        while cause is not None and not isinstance(cause, KeyboardInterrupt):
            cause = cause.__cause__ or cause.__context__
        if cause is None:
            raise
        raise KeyboardInterrupt from exc


@dataclass(frozen=True, eq=False)
class Segment:
    """One more training record of a problem: its network inputs, fitted targets and data initial states."""

    inputs: np.ndarray
    targets: np.ndarray
    init: Mapping[str, float]


@dataclass(frozen=True, eq=False)
class Problem:
    diagram: Diagram
    network: Network
    compiled: CompiledNetwork
    inputs: np.ndarray  # network input sequence (after alignment)
    targets: np.ndarray  # measured outputs on the fitted rows (Q', n_out)
    init: Mapping[str, float]
    alignment: str
    # rest-stability radii a trial step may reach: the limits, or the start's own when it is already worse
    # (a fit that starts unstable must be free to move towards stability, not be frozen by the guard)
    stability_floor: tuple[float, float] = (0.0, 0.0)
    # further training records, each simulated from its own initial state; residuals are concatenated
    extra: tuple[Segment, ...] = ()
    # free parameters with one value per training record (`per_record: true`, several records only): the
    # compiled theta holds record 1's value, names gets one more quantity "name@k" for every further record k
    record_params: tuple[str, ...] = ()

    @property
    def names(self) -> tuple[str, ...]:
        return self.compiled.names + tuple(f"{p}@{k}" for p in self.record_params
                                           for k in range(2, len(self.extra) + 2))

    def record_index(self) -> dict[str, list[int]]:
        """{per-record parameter: [its index in `names` for record 1, 2, ...]}."""
        base = {n: i for i, n in enumerate(self.names)}
        return {p: [base[p]] + [base[f"{p}@{k}"] for k in range(2, len(self.extra) + 2)]
                for p in self.record_params}

    def record_x(self, x: np.ndarray, k: int) -> np.ndarray:
        """The compiled network's theta for training record k (0-based): its own per-record values."""
        x = np.asarray(x, dtype=float)
        xk = x[:len(self.compiled.names)].copy()
        for idx in self.record_index().values():
            xk[idx[0]] = x[idx[k]]
        return xk

    def mean_x(self, x: np.ndarray) -> np.ndarray:
        """The compiled theta with every per-record parameter at the mean over the training records (the value
        a record without its own fit gets: the identified chart's `init`)."""
        x = np.asarray(x, dtype=float)
        xm = x[:len(self.compiled.names)].copy()
        for idx in self.record_index().values():
            xm[idx[0]] = float(np.mean(x[idx]))
        return xm

    def expand(self, xc: np.ndarray) -> np.ndarray:
        """A compiled theta as a start of this problem: every record starts at the same per-record values."""
        xc = np.asarray(xc, dtype=float)
        i = {n: j for j, n in enumerate(self.compiled.names)}
        more = [xc[i[p]] for p in self.record_params for _ in self.extra]
        return np.concatenate([xc, np.asarray(more, dtype=float)]) if more else xc

    @property
    def n_residuals(self) -> int:
        return int(sum(s.targets.size for s in self.segments))

    @property
    def segments(self) -> tuple[Segment, ...]:
        return (Segment(self.inputs, self.targets, self.init),) + self.extra

    def fun(self, x: np.ndarray):
        """(e, J) for LM: e = y - yhat flattened, J = d yhat / d x. None when the simulation diverges."""
        es, js = [], []
        index = self.record_index()
        for k, s in enumerate(self.segments):
            with interruptible():
                yhat, jac = self.compiled.jacobian(self.record_x(x, k) if index else x, s.inputs, s.init)
            if not np.all(np.isfinite(yhat)) or not np.all(np.isfinite(jac)):
                return None
            es.append((s.targets - yhat).ravel())
            jac = jac.reshape(-1, jac.shape[-1])
            if index:  # record k's own quantity takes the column of the parameter; the others see 0
                full = np.zeros((jac.shape[0], len(self.names)))
                full[:, :jac.shape[1]] = jac
                for idx in index.values():
                    full[:, idx[k]] = jac[:, idx[0]]
                    if k:
                        full[:, idx[0]] = 0.0
                jac = full
            js.append(jac)
        if len(es) == 1:
            return es[0], js[0]
        return np.concatenate(es), np.vstack(js)

    def residual(self, x: np.ndarray):
        es = []
        index = self.record_index()
        for k, s in enumerate(self.segments):
            with interruptible():
                yhat = self.compiled.simulate(self.record_x(x, k) if index else x, s.inputs, s.init)
            if not np.all(np.isfinite(yhat)):
                return None
            es.append((s.targets - yhat).ravel())
        return es[0] if len(es) == 1 else np.concatenate(es)

    def stability(self, x: np.ndarray) -> tuple[float, float]:
        """(chatter, growth) radii of the network linearized at rest (see network.stability.rest_radii).

        Growth is per data sample (the step's radius to the power `substeps`), so GROWTH_LIMIT means 1 % a
        sample whatever the step; chatter is per step (> 1 is > 1 in any power): with sub-steps the guard's
        bound on a curve's slope at zero is 2*J/h.
        """
        chatter = growth = 0.0
        # a per-record value may change the linearization (a gain): the worst record counts
        for k in range(len(self.segments) if self.record_params else 1):
            params, free = self.compiled.values(self.record_x(x, k))
            c, g = rest_radii(self.network, self.network.weight_values(params, free))
            chatter, growth = max(chatter, c), max(growth, g)
        n = self.network.substeps
        try:
            return chatter, (growth if n == 1 else growth ** n)
        except OverflowError:  # a radius far above 1 (a huge gain) to the power N: unbounded growth all the same
            return chatter, float("inf")

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of the free quantities: the parameters' min and max, unbounded where none is given
        (and for learned weights)."""
        params = {p.name: p for p in self.network.parameters}
        lo, hi = [], []
        for name in self.names:
            p = params.get(name.partition("@")[0] if "@" in name else name)
            lo.append(-np.inf if p is None or p.min is None else p.min)
            hi.append(np.inf if p is None or p.max is None else p.max)
        return np.array(lo, dtype=float), np.array(hi, dtype=float)

    def from_start(self, x: np.ndarray) -> Problem:
        """This problem with the stability floor raised to what the start `x` itself has.

        Each start of a multi-start gets its own floor: a drawn start that already drifts (or chatters) at rest
        must be free to move towards stability, not have every step refused by the guard.
        """
        chatter, growth = self.stability(np.asarray(x, dtype=float))
        floor = (max(self.stability_floor[0], chatter if chatter > CHATTER_LIMIT else 0.0),
                 max(self.stability_floor[1], growth if growth > GROWTH_LIMIT else 0.0))
        return self if floor == self.stability_floor else replace(self, stability_floor=floor)

    def chatter(self, x: np.ndarray) -> float:
        return self.stability(x)[0]

    def guard(self, x: np.ndarray) -> str | None:
        chatter, growth = self.stability(x)
        if chatter > max(CHATTER_LIMIT, self.stability_floor[0]):
            return (f"the network would chatter at rest (eigenvalue {-chatter:.3f}): a curve in a feedback loop is "
                    + ("steeper than the sample time allows (about 2*J/T)" if self.network.substeps == 1
                       else "steeper than the network step h allows (about 2*J/h)"))
        if growth > max(GROWTH_LIMIT, self.stability_floor[1]):
            return (f"the network would drift away from rest (eigenvalue {growth:.3f}): a curve in a feedback loop "
                    "has a negative slope at zero (it would feed energy in)")
        return None


def build_problem(diagram: Diagram, data: Dataset, alignment: str = "zoh", seed: int = 0,
                  network: Network | None = None, more: Sequence[Dataset] = ()) -> Problem:
    """Compile `diagram` (unless `network` is given) and align `data` (and the records in `more`) to it.

    Learned curves of the tanh basis without slopes get them over their input's range in the records
    (identify.offline.curvespan); the problem's `diagram` is the chart with them."""
    if network is None:
        diagram, _ = with_spans(diagram, (data, *more), alignment)
        network = compile_diagram(diagram, seed=seed).network
    compiled = CompiledNetwork(network)
    if alignment != "zoh" and compiled.shaped_inputs:
        raise SdnnError.at("DATA006", f"inputs with `intersample: linear` or a `delay` need the zoh alignment (a "
                           f"sample acts from its time on), not {alignment!r}", diagram.file,
                           hint="drop --alignment direct")
    first = _one_problem(diagram, network, compiled, data, alignment)
    extra = tuple(Segment(p.inputs, p.targets, p.init)
                  for p in (_one_problem(diagram, network, first.compiled, d, alignment) for d in more))
    if not extra:
        return first
    own = tuple(p.name for p in diagram.parameters if p.per_record and p.name in first.compiled.names)
    return replace(first, extra=extra, record_params=own)


def _one_problem(diagram: Diagram, network: Network, compiled: CompiledNetwork, data: Dataset,
                 alignment: str) -> Problem:
    u = columns_of(data, network_input_names(network))
    y = columns_of(data, compiled.output_names)
    rows = fitted_rows(data.n_rows, alignment)
    p = network_inputs(u, alignment)
    if len(p) < 2:
        raise SdnnError.at("DATA001", f"only {data.n_rows} rows: too few samples to identify anything", data.path)
    _check_magnitude(data, network_input_names(network) + list(compiled.output_names))
    return Problem(diagram, network, compiled, p, y[rows], data_init(network, data), alignment)


def _check_magnitude(data: Dataset, names) -> None:
    """Refuse values whose squares overflow: the cost of eq. (4) could not even be evaluated."""
    for name in dict.fromkeys(names):
        values = np.asarray(data.columns[name], dtype=float)
        with np.errstate(over="ignore", invalid="ignore"):
            total = float(np.sum(values * values))
        if not np.isfinite(total):
            k = int(np.argmax(np.abs(values)))
            column = data.source_columns.get(name, name)
            raise SdnnError.at("DATA002", f"column '{column}': values up to {values[k]:.3g} are too large to "
                               "square (expected magnitudes below about 1e150)", data.path,
                               hint="rescale the data (another unit)")


def metrics(compiled: CompiledNetwork, x: np.ndarray, data: Dataset, alignment: str, init=None,
            score_from: int = 0, history: np.ndarray | None = None, segments: int = 0) -> dict:
    """Free-run fit metrics on a record: cost E (eq. 4), RMS and fit % per output, on rows >= score_from.

    `history` (every neuron's value before the first step, see identify.offline.initstate) replaces the initial state.
    `segments` > 0 adds ``"segments"``: [[rows, squared error summed over every output], ...] on that many
    consecutive equal parts of the scored rows (how the error spreads along the record; diagnose's refusal).
    """
    network = compiled.net
    u = columns_of(data, network_input_names(network))
    y = columns_of(data, compiled.output_names)
    init = data_init(network, data) if init is None else init
    yhat = run_aligned(compiled, x, u, alignment, init, history=history)
    start = max(score_from, fitted_rows(data.n_rows, alignment).start)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        e = y[start:] - yhat[start:]
        out = {"rows": int(len(e)), "cost": finite_or_none(0.5 * np.sum(e**2)), "rms": {}, "fit_percent": {}}
        for i, name in enumerate(compiled.output_names):
            ei = e[:, i]
            yi = y[start:, i]
            if len(ei) == 0:
                out["rms"][name] = out["fit_percent"][name] = None
                continue
            out["rms"][name] = finite_or_none(np.sqrt(np.mean(ei**2)))
            spread = np.linalg.norm(yi - yi.mean())
            out["fit_percent"][name] = finite_or_none(100.0 * (1.0 - np.linalg.norm(ei) / spread)) if spread > 0 else None
        if segments > 0:
            out["segments"] = [[int(len(part)), finite_or_none(float(np.sum(part**2)))]
                               for part in np.array_split(e, min(segments, max(len(e), 1)))]
    return out


def combined_metrics(per_record: list[dict], problem: Problem, x: np.ndarray, records: list[Dataset],
              alignment: str) -> dict:
    """Training metrics over several records: E summed, RMS and fit % over all their scored samples (`x` the
    problem's point: each record runs with its own per-record values)."""
    names = problem.compiled.output_names
    errors, targets = [], []
    for k, d in enumerate(records):
        u = columns_of(d, network_input_names(problem.network))
        y = columns_of(d, names)
        rows = fitted_rows(d.n_rows, alignment)
        yhat = run_aligned(problem.compiled, problem.record_x(x, k), u, alignment, data_init(problem.network, d))
        errors.append(y[rows] - yhat[rows])
        targets.append(y[rows])
    e, y = np.vstack(errors), np.vstack(targets)
    costs = [m["cost"] for m in per_record]
    out = {"rows": int(len(e)), "cost": None if None in costs else float(sum(costs)), "rms": {}, "fit_percent": {},
           "records": per_record}
    for i, name in enumerate(names):
        finite = bool(np.all(np.isfinite(e[:, i])))
        spread = np.linalg.norm(y[:, i] - y[:, i].mean())
        out["rms"][name] = float(np.sqrt(np.mean(e[:, i] ** 2))) if finite else None
        out["fit_percent"][name] = (float(100 * (1 - np.linalg.norm(e[:, i]) / spread))
                                    if finite and spread > 0 else None)
    return out
