"""Column expressions of ``--map``: a CSV header times or divided by constants, ``speed_rpm*2*pi/60``.

``--map NAME=SOURCE`` reads chart signal NAME from SOURCE. SOURCE is a header when the file has a header of
exactly that text (``speed [rpm]`` included); otherwise it is a column expression in the whitelisted
expression language of gains (:mod:`flowchart2sdnn.expr`, never ``eval``): one header, written as a plain
name (letters, digits, ``_``), multiplied or divided by numbers and ``pi`` (``speed_rpm*2*pi/60``,
``position_mm/1000``, ``-torque``, ``(2*pi/60)*speed_rpm``). Sums, powers of the header, a header in a
denominator or two headers are refused: a scale is all a unit conversion needs.

Layer 2 (data): imports only the expression language and errors.
"""

from __future__ import annotations

import math

from ..expr import BinOp, Expr, ExprError, Neg, Num, Var, parse_expr

__all__ = ["column_scale", "source_header", "EXAMPLE"]

EXAMPLE = "speed_rpm*2*pi/60"


def _power(e: Expr, header: str) -> int:
    """The power of `header` in a product/quotient tree; ExprError where the header sits in a sum or power."""
    if isinstance(e, Num):
        return 0
    if isinstance(e, Var):
        return 1
    if isinstance(e, Neg):
        return _power(e.arg, header)
    assert isinstance(e, BinOp)
    left, right = _power(e.left, header), _power(e.right, header)
    if e.op == "*":
        return left + right
    if e.op == "/":
        return left - right
    if left or right:
        what = "a power of" if e.op == "^" else "a sum with"
        raise ExprError(f"'{e}' is {what} the column; expected the column times or divided by constants")
    return 0


def column_scale(text: str) -> tuple[str, float]:
    """The header and the factor of a column expression (``"speed_rpm*2*pi/60"`` -> ``("speed_rpm", 0.1047...)``).

    Raises
    ------
    ExprError
        When `text` does not parse, names no header or two, or is not the header times or divided by
        constants; the message says what was expected.
    """
    e = parse_expr(text)
    names = sorted(e.variables)
    if len(names) != 1:
        found = "no header" if not names else f"{len(names)} headers ({', '.join(names)})"
        raise ExprError(f"{found}; expected one header times or divided by constants, e.g. {EXAMPLE}")
    header = names[0]
    power = _power(e, header)
    if power != 1:
        raise ExprError(f"the column '{header}' enters to the power {power}; expected it times or divided by "
                        f"constants, e.g. {EXAMPLE}")
    factor = e.evaluate({header: 1.0})
    if factor == 0 or not math.isfinite(factor):
        raise ExprError(f"the factor is {factor!r}; expected a finite non-zero scale")
    return header, factor


def source_header(text: str) -> str:
    """The header `text` reads: itself, or the one header of a column expression (best effort, no error)."""
    try:
        return column_scale(text)[0]
    except ExprError:
        return text
