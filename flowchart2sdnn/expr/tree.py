"""The expression tree: frozen nodes that evaluate, differentiate, substitute and print (``str()`` re-parses
to an equal tree), the smart constructors that fold constants, and the limits and the error of
:mod:`flowchart2sdnn.expr`."""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ..errors import did_you_mean

__all__ = ["ExprError", "Expr", "Num", "Var", "Neg", "BinOp", "const", "add", "sub", "mul", "div", "power", "neg",
           "MAX_LENGTH", "MAX_DEPTH", "MAX_NODES", "NAME_RE"]

MAX_LENGTH = 1000
MAX_DEPTH = 50
MAX_NODES = 500
_PREC = {"+": 1, "-": 1, "*": 2, "/": 2, "^": 4}  # a sign sits at 3, atoms at 5
NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class ExprError(ValueError):
    """A gain expression that cannot be parsed or evaluated.

    `column` is the 1-based position in the expression text when known; `hint` is an optional fix
    (e.g. "did you mean 'J1'?"), also appended to ``str(exc)``.
    """

    def __init__(self, message: str, column: int | None = None, hint: str | None = None):
        super().__init__(f"{message} ({hint})" if hint else message)
        self.message = message
        self.column = column
        self.hint = hint


def _short(e: object) -> str:
    text = str(e)
    return text if len(text) <= 60 else text[:57] + "..."


def _apply(op: str, a: float, b: float) -> float:
    """One IEEE operation, refusing what a physical gain cannot be: x/0, complex, inf or nan."""
    if op == "/" and b == 0.0:
        raise ExprError("division by zero")
    try:
        r = a + b if op == "+" else a - b if op == "-" else a * b if op == "*" else a / b if op == "/" \
            else math.pow(a, b)
    except OverflowError:
        raise ExprError("overflow: the result is too large") from None
    except ValueError:  # math.pow: negative ** fractional, 0 ** negative
        raise ExprError(f"{_num_text(a)}^{_num_text(b)} has no real value") from None
    if not math.isfinite(r):
        raise ExprError("overflow: the result is not finite")
    return r


def _num_text(v: float) -> str:
    if v == math.pi or v == -math.pi:
        return "pi" if v > 0 else "-pi"
    if v.is_integer() and abs(v) < 1e16:
        return str(int(v))
    return repr(v)


class Expr:
    """Base of the frozen nodes :class:`Num`, :class:`Var`, :class:`Neg` and :class:`BinOp`.

    Build trees with :func:`parse_expr` or the smart constructors (:func:`add`, :func:`mul`, ...).
    """

    @property
    def variables(self) -> frozenset[str]:
        """The parameter names used (``pi`` is a number, not a name)."""
        if isinstance(self, Var):
            return frozenset((self.name,))
        return frozenset().union(*(k.variables for k in _kids(self)))

    @property
    def is_constant(self) -> bool:
        """True when the expression uses no parameter."""
        return not self.variables

    def evaluate(self, env: Mapping[str, float]) -> float:
        """The value for parameter values `env`.

        Raises ExprError for an unknown name, a division by zero, an overflow, or a complex result.
        """
        if isinstance(self, Num):
            return self.value
        if isinstance(self, Var):
            if self.name not in env:
                raise ExprError(f"unknown name '{self.name}'", hint=did_you_mean(self.name, env))
            try:
                value = float(env[self.name])
            except (TypeError, ValueError):
                raise ExprError(f"'{self.name}' is {env[self.name]!r}; expected a number") from None
            if not math.isfinite(value):
                raise ExprError(f"'{self.name}' = {value}; expected a finite number")
            return value
        if isinstance(self, Neg):
            return -self.arg.evaluate(env)
        assert isinstance(self, BinOp)
        a, b = self.left.evaluate(env), self.right.evaluate(env)
        try:
            return _apply(self.op, a, b)
        except ExprError as exc:
            raise ExprError(f"{exc.message} in '{_short(self)}'") from None

    def diff(self, name: str) -> Expr:
        """Exact symbolic derivative with respect to `name`, simplified by the smart constructors.

        A power whose exponent depends on `name` needs log(base): that works only for a positive
        constant base (the language has no log) and raises ExprError otherwise.
        """
        if name not in self.variables:
            return Num(0.0)
        if isinstance(self, Var):
            return Num(1.0)
        if isinstance(self, Neg):
            return neg(self.arg.diff(name))
        assert isinstance(self, BinOp)
        a, b, op = self.left, self.right, self.op
        da, db = a.diff(name), b.diff(name)
        if op in "+-":
            return _SMART[op](da, db)
        if op == "*":
            return add(mul(da, b), mul(a, db))
        if op == "/":
            return sub(div(da, b), div(mul(a, db), power(b, Num(2.0))))
        if name not in b.variables:  # d(a^c) = c*a^(c-1)*da
            return mul(mul(b, power(a, sub(b, Num(1.0)))), da)
        if a.is_constant and a.evaluate({}) > 0:  # d(c^b) = c^b*log(c)*db
            return mul(mul(self, Num(math.log(a.evaluate({})))), db)
        raise ExprError(f"cannot differentiate '{_short(self)}' with respect to '{name}': the exponent depends "
                        f"on '{name}', which needs log() of the base; expected a positive constant base")

    def substitute(self, env: Mapping[str, Expr | float]) -> Expr:
        """Replace the names in `env` by expressions or numbers.

        The tree is rebuilt by the smart constructors, so constant sub-expressions fold.
        """
        if isinstance(self, Var):
            return _as_expr(env[self.name]) if self.name in env else self
        if isinstance(self, Neg):
            return neg(self.arg.substitute(env))
        if isinstance(self, BinOp):
            return _SMART[self.op](self.left.substitute(env), self.right.substitute(env))
        return self

    def __str__(self) -> str:
        """Canonical text with the fewest parentheses; it re-parses to an equal tree."""
        if isinstance(self, Num):
            return _num_text(self.value)
        if isinstance(self, Var):
            return self.name
        if isinstance(self, Neg):
            return "-" + _wrap(self.arg, _prec(self.arg) < 3)
        assert isinstance(self, BinOp)
        p, lp, rp = _PREC[self.op], _prec(self.left), _prec(self.right)
        # '^' is right-associative and its exponent may carry a sign; the others are left-associative
        wrap_left, wrap_right = (lp <= 4, rp < 3) if self.op == "^" else (lp < p, rp <= p)
        left, right = _wrap(self.left, wrap_left), _wrap(self.right, wrap_right)
        return f"{left} {self.op} {right}" if p == 1 else f"{left}{self.op}{right}"


def _kids(e: Expr) -> tuple[Expr, ...]:
    return (e.arg,) if isinstance(e, Neg) else (e.left, e.right) if isinstance(e, BinOp) else ()


def _prec(e: Expr) -> int:
    if isinstance(e, Num):
        return 5 if e.value >= 0 else 3  # a negative number prints with a sign
    return 3 if isinstance(e, Neg) else _PREC[e.op] if isinstance(e, BinOp) else 5


def _wrap(e: Expr, wrap: bool) -> str:
    return f"({e})" if wrap else str(e)


@dataclass(frozen=True)
class Num(Expr):
    """A finite number (``pi`` included)."""

    value: float

    def __post_init__(self) -> None:
        if isinstance(self.value, bool) or not isinstance(self.value, numbers.Real):
            raise TypeError(f"Num needs a real number, found {type(self.value).__name__}")
        value = float(self.value)
        if not math.isfinite(value):
            raise ExprError(f"number {value!r} is not finite; expected a finite number")
        object.__setattr__(self, "value", value)


@dataclass(frozen=True)
class Var(Expr):
    """A parameter name (``pi`` is reserved for the constant)."""

    name: str

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not NAME_RE.fullmatch(self.name) or self.name == "pi":
            raise ExprError(f"{self.name!r} is not a parameter name; expected letters, digits and '_', not 'pi'")


@dataclass(frozen=True)
class Neg(Expr):
    """Unary minus."""

    arg: Expr


@dataclass(frozen=True)
class BinOp(Expr):
    """A binary operation; `op` is one of ``+ - * / ^``."""

    op: str
    left: Expr
    right: Expr

    def __post_init__(self) -> None:
        if self.op not in _PREC:
            raise ValueError(f"unknown operator {self.op!r}; expected one of + - * / ^")


# --- smart constructors ------------------------------------------------------------------------------
def _as_expr(x: Expr | float) -> Expr:
    return x if isinstance(x, Expr) else Num(x)


def _is(e: Expr, value: float) -> bool:
    return isinstance(e, Num) and e.value == value


def _build(op: str, a: Expr | float, b: Expr | float) -> Expr:
    a, b = _as_expr(a), _as_expr(b)
    if isinstance(a, Num) and isinstance(b, Num):
        try:
            return Num(_apply(op, a.value, b.value))
        except ExprError:  # leave 1/0 or an overflow in the tree: evaluate() reports it in context
            pass
    if op in "+-" and _is(b, 0):
        return a
    if op == "+" and _is(a, 0):
        return b
    if op == "-" and _is(a, 0):
        return neg(b)
    if op == "*":
        if _is(a, 0) or _is(b, 0):
            return Num(0.0)
        for one, other in ((a, b), (b, a)):
            if _is(one, 1) or _is(one, -1):
                return other if one.value == 1 else neg(other)
    if op == "/" and (_is(a, 0) or _is(b, 1) or _is(b, -1)):
        return Num(0.0) if _is(a, 0) else a if _is(b, 1) else neg(a)
    if op == "^" and (_is(b, 0) or _is(b, 1) or _is(a, 1)):
        return a if _is(b, 1) else Num(1.0)
    return BinOp(op, a, b)


def const(value: float) -> Expr:
    """A number node; ExprError for nan or inf, TypeError for a bool or a non-number."""
    return Num(value)


def neg(a: Expr | float) -> Expr:
    """``-a``, folding numbers and ``--x``."""
    a = _as_expr(a)
    return Num(-a.value) if isinstance(a, Num) else a.arg if isinstance(a, Neg) else Neg(a)


def add(a: Expr | float, b: Expr | float) -> Expr:
    """``a + b``, folding numbers and dropping ``0 +``."""
    return _build("+", a, b)


def sub(a: Expr | float, b: Expr | float) -> Expr:
    """``a - b``, folding numbers, dropping ``- 0`` and turning ``0 - b`` into ``-b``."""
    return _build("-", a, b)


def mul(a: Expr | float, b: Expr | float) -> Expr:
    """``a*b``, folding numbers, ``0*x -> 0``, ``1*x -> x`` and ``-1*x -> -x``."""
    return _build("*", a, b)


def div(a: Expr | float, b: Expr | float) -> Expr:
    """``a/b``, folding numbers, ``0/x -> 0``, ``x/1 -> x`` and ``x/-1 -> -x``."""
    return _build("/", a, b)


def power(a: Expr | float, b: Expr | float) -> Expr:
    """``a^b``, folding numbers, ``x^1 -> x``, ``x^0 -> 1`` and ``1^x -> 1``."""
    return _build("^", a, b)


_SMART: dict[str, Callable[[Expr, Expr], Expr]] = {"+": add, "-": sub, "*": mul, "/": div, "^": power}
