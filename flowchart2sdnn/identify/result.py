"""What an identification found, as frozen typed data.

:class:`Identification` is what :func:`flowchart2sdnn.identify` returns and what diagnose, batch, the plots and
the text summary read: physical parameters as :class:`Estimate` (value, 95 % interval, unit), learned curves as
:class:`Curve`, fit metrics per record and output (:class:`Metrics`), the optimizer's trace, the multi-start
summary, the uncertainty analysis, the quasi-online trace and the identified chart. Only
:mod:`flowchart2sdnn.identify.document` turns it into RESULT.json and back.

Layer: identify (below it: data, network, compiler, diagram).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..diagram.model import Diagram
from ..notices import Notice, aligned
from ..views import view
from .extra import Extra
from .settings import IdentifySettings

__all__ = ["Estimate", "Curve", "Metrics", "Fit", "Uncertainty", "OptimizerTrace", "MultistartSummary", "Extra",
           "OnlineTrace", "RecordInfo", "DataInfo", "ChartSource", "Identification"]


@dataclass(frozen=True)
class Estimate:
    """One physical parameter: its identified value, start value, standard error and 95 % interval, unit.

    ``stderr`` and ``ci95`` are None when the parameter is fixed or no uncertainty could be computed; they are
    widened for coloured residuals (see :attr:`Uncertainty.interval_inflation`). ``ci95`` is also widened by
    the discretization's bias |beta| on both sides where identify estimated it (RESULT.json
    `discretization.bias`, identify.assess.floorbias); ``ci95_noise`` is the interval from the noise alone (the
    Jacobian's covariance; equal to ``ci95`` where no bias was estimated), ``stderr`` always the noise's.
    """

    value: float
    init: float
    stderr: float | None
    ci95: tuple[float, float] | None
    unit: str | None
    fixed: bool
    ci95_noise: tuple[float, float] | None = None


@dataclass(frozen=True)
class Curve:
    """A learned static curve (a `nonlinear` block): y = sum v_i tanh(a_i x + b_i) + c x (c None: no linear
    term)."""

    a: tuple[float, ...]
    v: tuple[float, ...]
    b: tuple[float, ...] | None
    fixed: bool
    c: float | None = None

    @property
    def slope_at_zero(self) -> float:
        b = self.b if self.b is not None else (0.0,) * len(self.a)
        return float(sum(a * v * (1.0 - np.tanh(bb) ** 2) for a, v, bb in zip(self.a, self.v, b, strict=True))
                     + (self.c or 0.0))

    def __call__(self, x: np.ndarray | float) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        b = np.asarray(self.b if self.b is not None else np.zeros(len(self.a)))
        return np.tanh(x[..., None] * np.asarray(self.a) + b) @ np.asarray(self.v) + (self.c or 0.0) * x


@dataclass(frozen=True)
class Metrics:
    """Free-run fit on a record (or several): cost E (eq. 4), RMS and fit % per output, rows scored.

    A metric is None where the free run diverged. ``records`` holds the per-record metrics when several
    training records were fitted together; ``note`` says how a validation was scored (e.g. after a split).
    """

    rows: int
    cost: float | None
    rms: Mapping[str, float | None]
    fit_percent: Mapping[str, float | None]
    records: tuple[Metrics, ...] | None = None
    note: str | None = None


@dataclass(frozen=True)
class Fit:
    train: Metrics
    validation: Metrics | None = None


@dataclass(frozen=True)
class Uncertainty:
    """The covariance analysis at the final point (correlations rounded to 12 digits, None where undefined)."""

    names: tuple[str, ...]
    correlation: tuple[tuple[float | None, ...], ...]
    condition_number: float | None
    unidentifiable: tuple[tuple[str, ...], ...]
    sigma2: float
    residual_lag1: float | None
    interval_inflation: float
    note: str


@dataclass(frozen=True)
class OptimizerTrace:
    """Levenberg-Marquardt's work: iterations, cost after each, evaluations, refused trial steps by cause."""

    iterations: int
    cost_history: tuple[float, ...]
    nfev: int
    njev: int
    rejected_cost: int
    rejected_diverged: int
    rejected_chatter: int


@dataclass(frozen=True)
class MultistartSummary:
    """How the starts of a multi-start fit ended (indices into ``starts``; costs None where a start diverged).

    ``names`` is the parameter order of ``starts`` (given with several starts); ``cost`` says which cost was
    compared when it is not the training cost E (quasi-online runs).
    """

    n: int
    best_index: int
    costs: tuple[float | None, ...]
    near_best: tuple[int, ...]
    local_minima: tuple[int, ...]
    diverged: tuple[int, ...]
    starts: tuple[tuple[float, ...], ...]
    message: str
    names: tuple[str, ...] | None = None
    cost: str | None = None


@dataclass(frozen=True)
class OnlineTrace:
    """The quasi-online run: window settings, parameter and window-cost trajectories over time."""

    window: int
    average: int
    every: int
    steps: int
    mean_cost: float
    final: Mapping[str, float]
    trajectory_time: tuple[float, ...]
    trajectories: Mapping[str, tuple[float, ...]]
    cost_time: tuple[float, ...]
    cost: tuple[float, ...]


@dataclass(frozen=True)
class RecordInfo:
    """Which data file was used: path, content hash, rows, largest deviation of its time steps."""

    file: str | None
    sha256: str | None
    rows: int
    max_step_deviation: float | None


@dataclass(frozen=True)
class DataInfo:
    train: RecordInfo
    train_records: tuple[RecordInfo, ...]
    validation: RecordInfo | None


@dataclass(frozen=True)
class ChartSource:
    name: str
    file: str | None
    sha256: str | None


@dataclass(frozen=True, eq=False)
class Identification:
    """What :func:`~flowchart2sdnn.identify.offline.run.identify` found.

    Attributes
    ----------
    status, message : str        the optimizer's status word ("small_cost_change", "max_iter", "interrupted",
                                 ...) and sentence
    interrupted : bool           stopped early (Ctrl-C); the best point so far is reported
    converged : bool or None     the offline fit reached a minimum (False: it stopped at the iteration limit or
                                 was interrupted, and says so in ``warnings``); None where it does not apply
                                 (quasi-online, nothing to fit, no excitation)
    parameters : {name: Estimate}   every chart parameter, fixed ones included, in chart order
    curves : {block: Curve}      the learned curves
    fit : Fit                    training and validation metrics
    warnings : tuple of str      what the user should know, as sentences (RESULT.json's ``warnings``)
    notices : tuple of Notice    the same warnings as records, one per sentence in its order: code, message,
                                 the numbers it states, advice (a sentence given without one gets an uncoded
                                 record; docs/guide/warnings.md lists the codes)
    settings : IdentifySettings
    chart : Diagram or None      the identified chart (values as init, learned curves stored); None when read
                                 from a RESULT.json alone
    source : ChartSource         the chart that was fitted
    data : DataInfo
    versions : {package: version}
    optimizer, multistart, uncertainty, online : optional parts (None where they do not apply)
    extra : Extra                further RESULT.json keys, typed (``.discretization``, ``.shooting``,
                                 ``.parameters_per_record``, ``.command``, ``.identified_chart``, ...; unknown keys
                                 of a document read back in ``.other``) and readable as a mapping of those keys;
                                 a plain dict given here becomes one

    ``summary()``, ``parameters_table()`` and ``fit_table()`` are for reading it in a notebook (which shows
    ``_repr_html_``), ``to_json()`` is RESULT.json.

    The fitting problem and the optimizer's raw results (``problem``, ``x``, ``lm``, ``online_run``) are there
    for the code that continues from a fit (diagnose, plots); they are not part of the document.
    """

    status: str
    message: str
    interrupted: bool
    converged: bool | None
    parameters: Mapping[str, Estimate]
    curves: Mapping[str, Curve]
    fit: Fit
    warnings: tuple[str, ...]
    settings: IdentifySettings
    chart: Diagram | None
    source: ChartSource
    data: DataInfo
    versions: Mapping[str, str]
    optimizer: OptimizerTrace | None = None
    multistart: MultistartSummary | None = None
    uncertainty: Uncertainty | None = None
    online: OnlineTrace | None = None
    extra: Extra = field(default_factory=Extra)
    problem: Any = field(default=None, repr=False)
    x: np.ndarray | None = field(default=None, repr=False)
    lm: Any = field(default=None, repr=False)
    online_run: Any = field(default=None, repr=False)
    notices: tuple[Notice, ...] = ()

    def __post_init__(self) -> None:
        # the sentences lead: code that replaces `warnings` alone keeps a record per sentence
        object.__setattr__(self, "notices", aligned(self.warnings, self.notices))
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))
        if not isinstance(self.extra, Extra):
            object.__setattr__(self, "extra", Extra.of(self.extra))

    def __repr__(self) -> str:
        return view("identification_line")(self)

    def summary(self) -> str:
        """A short text: status, parameters with units, ± standard error and %, fit per output, warnings.

        ``print(result.summary())``; the whole report is ``sdnn identify``'s text (report.identify_text.format_result)
        and the RESULT.json document (:meth:`to_json`)."""
        return view("identification_text")(self)

    def _repr_html_(self) -> str:
        """What a notebook shows: the page's status, parameter, fit and warning sections (no figures)."""
        return view("identification_html")(self)

    def parameters_table(self):
        """The parameters as a table: a pandas DataFrame when pandas is installed, else a list of dicts; columns
        parameter, value, unit, stderr, stderr_percent, ci95_low, ci95_high, init, fixed."""
        from ..tables import frame
        from .rows import PARAMETER_COLUMNS, parameter_rows

        return frame(parameter_rows(self), PARAMETER_COLUMNS)

    def fit_table(self):
        """The fit per record (train, validation) and output as a table (DataFrame when pandas is installed, else
        a list of dicts); columns record, output, rms, fit_percent, cost, rows."""
        from ..tables import frame
        from .rows import FIT_COLUMNS, fit_rows

        return frame(fit_rows(self), FIT_COLUMNS)

    @property
    def diagram(self) -> Diagram | None:
        """The identified chart (the same as :attr:`chart`)."""
        return self.chart

    @property
    def values(self) -> dict[str, float]:
        """Parameter name -> identified value."""
        return {name: e.value for name, e in self.parameters.items()}

    def simulate(self, data, alignment: str | None = None) -> dict[str, np.ndarray]:
        """Free-run the identified network on a record's inputs; output name -> simulated samples.

        Parameters
        ----------
        data : Dataset
            A record with the chart's input columns (and the data columns of `init: data` states).
        alignment : str, optional
            "zoh" or "direct"; default the one of the fit.
        """
        from .compare import predict, require_columns
        from .offline.arrays import network_input_names

        compiled, x = self._network()
        require_columns(data, network_input_names(compiled.net))
        y = predict(compiled, x, data, alignment or self.settings.alignment)
        return {name: y[:, i] for i, name in enumerate(compiled.output_names)}

    def _network(self):
        """(compiled network, theta) of the identified model: the fit's own, else compiled from the chart."""
        if self.problem is not None and self.x is not None:
            return self.problem.compiled, self.x
        if self.chart is None:
            raise ValueError("this result has no chart to simulate (read the RESULT.json with its chart)")
        from ..compiler import compile_diagram
        from ..network.runtime import CompiledNetwork

        compiled = CompiledNetwork(compile_diagram(self.chart).network)
        return compiled, compiled.theta0()

    def compare(self, data, horizon: int | None = None, plot=None, alignment: str | None = None):
        """Measured against model output on records: fit % and RMS per record and output, drawn on request.

        Parameters
        ----------
        data : Dataset, sequence of Dataset, or {label: Dataset}
            Records with the chart's input and output columns (labelled by file name unless a mapping).
        horizon : int, optional
            None: free run; k: k-step-ahead prediction (restarts from the measured outputs every k samples,
            see :mod:`flowchart2sdnn.identify.compare`).
        plot : str or Path, optional
            Also draw the comparison (one PNG, every record; needs matplotlib) into this file: drawn by
            :func:`flowchart2sdnn.report.figures.write_compare`, which does the same with the returned data.
        alignment : str, optional
            "zoh" or "direct"; default the one of the fit.

        Returns
        -------
        Comparison
            ``.records[i].fit_percent[output]``, ``.rms[output]``, the traces; ``.table()`` as rows.
        """
        from pathlib import Path

        from .compare import compare_records

        if isinstance(data, Mapping):
            records = [(str(label), d, 0) for label, d in data.items()]
        else:
            items = [data] if hasattr(data, "columns") and hasattr(data, "n_rows") else list(data)
            records = [(Path(d.path).name, d, 0) for d in items]
        compiled, x = self._network()
        out = compare_records(compiled, x, records, alignment or self.settings.alignment, horizon, self.chart)
        if plot is not None:  # the figure is a view: report/ registered it (see flowchart2sdnn.views)
            view("compare_png")(out, plot, self.chart.name if self.chart is not None else self.source.name)
        return out

    def linearize(self, at: Mapping[str, float] | None = None, kink: str = "zero"):
        """The identified chart's continuous state-space model at an operating point.

        `at` gives states (integrators) and inputs their values (default 0); `kink` says how a Coulomb kink
        (``sign_smooth``) is taken: "zero" (the sign function's slope) or "smooth" (the smoothed slope). See
        :mod:`flowchart2sdnn.analysis.linearize`; ``.to_control()`` gives a python-control ``StateSpace``.
        """
        from ..analysis.linearize import linearize

        if self.chart is None:
            raise ValueError("this result has no chart to linearise (read the RESULT.json with its chart)")
        return linearize(self.chart, at, kink)

    def to_document(self) -> dict:
        """The RESULT.json body, a new dict each call (see :mod:`flowchart2sdnn.identify.document`)."""
        from .serialize import to_document

        return to_document(self)

    @cached_property
    def result(self) -> dict:
        """The RESULT.json body, built on first access and kept (for scripts that read the document's keys;
        the library itself reads the typed fields)."""
        return self.to_document()

    def to_json(self) -> str:
        """RESULT.json as text (strict JSON: non-finite numbers are stored as null, with a warning)."""
        from .serialize import dumps

        return dumps(self.to_document())
