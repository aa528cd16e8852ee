"""Diagnostics as data, and the one exception type that carries them.

Every check in the library reports a :class:`Diagnostic`; the CLI is the only place that prints one.
A :class:`SdnnError` is raised when a pass cannot go on; it carries one or more diagnostics, and its
``str()`` is the one-line message a user sees (``file:line: error[CODE] block 'x': message (hint)``).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

__all__ = ["Location", "Diagnostic", "SdnnError", "did_you_mean"]


@dataclass(frozen=True)
class Location:
    """Where something is: a file and, when known, a 1-based line and column (or a CSV row)."""

    file: str
    line: int | None = None
    column: int | None = None

    def __str__(self) -> str:
        text = self.file
        if self.line is not None:
            text += f":{self.line}"
            if self.column is not None:
                text += f":{self.column}"
        return text


@dataclass(frozen=True)
class Diagnostic:
    """One finding of a check: a stable code, a severity, where, which block, what, and how to fix it."""

    code: str
    severity: str  # "error" | "warning" | "info"
    message: str
    location: Location | None = None
    block: str | None = None
    hint: str | None = None

    def one_line(self) -> str:
        where = f"{self.location}: " if self.location is not None else ""
        who = f"block '{self.block}': " if self.block else ""
        hint = f" (hint: {self.hint})" if self.hint else ""
        text = f"{where}{self.severity}[{self.code}] {who}{self.message}{hint}"
        return " ".join(text.split())  # never more than one line, whatever the message held

    def to_dict(self) -> dict:
        return {
            "code": self.code,
            "severity": self.severity,
            "message": self.message,
            "file": self.location.file if self.location else None,
            "line": self.location.line if self.location else None,
            "column": self.location.column if self.location else None,
            "block": self.block,
            "hint": self.hint,
        }


class SdnnError(Exception):
    """A failure that a user can fix: bad chart, bad data, bad option. Carries diagnostics."""

    def __init__(self, diagnostics: Diagnostic | Sequence[Diagnostic]):
        if isinstance(diagnostics, Diagnostic):
            diagnostics = [diagnostics]
        self.diagnostics: tuple[Diagnostic, ...] = tuple(diagnostics)
        if not self.diagnostics:
            raise ValueError("SdnnError needs at least one diagnostic")
        super().__init__(self.diagnostics[0].one_line())

    @classmethod
    def at(
        cls,
        code: str,
        message: str,
        file: str | None = None,
        line: int | None = None,
        column: int | None = None,
        block: str | None = None,
        hint: str | None = None,
    ) -> SdnnError:
        location = Location(file, line, column) if file is not None else None
        return cls(Diagnostic(code, "error", message, location, block, hint))

    def __str__(self) -> str:
        return self.diagnostics[0].one_line()


def did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    """A hint naming the closest candidate, or None when nothing is close."""
    close = difflib.get_close_matches(str(name), sorted(set(map(str, candidates))), n=1, cutoff=0.6)
    return f"did you mean '{close[0]}'?" if close else None
