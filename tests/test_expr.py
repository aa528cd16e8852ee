"""The gain expression language: parsing, printing, evaluation, derivatives, and refusal of anything else."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flowchart2sdnn.expr import (
    MAX_DEPTH,
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
    parse_expr,
    power,
    sub,
)

# --- parsing and precedence against hand-computed values ---------------------------------------------
ENV = {"x": 3.0, "y": 2.0, "r": 0.5, "J1": 4.0, "c": 2.0, "a": 6.0, "b": 3.0}


@pytest.mark.parametrize(
    "text, expected",
    [
        ("1 + 2*3", 7.0),
        ("(1 + 2)*3", 9.0),
        ("2^3^2", 512.0),  # right-associative: 2^(3^2)
        ("(2^3)^2", 64.0),
        ("-2^2", -4.0),  # ^ binds tighter than the sign
        ("(-2)^2", 4.0),
        ("-x^2", -9.0),
        ("2^-1", 0.5),
        ("2^-2^2", 1 / 16),  # 2^(-(2^2))
        ("8/4/2", 1.0),
        ("8 - 3 - 2", 3.0),
        ("a/b*c", 4.0),  # (6/3)*2
        ("a/(b*c)", 1.0),
        ("2*pi*r", math.pi),
        ("1/J1", 0.25),
        ("-c", -2.0),
        ("+x", 3.0),
        ("- -x", 3.0),
        ("2*-3", -6.0),
        ("-2*3", -6.0),
        ("1e-3", 0.001),
        (".5", 0.5),
        ("1.5E+2", 150.0),
        ("2.", 2.0),
        ("x^0.5^2", 3.0**0.25),
        ("  x\t*\ny ", 6.0),
        ("((((x))))", 3.0),
    ],
)
def test_values(text, expected):
    assert parse_expr(text).evaluate(ENV) == pytest.approx(expected, rel=1e-15)


def test_tree_shapes():
    x = Var("x")
    assert parse_expr("-x^2") == Neg(BinOp("^", x, Num(2.0)))
    assert parse_expr("2^3^2") == BinOp("^", Num(2.0), BinOp("^", Num(3.0), Num(2.0)))
    assert parse_expr("a - b - c") == BinOp("-", BinOp("-", Var("a"), Var("b")), Var("c"))
    assert parse_expr("pi") == Num(math.pi)
    assert parse_expr("-2") == Num(-2.0)  # a signed literal is one number
    assert parse_expr("+x") == x
    assert parse_expr(3) == Num(3.0) and parse_expr(0.25) == Num(0.25)
    assert isinstance(parse_expr("x"), Expr)


def test_variables_and_constant():
    e = parse_expr("2*pi*r + a/b - a")
    assert e.variables == frozenset({"r", "a", "b"})
    assert not e.is_constant
    assert parse_expr("2*pi/3").is_constant and parse_expr("2*pi/3").variables == frozenset()


@pytest.mark.parametrize("name", ["pi", "a b", "1x", "", "a.b"])
def test_var_names_must_reparse(name):
    with pytest.raises(ExprError):
        Var(name)


def test_frozen():
    with pytest.raises(AttributeError):
        parse_expr("x").name = "y"


@pytest.mark.parametrize(
    "text, canonical",
    [
        ("2 * pi * r", "2*pi*r"),
        ("1/J1", "1/J1"),
        ("-c", "-c"),
        ("a-(b+c)", "a - (b + c)"),
        ("(a-b)+c", "a - b + c"),
        ("(a^b)^c", "(a^b)^c"),
        ("a^(b^c)", "a^b^c"),
        ("(-2)^x", "(-2)^x"),
        ("-(a*b)", "-(a*b)"),
        ("(-a)*b", "-a*b"),
        ("a*(-b)", "a*-b"),
        ("2^(-1)", "2^-1"),
        ("-(x^2)", "-x^2"),
        ("a/(b/c)", "a/(b/c)"),
        ("0.001", "0.001"),
        ("1e-5", "1e-05"),
        ("1e20", "1e+20"),
        ("3.0", "3"),
        ("-(pi)", "-pi"),
    ],
)
def test_canonical_text(text, canonical):
    assert str(parse_expr(text)) == canonical
    assert parse_expr(canonical) == parse_expr(text)


# --- random trees ------------------------------------------------------------------------------------
def random_tree(rng: np.random.Generator, depth: int) -> Expr:
    """A random tree over x, y, z whose powers stay real for positive arguments."""
    if depth == 0 or rng.random() < 0.25:
        r = rng.random()
        if r < 0.6:
            return Var(str(rng.choice(["x", "y", "z"])))
        if r < 0.7:
            return Num(math.pi)
        return Num(float(rng.choice([-1.25, 0.5, 1.0, 2.0, 3.5, 1e-3, 0.1])))
    kind = int(rng.integers(0, 8))
    if kind == 0:
        return neg(random_tree(rng, depth - 1))
    if kind <= 4:
        return BinOp("+-*/"[kind - 1], random_tree(rng, depth - 1), random_tree(rng, depth - 1))
    if kind == 5:
        return BinOp("^", random_tree(rng, depth - 1), Num(float(rng.choice([2, 3, -1, -2]))))
    if kind == 6:
        return BinOp("^", Num(float(rng.choice([2.0, 0.5, math.pi]))), random_tree(rng, depth - 1))
    t = random_tree(rng, depth - 1)
    return BinOp("^", BinOp("+", BinOp("*", t, t), Num(1.0)), Num(0.5))  # sqrt(1 + t^2)


def test_round_trip_random_trees():
    rng = np.random.default_rng(20240611)
    for _ in range(400):
        tree = random_tree(rng, 5)
        text = str(tree)
        assert parse_expr(text) == tree, text


def test_diff_matches_central_differences():
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(400):
        tree = random_tree(rng, 4)
        env = {v: float(rng.uniform(0.3, 2.0)) for v in "xyz"}
        absent = sorted({"x", "y", "z"} - tree.variables)
        if absent:
            assert tree.diff(absent[0]) == Num(0.0)
        if tree.is_constant:
            continue
        name = str(rng.choice(sorted(tree.variables)))
        d = tree.diff(name)

        def f(v: float, tree=tree, env=env, name=name) -> float:
            return tree.evaluate({**env, name: v})

        x0 = env[name]
        try:
            analytic = d.evaluate(env)
            h = 1e-5 * max(1.0, abs(x0))
            fd1 = (f(x0 + h) - f(x0 - h)) / (2 * h)
            fd2 = (f(x0 + h / 2) - f(x0 - h / 2)) / h
        except ExprError:
            continue  # a pole or overflow near the point: nothing to compare
        scale = max(1.0, abs(fd1), abs(fd2))
        if abs(fd1 - fd2) > 1e-6 * scale:
            continue  # ill-conditioned here (close to a pole); the difference quotient is not an oracle
        assert analytic == pytest.approx(fd2, rel=1e-5, abs=1e-5), (str(tree), name, str(d))
        checked += 1
    assert checked >= 250


@pytest.mark.parametrize(
    "text, name, env, expected",
    [
        ("x^3", "x", {"x": 2.0}, 12.0),
        ("1/J1", "J1", {"J1": 2.0}, -0.25),
        ("2^x", "x", {"x": 1.0}, 2 * math.log(2)),
        ("-x^2", "x", {"x": 3.0}, -6.0),
        ("a*x/(1 + x)", "x", {"a": 2.0, "x": 1.0}, 0.5),  # a/(1+x)^2
        ("(1 + x^2)^0.5", "x", {"x": 0.75}, 0.6),  # x/sqrt(1+x^2)
    ],
)
def test_diff_hand_derived(text, name, env, expected):
    assert parse_expr(text).diff(name).evaluate(env) == pytest.approx(expected, rel=1e-14)


def test_diff_simplifies():
    assert parse_expr("3*x").diff("x") == Num(3.0)
    assert parse_expr("c").diff("c") == Num(1.0)
    assert parse_expr("c").diff("d") == Num(0.0)
    assert parse_expr("x + y").diff("x") == Num(1.0)
    assert parse_expr("-x").diff("x") == Num(-1.0)
    assert parse_expr("x*y").diff("x") == Var("y")


@pytest.mark.parametrize("text", ["x^x", "y^x"])
def test_diff_variable_exponent_needs_constant_base(text):
    with pytest.raises(ExprError, match="exponent depends on 'x'"):
        parse_expr(text).diff("x")


def test_substitute():
    e = parse_expr("2*pi*r").substitute({"r": 0.5})
    assert e.is_constant and e.evaluate({}) == pytest.approx(math.pi)
    assert parse_expr("1/J").substitute({"J": parse_expr("J1 + J2")}) == parse_expr("1/(J1 + J2)")
    assert parse_expr("a + b").substitute({}) == parse_expr("a + b")


def test_smart_constructors():
    x = Var("x")
    assert mul(const(0), x) == Num(0.0) and mul(x, 0.0) == Num(0.0)
    assert mul(const(1), x) == x and mul(x, 1) == x
    assert mul(-1, x) == Neg(x)
    assert add(x, 0) == x and add(0, x) == x
    assert sub(x, 0) == x and sub(0, x) == Neg(x)
    assert add(2, 3) == Num(5.0) and mul(2, 3) == Num(6.0) and div(1, 4) == Num(0.25)
    assert div(x, 1) == x and power(x, 1) == x and power(x, 0) == Num(1.0)
    assert neg(neg(x)) == x and neg(const(2)) == Num(-2.0)
    assert mul(1e200, 1e200) == BinOp("*", Num(1e200), Num(1e200))  # not folded: it would overflow
    assert div(1, 0) == BinOp("/", Num(1.0), Num(0.0))
    with pytest.raises(ExprError):
        const(float("inf"))
    with pytest.raises(TypeError):
        const(True)


# --- refusals ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, fragment, column",
    [
        ("__import__('os')", "calls are not allowed", 11),
        ("a.b", "attribute access is not allowed", 2),
        ("f(x)", "calls are not allowed", 2),
        ("pi(2)", "calls are not allowed", 3),
        ("1**2", "'**'", 2),
        ("", "empty expression", 1),
        ("   ", "empty expression", 1),
        ("(", "not closed", 2),
        ("(1 + 2", "not closed", 7),
        ("1 2", "unexpected number '2' at column 3", 3),
        ("a b", "unexpected name 'b'", 3),
        ("[1]", "indexing is not allowed", 1),
        ("x[0]", "indexing is not allowed", 2),
        ("'s'", "strings are not allowed", 1),
        ('"s"', "strings are not allowed", 1),
        ("1, 2", "commas are not allowed", 2),
        ("x = 1", "not allowed", 3),
        ("1)", "no matching '('", 2),
        (")", "unexpected ')'", 1),
        ("1 +", "unexpected end", 4),
        ("2pi", "malformed number '2pi'", 1),
        ("1e", "malformed number", 1),
        ("1.2.3", "malformed number", 1),
        ("1e999", "too large", 1),
        ("(a)(b)", "implicit multiplication", 4),
        ("2(x)", "implicit multiplication", 2),
        ("lambda: 0", "unexpected character ':'", 7),
        ("x % 2", "unexpected character '%'", 3),
        ("x\x00", "unexpected character", 2),
        ("é", "unexpected character", 1),
        ("-" * 60 + "x", "nested too deeply", None),
        ("(" * 400 + "1" + ")" * 400, "nested too deeply", None),
        ("+".join(["*".join(["x"] * 10)] * 26), "too large", None),  # 519 nodes, 36 levels
        ("+".join(["1"] * 300), "nested too deeply", None),
        ("x" * 1001, "at most 1000", None),
        ("(" * 1000 + "1" + ")" * 1000, "at most 1000", None),
    ],
)
def test_rejects(text, fragment, column):
    with pytest.raises(ExprError) as info:
        parse_expr(text)
    assert fragment in str(info.value)
    if column is not None:
        assert info.value.column == column


@pytest.mark.parametrize("value", [True, float("nan"), float("inf"), None, [1], 10**400])
def test_rejects_non_text(value):
    with pytest.raises(ExprError):
        parse_expr(value)


def test_depth_limit_is_exact():
    parse_expr("(" * MAX_DEPTH + "1" + ")" * MAX_DEPTH)
    with pytest.raises(ExprError, match="nested too deeply"):
        parse_expr("(" * (MAX_DEPTH + 1) + "1" + ")" * (MAX_DEPTH + 1))


@pytest.mark.parametrize("op", ["+", "-", "*", "/", "^"])
def test_operation_chain_limit_is_exact(op):
    with pytest.raises(ExprError, match="nested too deeply"):
        parse_expr(op.join(["x"] * (MAX_DEPTH + 1)))
    e = parse_expr(op.join(["x"] * MAX_DEPTH))  # 50 levels: walkers, derivatives included, stay shallow
    assert parse_expr(str(e)) == e
    if op != "^":
        second = e.diff("x").diff("x")
        assert str(second) and math.isfinite(second.evaluate({"x": 1.5}))


def test_product_chain_derivative_closed_form():
    e = parse_expr("*".join(["x"] * MAX_DEPTH))  # x^50
    assert e.diff("x").evaluate({"x": 1.01}) == pytest.approx(MAX_DEPTH * 1.01 ** (MAX_DEPTH - 1), rel=1e-12)


def test_unknown_names_with_hint():
    with pytest.raises(ExprError) as info:
        parse_expr("1/J + c", names=["J1", "c"])
    exc = info.value
    assert "'J'" in exc.message and exc.column == 3
    assert exc.hint == "did you mean 'J1'?" and "did you mean 'J1'?" in str(exc)
    with pytest.raises(ExprError, match="unknown names 'a', 'b'"):
        parse_expr("a*b", names=[])
    assert parse_expr("2*pi*r", names=["r"]) == parse_expr("2*pi*r")  # pi is not a name


@pytest.mark.parametrize(
    "text, env, fragment",
    [
        ("1/0", {}, "division by zero"),
        ("x/(y - 2)", {"x": 1, "y": 2}, "division by zero"),
        ("2^2^2^2^2^2", {}, "overflow"),
        ("1e308*10", {}, "overflow"),
        ("(-8)^(1/3)", {}, "no real value"),
        ("0^-1", {}, "no real value"),
        ("x*y", {"x": 1.0, "Y": 2.0}, "unknown name 'y'"),
        ("J11", {"J1": 1.0}, "did you mean 'J1'?"),
        ("x", {"x": float("nan")}, "finite"),
        ("x", {"x": "abc"}, "expected a number"),
    ],
)
def test_evaluate_errors(text, env, fragment):
    with pytest.raises(ExprError) as info:
        parse_expr(text).evaluate(env)
    assert fragment in str(info.value)


# --- fuzz --------------------------------------------------------------------------------------------
TOKENS = ["x", "y", "J1", "2", ".5", "1e3", "1e-3", "pi", "+", "-", "*", "/", "^", "(", ")", " ", "**",
          "f(", ".", ",", "[", "'", "0", "e", "_"]
TEXTS = st.one_of(
    st.text(max_size=40),
    st.text(alphabet="0123456789.eE+-*/^() xyzpi_,[]'\"", max_size=60),
    st.lists(st.sampled_from(TOKENS), max_size=30).map("".join),
)


@settings(max_examples=300, deadline=None)
@given(TEXTS)
def test_arbitrary_text_only_raises_expr_error(text):
    try:
        e = parse_expr(text)
    except ExprError:
        return
    assert parse_expr(str(e)) == e  # the canonical text re-parses to the same tree
    for run in (lambda: e.evaluate({"x": 1.5, "y": -0.5, "z": 2.0, "J1": 0.1, "e": 3.0, "_": 1.0}),
                lambda: e.diff("x"),
                lambda: e.substitute({"x": 2.0})):
        try:
            run()
        except ExprError:
            pass
