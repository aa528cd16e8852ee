"""Warnings as data: a :class:`Notice` is one thing a finished run wants the user to know.

Errors stop a pass (:class:`~flowchart2sdnn.errors.SdnnError`); a notice does not, but it carries the same
kind of record: a stable code, the sentence a user reads (RESULT.json's ``warnings`` keeps it word for word),
the numbers in that sentence by name (so a reader never parses them back out of the text), and what to do.
Every code is listed in :data:`CODES` with what it means; docs/guide/warnings.md is its table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

__all__ = ["Notice", "CODES", "messages", "aligned"]

#: Every code a notice can carry, with what it means (the docs table; tests check both against the code).
CODES: Mapping[str, str] = MappingProxyType({
    "START001": "at its init the chart's network drifts away from rest (a negative slope at zero in a loop)",
    "START002": "a free quantity starts exactly on one of its bounds",
    "CONV001": "the offline fit stopped before it reached a minimum",
    "CONV002": "the fit converged at the noise floor while still creeping along a poorly determined direction",
    "CONV003": "several starts ended in different minima",
    "IDENT001": "physical parameters that cannot be told apart from this data",
    "IDENT002": "two parameters that are almost interchangeable (strongly correlated)",
    "STAB001": "the fitted network is close to chattering at rest",
    "SQRT001": "a sqrt block's argument went negative in the fitted model",
    "NOISE001": "the training residual is far above the noise read off the records",
    "LAG001": "the residual follows a held input at lag 0 (the input may move between its samples)",
    "SHOOT001": "a free run of the fitted chart does not follow the whole records (multiple shooting kept)",
    "FLOOR001": "the network's own step error is a visible part of the residual",
    "FLOOR002": "substeps auto was too coarse for the fitted curves: the fit was redone at more sub-steps",
    "FLOOR003": "the discretization-bias refit did not settle",
    "FLOOR004": "the discretization shifts parameters by more than half a standard error",
    "TIME001": "timestamps off the sample grid were snapped to it",
    "TIME002": "a record with gaps of missing samples was split into parts",
    "TIME003": "a record of another sample time was resampled",
    "TIME004": "of a record's parts only the longest is used",
    "READ001": "the CSV delimiter was detected from the header",
    "READ002": "a decimal comma was detected from the first data row",
    "JSON001": "non-finite values were stored as null in the document",
    "STOP001": "diagnose was interrupted (Ctrl-C): the chart holds what was accepted before",
    "TRACE001": "diagnose's first fit did not converge: nothing was traced",
})


@dataclass(frozen=True)
class Notice:
    """One warning of a run.

    code : str or None     a key of :data:`CODES`; None for a warning read back from a document without codes
    message : str          the sentence as the user reads it (RESULT.json's ``warnings`` entry)
    numbers : {name: value}   the values the message states, unrounded (floats, ints, strings)
    advice : str or None   what to do about it, when there is something to do
    """

    code: str | None
    message: str
    numbers: Mapping[str, object] = field(default_factory=dict)
    advice: str | None = None

    def __post_init__(self) -> None:
        if self.code is not None and self.code not in CODES:
            raise ValueError(f"unknown notice code {self.code!r} (add it to flowchart2sdnn.notices.CODES)")
        object.__setattr__(self, "numbers", dict(self.numbers))  # a copy: the caller's dict may change

    def __str__(self) -> str:
        return self.message

    def one_line(self, kind: str = "warning") -> str:
        """``warning[CODE] message`` as a lint diagnostic prints (``warning: message`` without a code); `kind`
        names it otherwise (``note[READ001] ...``)."""
        return f"{kind}[{self.code}] {self.message}" if self.code else f"{kind}: {self.message}"

    def to_dict(self) -> dict:
        """The document's form; a non-finite number becomes null (strict JSON)."""
        return {"code": self.code, "message": self.message,
                "numbers": {k: _finite(v) for k, v in self.numbers.items()}, "advice": self.advice}

    @classmethod
    def from_dict(cls, d: Mapping) -> Notice:
        code = d.get("code")
        return cls(code if code in CODES else None, str(d["message"]), dict(d.get("numbers") or {}),
                   d.get("advice"))

    def prefixed(self, prefix: str) -> Notice:
        """The same notice with `prefix` before its message (a record's file before its data note)."""
        return Notice(self.code, prefix + self.message, self.numbers, self.advice)


def messages(notices: Iterable[Notice]) -> tuple[str, ...]:
    """The sentences of `notices`, in order: what ``warnings`` holds."""
    return tuple(n.message for n in notices)


def aligned(warnings: Iterable[str | Notice], notices: Iterable[Notice]) -> tuple[Notice, ...]:
    """A notice per warning, in the warnings' order: the warning itself when it is a Notice, else the one of
    `notices` with that message, else an uncoded one. The sentences stay the source of truth, so code that edits
    ``warnings`` alone keeps the two in step."""
    by_message = {n.message: n for n in notices}
    return tuple(w if isinstance(w, Notice) else by_message.get(str(w)) or Notice(None, str(w)) for w in warnings)


def _finite(v):
    """`v` as plain JSON: numpy scalars as Python numbers, every non-finite float inside it (dicts, lists) as None."""
    if type(v).__module__ == "numpy" and hasattr(v, "item"):  # np.int64 is no int to json
        v = v.item()
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, Mapping):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v
