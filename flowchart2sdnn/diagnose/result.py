"""What a diagnosis found, as frozen typed data.

:class:`Diagnosis` is what :func:`flowchart2sdnn.diagnose` returns: how the first fit ended (:class:`FirstFit`),
every scored candidate (:class:`CandidateRow`, the refitted ones with their :class:`Refit`), each round's
before/after and decision (:class:`Round`), the accepted effects (:class:`AcceptedEffect`), the fits of the
chart as given and of the final chart (:class:`FitSummary`), the residual tests before and after
(:class:`ResidualCheck`) and the final chart's identification. Only :mod:`flowchart2sdnn.diagnose.document` turns
it into REPORT.json and back; each part's fields are named as that document's keys.

Layer: diagnose.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from ..diagram.model import Diagram
from ..identify import Identification
from ..notices import Notice, aligned, messages
from ..views import view
from .fitting import DiagnoseSettings

__all__ = ["FirstFit", "FitSummary", "Refit", "CandidateRow", "Control", "Round", "AcceptedEffect",
           "ResidualCheck", "Diagnosis"]


@dataclass(frozen=True)
class FirstFit:
    """How the fit of the chart as given ended; ``still_moving`` names the parameters that still moved by more
    than their standard error when it stopped unconverged (then nothing is traced)."""

    converged: bool | None
    status: str
    message: str
    still_moving: tuple[str, ...] = ()


@dataclass(frozen=True)
class FitSummary:
    """One fitted chart's error: training RMS and cost, validation RMS, information criteria (k free quantities),
    the discretization floor on the validation records, and per output (validation: one mapping per record).
    A number is None where the fit diverged."""

    rms: float | None
    validation_rms: float | None
    aic: float | None
    bic: float | None
    cost: float | None
    k: int
    validation_floor: float | None
    rms_per_output: Mapping[str, float | None]
    fit_percent: Mapping[str, float | None]
    validation_rms_per_output: tuple[Mapping[str, float | None], ...]
    validation_fit_percent: tuple[Mapping[str, float | None], ...]
    validation_initial_state: tuple[Any, ...]


@dataclass(frozen=True)
class Refit:
    """A candidate's brief refit: its training cost and the fall from the current fit's, which start won, the
    validation RMS and the information criterion (``criterion``: "aic" or "bic") after it."""

    achieved_cost: float | None
    achieved_decrease: float | None
    start: str | None
    validation_rms_after: float | None
    criterion: str
    criterion_after: float | None


@dataclass(frozen=True)
class CandidateRow:
    """One scored candidate: an effect at a place with an option (``label`` says which), its rank in its round,
    the score test (score = the cost's decrease one Gauss-Newton step predicts, its p-value), and ``refit`` when
    it was refitted (None otherwise). ``error`` says why it could not be scored."""

    round: int
    rank: int
    effect: str
    at: str
    option: Any
    label: str
    score: float | None
    predicted_cost: float | None
    cost_patched: float | None
    dof: int | None
    statistic: float | None
    p_value: float | None
    error: str | None
    refit: Refit | None = None

    @property
    def title(self) -> str:
        return _title(self.effect, self.at, self.label)


@dataclass(frozen=True)
class Control:
    """A round's control: the current chart refitted as briefly as the candidates without any new effect;
    ``used_as_baseline`` when the candidates were judged against it, ``final`` when it became the final fit."""

    start: str | None
    rms: float | None
    validation_rms: float | None
    used_as_baseline: bool
    final: bool


@dataclass(frozen=True)
class Round:
    """One round's decision on its best refitted candidate: accepted or not and why, the error before and after
    (``before`` / ``after`` in full), the refit's parameter values, the control, and the extra places the round
    refitted (``score_rows``: rows per training record the tracked-part score test used, or None)."""

    round: int
    effect: str
    at: str
    option: Any
    label: str
    accepted: bool
    reason: str
    start: str | None
    score: float | None
    predicted_decrease: float | None
    achieved_decrease: float | None
    rms_before: float | None
    rms_after: float | None
    validation_rms_before: float | None
    validation_rms_after: float | None
    validation_gain_spread: float | None
    aic_before: float | None
    aic_after: float | None
    bic_before: float | None
    bic_after: float | None
    before: FitSummary
    after: FitSummary | None
    parameters: Mapping[str, float] | None
    control: Control | None = None
    score_rows: tuple[int, ...] | None = None
    score_rows_added: tuple[str, ...] = ()
    second_look: tuple[str, ...] = ()
    # the significant places judged by their one Gauss-Newton step near the noise (choice.one_step_relevant):
    # {candidate, step, rho, validation_rms, refitted} each
    one_step: tuple[Mapping[str, Any], ...] = ()

    @property
    def title(self) -> str:
        return _title(self.effect, self.at, self.label)


@dataclass(frozen=True)
class AcceptedEffect:
    """An effect added to the chart: its name, the place it attaches to, its option and the option's label."""

    effect: str
    at: str
    option: Any
    label: str

    @property
    def title(self) -> str:
        return _title(self.effect, self.at, self.label)


@dataclass(frozen=True)
class ResidualCheck:
    """The residual analysis of one fit as :func:`~.fitting.residual_analysis` made it (``analysis``: the
    autocorrelation and cross-correlation per output, the 99 % band, the signals most correlated with the
    residual), with its verdicts read out. ``error`` is set (and the verdicts None) where the fit diverged."""

    analysis: Mapping[str, Any]

    @property
    def error(self) -> str | None:
        return self.analysis.get("error")

    @property
    def white(self) -> bool | None:
        return self.analysis.get("white")

    @property
    def independent(self) -> bool | None:
        return self.analysis.get("independent")

    @property
    def signals(self) -> tuple[Mapping[str, Any], ...]:
        """The internal signals most correlated with the residual, most first (signal, output, lag, r)."""
        return tuple(self.analysis.get("signals") or ())


def _title(effect: str, at: str, label: str | None) -> str:
    return f"{effect} at {at}" + (f" ({label})" if label else "")


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """What :func:`~flowchart2sdnn.diagnose.loop.diagnose` found.

    Attributes
    ----------
    stop : str                   how the whole run ended ("done_after_accepting", "nothing_significant", ...;
                                 report.diagnose_text.STOP_MESSAGES says each in words); ``last_round`` how its last
                                 round ended
    n_accepted : int             (the number of ``accepted``)
    first_fit : FirstFit
    interrupted : bool           stopped by Ctrl-C; the chart holds what was accepted before
    candidates : tuple of CandidateRow   every scored candidate of every round, ranked per round
    rounds : tuple of Round      one per round that refitted candidates
    accepted : tuple of AcceptedEffect
    before, after : FitSummary   the chart as given and the final chart
    whiteness : (ResidualCheck, ResidualCheck)   the residual tests before and after
    identification : Identification   the final chart's fit (REPORT.json ``final``)
    settings : DiagnoseSettings  as given, ``split`` the split used (None with validation records)
    effects : tuple of str       the effects tried
    timing : {part: seconds}
    data_notes : tuple of str    the records' notes (time base, delimiter)
    data_notices : tuple of Notice   the same notes as records (code, numbers, advice), one per note
    command : {key: value} or None   the command line that wrote the report
    extra : {key: value}         further REPORT.json keys, kept so a document reads back unchanged

    ``diagram`` is the augmented, identified chart (None when read from a REPORT.json alone); ``final`` and
    ``nominal`` the fits with their fitting problems, ``screens`` the score tests (for the plots and for code that
    continues from a diagnosis; not part of the document). ``report`` is the REPORT.json body, ``to_json()`` its
    text; ``summary()``, ``candidates_table()`` and ``rounds_table()`` are for reading it in a notebook.
    """

    stop: str
    last_round: str
    first_fit: FirstFit
    interrupted: bool
    candidates: tuple[CandidateRow, ...]
    rounds: tuple[Round, ...]
    accepted: tuple[AcceptedEffect, ...]
    before: FitSummary
    after: FitSummary
    whiteness: tuple[ResidualCheck, ResidualCheck]
    identification: Identification
    settings: DiagnoseSettings
    split: float | None
    effects: tuple[str, ...]
    timing: Mapping[str, Any] = field(default_factory=dict)
    data_notes: tuple[str, ...] = ()
    command: Mapping[str, Any] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    diagram: Diagram | None = field(default=None, repr=False)
    final: Any = field(default=None, repr=False)
    nominal: Any = field(default=None, repr=False)
    screens: tuple = field(default=(), repr=False)
    data_notices: tuple[Notice, ...] = ()

    def __post_init__(self) -> None:
        # the sentences lead, as in Identification: a note given alone gets an uncoded record
        object.__setattr__(self, "data_notices", aligned(self.data_notes, self.data_notices))
        object.__setattr__(self, "data_notes", tuple(str(n) for n in self.data_notes))

    def __repr__(self) -> str:
        return view("diagnosis_line")(self)

    def summary(self) -> str:
        """A short text: what was accepted, how the run stopped, the error before and after, each round's
        decision, the best candidates, the final chart's parameters (units, ± standard error and %), warnings.

        The whole report is ``sdnn diagnose``'s text (report.diagnose_text.format_report) and REPORT.json."""
        return view("diagnosis_text")(self)

    def _repr_html_(self) -> str:
        """What a notebook shows: the page's sections as an HTML fragment (no figures)."""
        return view("diagnosis_html")(self)

    def candidates_table(self):
        """Every scored candidate (round, rank, effect, at, label, score, p_value, refitted, achieved_decrease,
        validation_rms_after, start, error): a pandas DataFrame when pandas is installed, else a list of dicts."""
        from ..tables import frame
        from .rows import CANDIDATE_COLUMNS, candidate_rows

        return frame(candidate_rows(self), CANDIDATE_COLUMNS)

    def rounds_table(self):
        """Each round's decision and its error before and after (DataFrame when pandas is installed, else a list
        of dicts)."""
        from ..tables import frame
        from .rows import ROUND_COLUMNS, round_rows

        return frame(round_rows(self), ROUND_COLUMNS)

    @property
    def n_accepted(self) -> int:
        return len(self.accepted)

    @property
    def warnings(self) -> tuple[str, ...]:
        """What to know before trusting the diagnosis: the records' notes, how the run ended when that was not
        its own decision, and the final fit's warnings (the sentences of :attr:`notices`)."""
        return messages(self.notices)

    @property
    def notices(self) -> tuple[Notice, ...]:
        """:attr:`warnings` as records (code, message, numbers, advice)."""
        own = []
        if self.interrupted:
            own.append(Notice("STOP001", "interrupted (Ctrl-C): the chart holds what was accepted before", {},
                              "run again to trace the rest"))
        if self.stop == "first_fit_not_converged":
            moving = ", ".join(self.first_fit.still_moving) or "?"
            own.append(Notice("TRACE001", f"the first fit stopped ({self.first_fit.status}) while {moving} still "
                              "moved by more than their standard error: nothing was traced",
                              {"status": self.first_fit.status, "still_moving": list(self.first_fit.still_moving)},
                              "raise --max-iter, or start closer (or --allow-unconverged to trace anyway)"))
        return tuple(self.data_notices) + tuple(own) + tuple(self.identification.notices)

    def to_document(self) -> dict:
        """The REPORT.json body, a new dict each call (see :mod:`flowchart2sdnn.diagnose.document`)."""
        from .serialize import to_document

        return to_document(self)

    @cached_property
    def report(self) -> dict:
        """The REPORT.json body, built on first access and kept (for scripts that read the document's keys; the
        library itself reads the typed fields)."""
        return self.to_document()

    def to_json(self) -> str:
        """REPORT.json as text (strict JSON: non-finite numbers stored as null)."""
        from .serialize import dumps

        return dumps(self.to_document())
