"""Unit algebra for lint: parse ``N*m*s/rad``, multiply, compare, and infer the unit of a gain expression.

A :class:`Unit` is a vector of rational exponents over the SI base (kg, m, s, A, K, mol, cd) and a scale to
SI. Angles are dimensionless on purpose (``rad`` is 1, ``deg`` is pi/180, ``rev`` is 2*pi), so a torque over
an inertia, N*m/(kg*m^2), equals rad/s^2 and 1/s^2.

Unit grammar (symbols come from an explicit table, no generic prefixes)::

    unit     := factor (('*' | '/') factor)*       ('*' after '/' at the same level is refused as ambiguous)
    factor   := atom ('^' exponent)?
    atom     := SYMBOL | '1' | '(' unit ')'
    exponent := ['-'] NUMBER | '(' ['-'] NUMBER ['/' INT] ')'      NUMBER: 2, or a decimal such as 0.5 or 1.5

A decimal exponent must be a simple fraction (``V^0.5`` is ``V^(1/2)``; ``V^0.333`` is refused: write
``V^(1/3)``); a square root of a unit (``f: sqrt``) prints with a fractional exponent.
``kg/m*s`` is refused because readers split between (kg/m)*s and kg/(m*s): write ``kg*s/m`` or
``kg/(m*s)``. ``str()`` of a unit with scale 1 re-parses to an equal unit; a scaled one prints its factor
first (``0.001*m*s^-1``), which is readable but not parseable.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from fractions import Fraction
from types import MappingProxyType

from ..errors import did_you_mean
from ..expr import BinOp, Expr, ExprError, Neg, Num, Var

__all__ = ["UnitError", "Unit", "BASE_SYMBOLS", "DIMENSIONLESS", "SYMBOLS", "parse_unit", "unit_of_expr"]

BASE_SYMBOLS = ("kg", "m", "s", "A", "K", "mol", "cd")
MAX_LENGTH = 200
MAX_DEPTH = 10
MAX_EXPONENT = 10
_TOKEN = re.compile(r"\s*(?:(?P<name>[A-Za-z_][A-Za-z0-9_]*)|(?P<int>[0-9]+(?:\.[0-9]+)?)|(?P<op>[*/^()+-]))")
_HINT = {"µ": "write 'u' for micro, e.g. 'um'", "μ": "write 'u' for micro, e.g. 'um'", "·": "write '*'",
         "²": "write '^2'", "³": "write '^3'", "°": "write 'deg'", "Ω": "write 'Ohm'", ".": "write '*'"}
_ALIASES = {"sec": "s", "secs": "s", "hr": "h", "Nms": "N*m*s", "kgm2": "kg*m^2"}


class UnitError(ValueError):
    """A unit that cannot be parsed, or units that do not fit together.

    `column` is the 1-based position in the unit text when known; `hint` an optional fix.
    """

    def __init__(self, message: str, column: int | None = None, hint: str | None = None):
        super().__init__(f"{message} ({hint})" if hint else message)
        self.message = message
        self.column = column
        self.hint = hint


@dataclass(frozen=True)
class Unit:
    """Exponents `dims` over :data:`BASE_SYMBOLS` and a positive `scale` to SI (mm has scale 1e-3)."""

    dims: tuple[Fraction, ...] = (Fraction(0),) * 7
    scale: float = 1.0

    def __post_init__(self) -> None:
        dims = tuple(Fraction(d) for d in self.dims)
        if len(dims) != len(BASE_SYMBOLS):
            raise ValueError(f"a unit needs {len(BASE_SYMBOLS)} exponents, found {len(dims)}")
        scale = float(self.scale)
        if not (math.isfinite(scale) and scale > 0):
            raise UnitError(f"unit scale {scale!r} is out of range; expected a finite positive number")
        object.__setattr__(self, "dims", dims)
        object.__setattr__(self, "scale", scale)

    def __mul__(self, other: Unit) -> Unit:
        if not isinstance(other, Unit):
            return NotImplemented
        return Unit(tuple(a + b for a, b in zip(self.dims, other.dims, strict=True)), self.scale * other.scale)

    def __truediv__(self, other: Unit) -> Unit:
        if not isinstance(other, Unit):
            return NotImplemented
        return Unit(tuple(a - b for a, b in zip(self.dims, other.dims, strict=True)), self.scale / other.scale)

    def __pow__(self, p: Fraction | int) -> Unit:
        if isinstance(p, bool) or not isinstance(p, (int, Fraction)):
            return NotImplemented
        try:
            scale = self.scale ** float(p)
        except OverflowError:
            raise UnitError(f"({self})^{p} is out of range") from None
        return Unit(tuple(d * p for d in self.dims), scale)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Unit):
            return NotImplemented
        return self.dims == other.dims and math.isclose(self.scale, other.scale, rel_tol=1e-12)

    def __hash__(self) -> int:  # equal units may differ in the last bits of scale
        return hash(self.dims)

    def same_dimension(self, other: Unit) -> bool:
        """True when the exponents agree, whatever the scales (mm/s and m/s)."""
        return self.dims == other.dims

    @property
    def is_dimensionless(self) -> bool:
        """True when every exponent is zero (``1``, ``rad``, ``deg``; the scale may differ from 1)."""
        return not any(self.dims)

    def __str__(self) -> str:
        parts = []
        for sym, p in zip(BASE_SYMBOLS, self.dims, strict=True):
            if p != 0:
                exp = "" if p == 1 else f"^{p}" if p.denominator == 1 else f"^({p})"
                parts.append(sym + exp)
        text = "*".join(parts)
        if not math.isclose(self.scale, 1.0, rel_tol=1e-12):
            text = f"{self.scale:.12g}" + (f"*{text}" if text else "")
        return text or "1"


DIMENSIONLESS = Unit()


def _base(i: int) -> Unit:
    return Unit(tuple(Fraction(int(i == j)) for j in range(len(BASE_SYMBOLS))))


def _times(factor: float, u: Unit) -> Unit:
    return Unit(u.dims, u.scale * factor)


def _table() -> dict[str, Unit]:
    kg, m, s, A, K, mol, cd = (_base(i) for i in range(len(BASE_SYMBOLS)))
    N = kg * m / s**2
    J = N * m
    W = J / s
    V = W / A
    C = A * s
    Wb = V * s
    Pa = N / m**2
    rev = _times(2 * math.pi, DIMENSIONLESS)
    return {
        "kg": kg, "g": _times(1e-3, kg),
        "m": m, "mm": _times(1e-3, m), "cm": _times(1e-2, m), "km": _times(1e3, m), "um": _times(1e-6, m),
        "s": s, "ms": _times(1e-3, s), "us": _times(1e-6, s), "min": _times(60, s), "h": _times(3600, s),
        "A": A, "mA": _times(1e-3, A), "K": K, "mol": mol, "cd": cd,
        "rad": DIMENSIONLESS, "deg": _times(math.pi / 180, DIMENSIONLESS), "rev": rev,
        "rpm": rev / _times(60, s), "Hz": DIMENSIONLESS / s,
        "N": N, "mN": _times(1e-3, N), "kN": _times(1e3, N), "Nm": N * m,
        "J": J, "W": W, "kW": _times(1e3, W), "V": V, "mV": _times(1e-3, V),
        "Ohm": V / A, "H": Wb / A, "F": C / V, "C": C, "T": Wb / m**2, "Wb": Wb,
        "Pa": Pa, "bar": _times(1e5, Pa),
    }


SYMBOLS: Mapping[str, Unit] = MappingProxyType(_table())


def _tokens(text: str) -> Iterator[tuple[str, str, int]]:
    """(kind, text, column) lazily; kinds are name, int, an operator character, and end."""
    i = 0
    while i < len(text):
        if text[i:].strip() == "":
            break
        m = _TOKEN.match(text, i)
        if m is None:
            j = len(text) - len(text[i:].lstrip())
            ch = text[j]
            hint = "write a fractional exponent as ^(3/2)" if text[j - 1 : j].isdigit() else _HINT.get(ch)
            raise UnitError(f"unexpected character {ch!r} at column {j + 1}; expected a unit symbol, "
                            "'*', '/', '^' or a parenthesis", j + 1, hint)
        kind = m.lastgroup or "op"
        yield (m.group(kind) if kind == "op" else kind), m.group(kind), m.start(kind) + 1
        i = m.end()
    yield "end", "", len(text) + 1


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.stream = _tokens(text)
        self.tok = next(self.stream)
        self.depth = 0

    def advance(self) -> tuple[str, str, int]:
        tok = self.tok
        if tok[0] != "end":
            self.tok = next(self.stream)
        return tok

    def fail(self, expected: str) -> UnitError:
        kind, text, col = self.tok
        what = "end of unit" if kind == "end" else f"'{text}' at column {col}"
        return UnitError(f"unexpected {what} in '{self.text}'; expected {expected}", col)

    def unit(self) -> Unit:
        result = self.factor()
        seen_slash = False
        while self.tok[0] in ("*", "/"):
            op, _, col = self.advance()
            if op == "*" and seen_slash:
                raise UnitError(f"ambiguous '*' after '/' at column {col} in '{self.text}'; expected the "
                                "denominator in parentheses, e.g. 'kg/(m*s)', or 'kg*s/m'", col)
            seen_slash = seen_slash or op == "/"
            rhs = self.factor()
            result = result * rhs if op == "*" else result / rhs
        return result

    def factor(self) -> Unit:
        kind, text, col = self.tok
        if kind == "name":
            if text not in SYMBOLS:
                folded = [s for s in SYMBOLS if s.lower() == text.lower()] + [_ALIASES.get(text, "")]
                hint = f"did you mean '{folded[0]}'?" if folded[0] else did_you_mean(text, SYMBOLS)
                raise UnitError(f"unknown unit '{text}' at column {col}; expected one of "
                                f"{', '.join(SYMBOLS)}", col, hint)
            base = SYMBOLS[text]
        elif kind == "int" and text == "1":
            base = DIMENSIONLESS
        elif kind == "int":
            raise UnitError(f"unexpected number '{text}' at column {col}; expected a unit symbol "
                            "(only '1' may stand for dimensionless)", col)
        elif kind == "(":
            self.depth += 1
            if self.depth > MAX_DEPTH:
                raise UnitError(f"unit nested too deeply at column {col}; expected at most {MAX_DEPTH} "
                                "levels of parentheses", col)
            self.advance()
            base = self.unit()
            if self.tok[0] != ")":
                raise self.fail("'*', '/' or ')'")
            self.depth -= 1
        else:
            raise self.fail("a unit symbol, '1' or '('")
        self.advance()
        if self.tok[0] != "^":
            return base
        self.advance()
        return base ** self.exponent()

    def exponent(self) -> Fraction:
        col = self.tok[2]
        grouped = self.tok[0] == "("
        if grouped:
            self.advance()
        sign = -1 if self.tok[0] == "-" else 1
        if self.tok[0] in ("-", "+"):
            self.advance()
        if self.tok[0] != "int":
            raise self.fail("an exponent such as 2, -1, 0.5 or (1/2)")
        text = self.advance()[1]
        p = sign * Fraction(text)
        if p.denominator > 100:  # 0.333 is not 1/3: say which fraction is meant
            raise UnitError(f"exponent {text} at column {col} is not a simple fraction; expected e.g. 0.5 or "
                            "(1/3)", col, "write a fraction as ^(1/3)")
        if grouped:
            if self.tok[0] == "/":
                self.advance()
                if self.tok[0] != "int" or not self.tok[1].isdigit() or int(self.tok[1]) == 0:
                    raise self.fail("a positive integer denominator")
                p /= int(self.advance()[1])
            if self.tok[0] != ")":
                raise self.fail("')' closing the exponent")
            self.advance()
        if abs(p) > MAX_EXPONENT:
            raise UnitError(f"exponent {p} at column {col} is out of range; expected at most {MAX_EXPONENT} "
                            "in magnitude", col)
        return p


def parse_unit(text: str) -> Unit:
    """Parse a unit such as ``"N*m*s/rad"``, ``"kg/(m*s)"``, ``"m^(1/2)"`` or ``"1"``.

    Parameters
    ----------
    text : str
        Products and quotients of symbols from :data:`SYMBOLS` with optional exponents.

    Returns
    -------
    Unit

    Raises
    ------
    UnitError
        With a 1-based `column`, for unknown symbols (with a did-you-mean hint) and bad syntax.
    """
    if not isinstance(text, str):
        raise UnitError(f"expected a unit such as 'N*m', found {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise UnitError(f"unit is {len(text)} characters long; expected at most {MAX_LENGTH}")
    parser = _Parser(text)
    if parser.tok[0] == "end":
        raise UnitError("empty unit; expected a unit such as 'N*m', or '1' for dimensionless", 1)
    unit = parser.unit()
    if parser.tok[0] != "end":
        raise parser.fail("'*', '/' or the end")
    return unit


def unit_of_expr(expr: Expr, units: Mapping[str, Unit | None]) -> Unit | None:
    """The unit of a gain expression given the units of its parameters.

    Numbers and ``pi`` are dimensionless; ``+`` and ``-`` need equal units (adding a literal 0 is always
    fine); ``^`` needs a dimensionless exponent, which must be a constant (a rational with denominator at
    most 100) unless the base is dimensionless.

    Returns
    -------
    Unit or None
        None when a parameter used by `expr` has no unit (missing or None): nothing can be checked.

    Raises
    ------
    UnitError
        When the units do not fit together; the message names the sub-expressions and their units.
    """
    if any(units.get(name) is None for name in expr.variables):
        return None
    return _unit(expr, units)


def _unit(e: Expr, units: Mapping[str, Unit | None]) -> Unit:
    if isinstance(e, Num):
        return DIMENSIONLESS
    if isinstance(e, Var):
        unit = units[e.name]
        assert unit is not None
        return unit
    if isinstance(e, Neg):
        return _unit(e.arg, units)
    assert isinstance(e, BinOp)
    left, right = _unit(e.left, units), _unit(e.right, units)
    if e.op == "*":
        return left * right
    if e.op == "/":
        return left / right
    if e.op == "^":
        return _power(e, left, right)
    for zero, other in ((e.left, right), (e.right, left)):
        if isinstance(zero, Num) and zero.value == 0:
            return other
    if left != right:
        verb = "add" if e.op == "+" else "subtract"
        raise UnitError(f"cannot {verb} '{e.left}' [{left}] and '{e.right}' [{right}] in '{e}': the units "
                        "differ; expected equal units")
    return left


def _power(e: BinOp, base: Unit, exponent: Unit) -> Unit:
    if exponent != DIMENSIONLESS:
        raise UnitError(f"exponent '{e.right}' in '{e}' has unit [{exponent}]; expected a dimensionless one")
    if base == DIMENSIONLESS:
        return DIMENSIONLESS
    if not e.right.is_constant:
        raise UnitError(f"'{e}': a quantity in [{base}] raised to '{e.right}', which depends on parameters; "
                        "expected a constant exponent")
    try:
        x = e.right.evaluate({})
    except ExprError as exc:
        raise UnitError(f"exponent '{e.right}' in '{e}': {exc.message}") from None
    p = Fraction(x).limit_denominator(100)
    if abs(float(p) - x) > 1e-9 * max(1.0, abs(x)):
        raise UnitError(f"exponent {x!r} in '{e}' is not a simple fraction; expected a rational power of "
                        f"[{base}]")
    return base**p
