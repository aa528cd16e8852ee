"""The parts of a result that RESULT.json holds beside the fit itself, typed (:class:`Extra`).

Each is optional (None where the run did not make it): the discretization (sub-steps, floor, bias), the
multiple-shooting stages, how learned curves started, the validation record's fitted initial state, the
per-record parameters, the first fit of a sub-step refit, and, from the command line, the command and the
identified chart's file. Further keys of a document read back are kept in ``other``.

An :class:`Extra` is also a read-only mapping of those keys (the ones set, in document order, then ``other``)
so code and scripts that read ``result.extra["discretization"]`` keep working; an
:class:`~flowchart2sdnn.identify.result.Identification` given a plain dict turns it into one.

Layer: identify.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

__all__ = ["Extra"]


@dataclass(frozen=True)
class Extra(Mapping):
    """RESULT.json's further keys; the field names are the keys."""

    discretization: Mapping[str, Any] | None = None
    shooting: Mapping[str, Any] | None = None
    curve_start: Any = None
    initial_states: Mapping[str, Any] | None = None
    parameters_per_record: Mapping[str, Any] | None = None
    substeps_refit: Mapping[str, Any] | None = None
    command: Mapping[str, Any] | None = None
    identified_chart: str | None = None
    other: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def of(cls, items: Mapping[str, Any] | None) -> Extra:
        """An Extra from a mapping of document keys (an Extra as it is)."""
        if isinstance(items, Extra):
            return items
        items = dict(items or {})
        known = {f.name for f in fields(cls)} - {"other"}
        # a key the document holds as null stays a key: it goes to `other` (a typed field's None means absent)
        return cls(**{k: v for k, v in items.items() if k in known and v is not None},
                   other={k: v for k, v in items.items() if k not in known or v is None})

    def _typed(self) -> list[str]:
        return [f.name for f in fields(self) if f.name != "other" and getattr(self, f.name) is not None]

    def __getitem__(self, key: str) -> Any:
        if key != "other" and key in self.__dataclass_fields__ and getattr(self, key) is not None:
            return getattr(self, key)
        return self.other[key]

    def __iter__(self) -> Iterator[str]:
        typed = self._typed()
        yield from typed
        yield from (k for k in self.other if k not in typed)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    # a dataclass's own == compares the fields; as a mapping it equals any mapping with the same items
    def __eq__(self, other: object) -> bool:
        return isinstance(other, Mapping) and dict(self.items()) == dict(other.items())
