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

from .parse import parse_expr
from .tree import (
    MAX_DEPTH,
    MAX_LENGTH,
    MAX_NODES,
    BinOp,
    Expr,
    ExprError,
    Neg,
    Num,
    Var,
    add,
    const,
    div,
    mul,
    neg,
    power,
    sub,
)

__all__ = ["ExprError", "Expr", "Num", "Var", "Neg", "BinOp", "parse_expr",
           "const", "add", "sub", "mul", "div", "power", "neg", "MAX_LENGTH", "MAX_DEPTH", "MAX_NODES"]
