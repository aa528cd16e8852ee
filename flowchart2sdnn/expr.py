"""Whitelisted arithmetic for gains such as ``1/J1``, ``2*pi*r`` or ``-c``; user text is never ``eval``-ed.

Grammar (``^`` is right-associative and binds tighter than a sign, so ``-x^2`` is ``-(x^2)``)::

    expr  := term (('+' | '-') term)*
    term  := unary (('*' | '/') unary)*
    unary := ('+' | '-') unary | power
    power := atom ('^' unary)?
    atom  := NUMBER | NAME | 'pi' | '(' expr ')'

A sign applied directly to a number is folded into it (``-2`` is ``Num(-2.0)``), and ``pi`` is
``Num(math.pi)``. Limits keep hostile text cheap: at most 1000 characters, 500 nodes, and 50 levels of
nesting, counted twice: in the text (each parenthesis, sign and ``^``) and in the tree (each operation,
so a chain ``a+b+...`` has at most 50 terms). The tree limit keeps every recursive walk, derivatives
included, far from Python's recursion limit.

Arithmetic is IEEE double precision and every intermediate value must be finite, so ``2^2^2^2^2^2``
fails at once with an overflow instead of building a huge integer; powers use :func:`math.pow`, which
refuses a complex result (negative base, fractional exponent) instead of returning one.
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass

from .errors import did_you_mean

__all__ = ["ExprError", "Expr", "Num", "Var", "Neg", "BinOp", "parse_expr",
           "const", "add", "sub", "mul", "div", "power", "neg", "MAX_LENGTH", "MAX_DEPTH", "MAX_NODES"]

MAX_LENGTH = 1000
MAX_DEPTH = 50
MAX_NODES = 500
_PREC = {"+": 1, "-": 1, "*": 2, "/": 2, "^": 4}  # a sign sits at 3, atoms at 5
_NUMBER = re.compile(r"(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_WORD = re.compile(r"[A-Za-z0-9_.]*")
_WHY = {"'": "strings are not allowed", '"': "strings are not allowed", "[": "indexing is not allowed",
        "]": "indexing is not allowed", ",": "commas are not allowed", ".": "attribute access is not allowed",
        "=": "comparisons and assignments are not allowed", "%": "only + - * / ^ are allowed"}


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
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name) or self.name == "pi":
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


# --- parsing -----------------------------------------------------------------------------------------
def _tokens(text: str) -> Iterator[tuple[str, str, int]]:
    """(kind, text, column) lazily, so the parser reports the first problem in reading order."""
    i, n = 0, len(text)
    while i < n:
        ch, col = text[i], i + 1
        if ch in " \t\r\n":
            i += 1
            continue
        m = _NUMBER.match(text, i) or _NAME.match(text, i)
        if m and m.re is _NUMBER:
            tail = _WORD.match(text, m.end()).end()
            if tail > m.end():
                raise ExprError(f"malformed number '{text[i:tail]}' at column {col}; expected a number such "
                                "as 2, 0.5 or 1e-3 (write '*' for a product)", col)
            yield "num", m.group(), col
        elif m:
            if text.startswith(".", m.end()):
                raise ExprError(f"unexpected '.' at column {m.end() + 1}: attribute access is not allowed; "
                                "expected an operator", m.end() + 1)
            yield "name", m.group(), col
        elif text.startswith("**", i):
            raise ExprError(f"unexpected '**' at column {col}; expected '^' for a power", col)
        elif ch in "+-*/^()":
            yield ("op" if ch not in "()" else ch), ch, col
        else:
            why = f": {_WHY[ch]}" if ch in _WHY else ""
            raise ExprError(f"unexpected character {ch!r} at column {col}{why}; expected a number, a name, "
                            "an operator or a parenthesis", col)
        i = m.end() if m else i + 1
    yield "end", "", n + 1


class _Parser:
    def __init__(self, text: str):
        self.stream = _tokens(text)
        self.tok = next(self.stream)
        self.depth = self.nodes = 0
        self.open: list[int] = []  # columns of the '(' not yet closed
        self.names: dict[str, int] = {}  # name -> column of its first use

    def advance(self) -> tuple[str, str, int]:
        tok = self.tok
        if tok[0] != "end":
            self.tok = next(self.stream)
        return tok

    def at(self, ops: str) -> bool:
        return self.tok[0] == "op" and self.tok[1] in ops

    def enter(self, col: int) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExprError(f"expression nested too deeply at column {col}; expected at most {MAX_DEPTH} "
                            "levels of parentheses, signs and powers", col)

    def node(self, e: Expr, col: int, *kid_heights: int) -> tuple[Expr, int]:
        """Count a new node and return it with its height (tree walkers recurse once per level)."""
        self.nodes += 1
        height = 1 + max(kid_heights, default=0)
        if self.nodes > MAX_NODES:
            raise ExprError(f"expression too large at column {col}; expected at most {MAX_NODES} numbers, "
                            "names and operations", col)
        if height > MAX_DEPTH:
            raise ExprError(f"expression nested too deeply at column {col}; expected at most {MAX_DEPTH} "
                            "levels of operations", col)
        return e, height

    def unexpected(self, expected: str) -> ExprError:
        kind, text, col = self.tok
        if kind == "end":
            where = f" (the '(' at column {self.open[-1]} is not closed)" if self.open else ""
            return ExprError(f"unexpected end of expression{where}; expected {expected}", col)
        what = {"num": f"number '{text}'", "name": f"name '{text}'"}.get(kind, f"'{text}'")
        why = ": it has no matching '('" if kind == ")" and not self.open else ""
        return ExprError(f"unexpected {what} at column {col}{why}; expected {expected}", col)

    def parse(self) -> Expr:
        if self.tok[0] == "end":
            raise ExprError("empty expression; expected a number, a name or '('", 1)
        e, _ = self.expr()
        if self.tok[0] != "end":
            raise self.unexpected("an operator or the end")
        return e

    # each rule returns (tree, height)
    def expr(self, ops: str = "+-") -> tuple[Expr, int]:
        """Left-associative sums (ops "+-") or products (ops "*/")."""
        operand = (lambda: self.expr("*/")) if ops == "+-" else self.unary
        left, height = operand()
        while self.at(ops):
            _, op, col = self.advance()
            right, right_height = operand()
            left, height = self.node(BinOp(op, left, right), col, height, right_height)
        return left, height

    def unary(self) -> tuple[Expr, int]:
        if not self.at("+-"):
            return self.power()
        _, sign, col = self.advance()
        self.enter(col)
        arg, height = self.unary()
        self.depth -= 1
        if sign == "+":
            return arg, height
        return (Num(-arg.value), height) if isinstance(arg, Num) else self.node(Neg(arg), col, height)

    def power(self) -> tuple[Expr, int]:
        base, height = self.atom()
        if not self.at("^"):
            return base, height
        _, _, col = self.advance()
        self.enter(col)
        exponent, exponent_height = self.unary()
        self.depth -= 1
        return self.node(BinOp("^", base, exponent), col, height, exponent_height)

    def atom(self) -> tuple[Expr, int]:
        kind, text, col = self.tok
        if kind == "num":
            value = float(text)
            if not math.isfinite(value):
                raise ExprError(f"number '{text}' at column {col} is too large; expected a finite number", col)
            result = self.node(Num(value), col)
        elif kind == "name" and text == "pi":
            result = self.node(Num(math.pi), col)
        elif kind == "name":
            self.names.setdefault(text, col)
            result = self.node(Var(text), col)
        elif kind == "(":
            self.open.append(col)
            self.advance()
            self.enter(col)
            result = self.expr()
            self.depth -= 1
            if self.tok[0] != ")":
                raise self.unexpected("an operator or ')'")
            self.open.pop()
        else:
            raise self.unexpected("a number, a name or '('")
        self.advance()
        if self.tok[0] == "(":  # point at the construct a user (or an attacker) most likely meant
            why = "calls are not allowed" if kind == "name" else "implicit multiplication is not allowed"
            raise ExprError(f"unexpected '(' at column {self.tok[2]}: {why}; expected an operator", self.tok[2])
        return result


def parse_expr(text: str | int | float, names: Collection[str] | None = None) -> Expr:
    """Parse a gain expression.

    Parameters
    ----------
    text : str, int or float
        The expression (``"1/J1"``) or a plain number. Bools, nan and inf are refused.
    names : collection of str, optional
        The known parameter names; any other name raises ExprError with a did-you-mean hint.

    Returns
    -------
    Expr
        A frozen tree; ``str()`` of it re-parses to an equal tree.

    Raises
    ------
    ExprError
        With a 1-based `column` for syntax errors, naming what was found and what was expected.
    """
    if isinstance(text, bool) or not isinstance(text, (str, numbers.Real)):
        raise ExprError(f"expected an expression or a number, found {type(text).__name__}")
    if not isinstance(text, str):
        try:
            return Num(text)
        except OverflowError:
            raise ExprError(f"number {text} is too large; expected a finite number") from None
    if len(text) > MAX_LENGTH:
        raise ExprError(f"expression is {len(text)} characters long; expected at most {MAX_LENGTH}")
    parser = _Parser(text)
    e = parser.parse()
    if names is not None:
        known = set(names)
        unknown = [n for n in parser.names if n not in known]
        if unknown:
            listed = ", ".join(sorted(known)) if len(known) <= 12 else f"{len(known)} parameters"
            hint = "; ".join(h for h in (did_you_mean(n, known) for n in unknown) if h) or None
            col = parser.names[unknown[0]]
            raise ExprError(f"unknown name{'s' if len(unknown) > 1 else ''} "
                            f"{', '.join(repr(n) for n in unknown)} at column {col}; "
                            f"expected a parameter ({listed or 'none are declared'})", col, hint)
    return e
