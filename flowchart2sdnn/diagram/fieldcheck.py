"""The checks of one field of a chart, shared by every section: a name, a string, a number, a flag, unknown
keys, each problem a :class:`~flowchart2sdnn.errors.Diagnostic` at its file, line and block
(:class:`FieldChecks`, the base of :mod:`.validate`'s validator), and the short forms of user values that
messages show."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping

from ..errors import Diagnostic, Location, did_you_mean
from .model import RESERVED
from .yamlload import LocatedYaml

__all__ = ["NAME_RE", "FieldChecks", "is_number", "finite_number", "show_value", "kind_of"]

NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_YAML11_BOOLS = {"yes": True, "on": True, "no": False, "off": False}


def is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def finite_number(x) -> bool:
    """A number that is a finite float; a YAML integer of 400 digits is not (math.isfinite would raise)."""
    if not is_number(x):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def show_value(value, quote: bool = True, limit: int = 40) -> str:
    """A short printable form of a user value for a message (repr of a huge int raises, a list may be huge)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"an integer of {value.bit_length()} bits"
    text = repr(value) if quote else str(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def kind_of(value) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return f"the text {show_value(value)}"
    if is_number(value):
        return f"the number {show_value(value)}"
    return type(value).__name__


class FieldChecks:
    """Collects the diagnostics of one chart document; the checks of single fields."""

    def __init__(self, doc: LocatedYaml):
        self.doc = doc
        self.diagnostics: list[Diagnostic] = []
        self.broken_blocks: set[str] = set()  # blocks that exist but failed to validate
        self._known: tuple[list[str] | None, frozenset[str]] = (None, frozenset())

    # -- reporting ---------------------------------------------------------------------------------
    def error(self, code: str, message: str, path: tuple = (), block: str | None = None, hint=None) -> None:
        loc = Location(self.doc.file, self.doc.line(*path), self.doc.column(*path))
        self.diagnostics.append(Diagnostic(code, "error", message, loc, block, hint))

    def loc(self, *path) -> Location:
        return Location(self.doc.file, self.doc.line(*path), self.doc.column(*path))

    def unknown_keys(self, mapping: Mapping, allowed, path: tuple, what: str, block=None) -> None:
        for key in mapping:
            if key not in allowed and not str(key).startswith("x-"):
                self.error(
                    "CHART003",
                    f"unknown key '{key}' in {what}; expected one of: {', '.join(allowed)}",
                    path + (key,),
                    block,
                    did_you_mean(key, allowed),
                )

    # -- fields ------------------------------------------------------------------------------------
    def check_name(self, name, path: tuple, what: str) -> bool:
        if not isinstance(name, str) or not NAME_RE.match(name):
            self.error(
                "CHART005",
                f"{what} name {show_value(name)} is not a valid name (letters, digits, '_', not starting with a digit)",
                path,
            )
            return False
        if name in RESERVED:
            self.error("CHART005", f"{what} name '{name}' is reserved", path)
            return False
        return True

    def optional_str(self, spec: Mapping, key: str, path: tuple, block=None) -> str | None:
        value = spec.get(key)
        if value is None:
            return None
        if is_number(value) and key == "unit":
            return str(value)
        if not isinstance(value, str):
            self.error("CHART004", f"'{key}' must be a string, found {kind_of(value)}", path + (key,), block)
            return None
        return value

    def number(self, spec: Mapping, key: str, path: tuple, block=None, default=None, required=False):
        if key not in spec or spec[key] is None:
            if required:
                self.error("CHART002", f"missing '{key}' (a number)", path, block)
            return default
        value = spec[key]
        if not is_number(value) or not finite_number(value):
            self.error("CHART004", f"'{key}' must be a finite number, found {show_value(value)}", path + (key,), block)
            return default
        return float(value)

    def flag(self, spec: Mapping, key: str, path: tuple, block=None, default=False) -> bool:
        value = spec.get(key, default)
        if value is None:
            return default
        if isinstance(value, str) and value.lower() in _YAML11_BOOLS:  # the loader reads only true/false
            return _YAML11_BOOLS[value.lower()]
        if not isinstance(value, bool):
            self.error("CHART004", f"'{key}' must be true or false, found {show_value(value)}", path + (key,), block)
            return default
        return value
