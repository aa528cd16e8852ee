"""The parser of :mod:`flowchart2sdnn.expr`: tokens read lazily (the first problem in reading order), a
precedence-climbing parser that counts nesting in the text and in the tree, and :func:`parse_expr`."""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Collection, Iterator

from ..errors import did_you_mean
from .tree import MAX_DEPTH, MAX_LENGTH, MAX_NODES, NAME_RE, BinOp, Expr, ExprError, Neg, Num, Var

__all__ = ["parse_expr"]

_NUMBER = re.compile(r"(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_WORD = re.compile(r"[A-Za-z0-9_.]*")
_WHY = {"'": "strings are not allowed", '"': "strings are not allowed", "[": "indexing is not allowed",
        "]": "indexing is not allowed", ",": "commas are not allowed", ".": "attribute access is not allowed",
        "=": "comparisons and assignments are not allowed", "%": "only + - * / ^ are allowed"}


def _tokens(text: str) -> Iterator[tuple[str, str, int]]:
    """(kind, text, column) lazily, so the parser reports the first problem in reading order."""
    i, n = 0, len(text)
    while i < n:
        ch, col = text[i], i + 1
        if ch in " \t\r\n":
            i += 1
            continue
        m = _NUMBER.match(text, i) or NAME_RE.match(text, i)
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
