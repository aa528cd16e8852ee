"""Unit algebra: physics identities, scales, refusals, and the unit of a gain expression."""

from __future__ import annotations

import math
from fractions import Fraction

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from flowchart2sdnn.diagram.units import (
    DIMENSIONLESS,
    SYMBOLS,
    Unit,
    UnitError,
    parse_unit,
    unit_of_expr,
)
from flowchart2sdnn.expr import parse_expr


def U(kg=0, m=0, s=0, A=0, K=0, mol=0, cd=0, scale=1.0) -> Unit:
    """A unit written out by hand from SI base exponents (the independent oracle)."""
    return Unit(tuple(Fraction(x) for x in (kg, m, s, A, K, mol, cd)), scale)


# --- symbols against their SI definitions ------------------------------------------------------------
@pytest.mark.parametrize(
    "text, expected",
    [
        ("N", U(kg=1, m=1, s=-2)),
        ("J", U(kg=1, m=2, s=-2)),
        ("W", U(kg=1, m=2, s=-3)),
        ("V", U(kg=1, m=2, s=-3, A=-1)),
        ("Ohm", U(kg=1, m=2, s=-3, A=-2)),
        ("H", U(kg=1, m=2, s=-2, A=-2)),
        ("F", U(kg=-1, m=-2, s=4, A=2)),
        ("C", U(s=1, A=1)),
        ("T", U(kg=1, s=-2, A=-1)),
        ("Wb", U(kg=1, m=2, s=-2, A=-1)),
        ("Pa", U(kg=1, m=-1, s=-2)),
        ("bar", U(kg=1, m=-1, s=-2, scale=1e5)),
        ("Hz", U(s=-1)),
        ("rpm", U(s=-1, scale=2 * math.pi / 60)),
        ("deg", U(scale=math.pi / 180)),
        ("rev", U(scale=2 * math.pi)),
        ("rad", U()),
        ("g", U(kg=1, scale=1e-3)),
        ("um", U(m=1, scale=1e-6)),
        ("h", U(s=1, scale=3600)),
        ("kW", U(kg=1, m=2, s=-3, scale=1e3)),
        ("mV", U(kg=1, m=2, s=-3, A=-1, scale=1e-3)),
        ("Nm", U(kg=1, m=2, s=-2)),
        ("K", U(K=1)),
        ("mol", U(mol=1)),
        ("cd", U(cd=1)),
    ],
)
def test_symbol_definitions(text, expected):
    assert parse_unit(text) == expected
    assert parse_unit(text).scale == pytest.approx(expected.scale, rel=1e-15)


def test_every_symbol_parses():
    for symbol, unit in SYMBOLS.items():
        assert parse_unit(symbol) == unit


@pytest.mark.parametrize(
    "text, expected",
    [
        ("N*m", U(kg=1, m=2, s=-2)),
        ("kg*m^2", U(kg=1, m=2)),
        ("rad/s", U(s=-1)),
        ("N*m*s/rad", U(kg=1, m=2, s=-1)),
        ("V*s^2/mm", U(kg=1, m=1, s=-1, A=-1, scale=1e3)),
        ("1", U()),
        ("mm/s", U(m=1, s=-1, scale=1e-3)),
        ("1/s", U(s=-1)),
        ("m/s^2", U(m=1, s=-2)),
        ("N*m/rad", U(kg=1, m=2, s=-2)),
        ("kg/(m*s)", U(kg=1, m=-1, s=-1)),
        ("kg / (m * s)", U(kg=1, m=-1, s=-1)),
        ("m^(1/2)", U(m=Fraction(1, 2))),
        ("m^(-1/2)", U(m=Fraction(-1, 2))),
        ("s^-1", U(s=-1)),
        ("s^(-2)", U(s=-2)),
        ("(m/s)^2", U(m=2, s=-2)),
        ("m/s/s", U(m=1, s=-2)),
        ("mm^2", U(m=2, scale=1e-6)),
    ],
)
def test_parse(text, expected):
    assert parse_unit(text) == expected


# --- the identities lint relies on -------------------------------------------------------------------
def test_physics_identities():
    torque_over_inertia = parse_unit("N*m") / parse_unit("kg*m^2")
    assert torque_over_inertia == parse_unit("rad/s^2") == parse_unit("1/s^2")
    assert parse_unit("N*m/(kg*m^2)") == parse_unit("rad/s^2")
    assert parse_unit("N*m*s/rad") * parse_unit("rad/s") == parse_unit("N*m")
    assert parse_unit("V*s^2/mm") * parse_unit("mm/s^2") == parse_unit("V")
    assert parse_unit("V") * parse_unit("A") == parse_unit("W")
    assert parse_unit("Ohm") * parse_unit("F") == parse_unit("s")  # RC time constant
    assert parse_unit("H") / parse_unit("Ohm") == parse_unit("s")  # L/R time constant
    assert parse_unit("Wb") / parse_unit("m^2") == parse_unit("T")
    assert parse_unit("rpm") == parse_unit("rev/min")
    assert parse_unit("Hz") == parse_unit("rad/s")  # the price of a dimensionless radian
    assert parse_unit("km") == parse_unit("m") * Unit(DIMENSIONLESS.dims, 1e3)
    assert (parse_unit("m^2") ** Fraction(1, 2)) == parse_unit("m")


def test_scale():
    mm_s, m_s = parse_unit("mm/s"), parse_unit("m/s")
    assert mm_s.same_dimension(m_s) and mm_s != m_s
    assert mm_s.scale == pytest.approx(1e-3, rel=1e-15)
    assert parse_unit("deg").is_dimensionless and parse_unit("deg") != DIMENSIONLESS
    assert parse_unit("rad") == DIMENSIONLESS and parse_unit("rad").is_dimensionless
    assert not parse_unit("m").is_dimensionless
    assert parse_unit("deg") * Unit(DIMENSIONLESS.dims, 180 / math.pi) == parse_unit("rad")
    assert parse_unit("mm") ** 3 == Unit(parse_unit("m").dims, 1) ** 3 * Unit(DIMENSIONLESS.dims, 1e-9)


def test_equality_tolerates_rounding_and_hashes_consistently():
    a = U(m=1, scale=0.1 * 3)
    b = U(m=1, scale=0.3)
    assert a == b and hash(a) == hash(b)
    assert U(m=1, scale=1.0) != U(m=1, scale=1.0 + 1e-9)
    assert len({parse_unit("N*m"), parse_unit("Nm"), parse_unit("J")}) == 1


@pytest.mark.parametrize(
    "text, shown",
    [("N*m", "kg*m^2*s^-2"), ("1", "1"), ("m^(1/2)", "m^(1/2)"), ("1/s", "s^-1"), ("mm/s", "0.001*m*s^-1")],
)
def test_str(text, shown):
    assert str(parse_unit(text)) == shown


@pytest.mark.parametrize("text", ["N*m", "kg/(m*s)", "F", "m^(-3/2)*A", "1", "Ohm*mol/cd"])
def test_str_round_trip(text):
    u = parse_unit(text)
    assert parse_unit(str(u)) == u


# --- refusals ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, fragment, column",
    [
        ("", "empty unit", 1),
        ("Kg", "did you mean 'kg'?", 1),
        ("N*m2", "unknown unit 'm2'", 3),
        ("sec", "did you mean 's'?", 1),
        ("Nms", "did you mean 'N*m*s'?", 1),
        ("kg/m*s", "ambiguous", 5),
        ("N m", "unexpected 'm' at column 3", 3),
        ("N.m", "write '*'", 2),
        ("µm", "'um'", 1),
        ("m²", "'^2'", 2),
        ("2*m", "only '1'", 1),
        ("m^", "exponent", 3),
        ("m^x", "exponent", 3),
        ("m^1.333", "^(1/3)", 3),  # a decimal exponent must be a simple fraction (m^1.5 is m^(3/2))
        ("m^(1/0)", "denominator", 6),
        ("m^(1/2", "')'", 7),
        ("(m", "')'", 3),
        ("m)", "unexpected ')'", 2),
        ("m^99", "out of range", 3),
        ("*m", "unexpected '*'", 1),
        ("m*", "unexpected end", 3),
        ("(" * 20 + "m" + ")" * 20, "nested too deeply", 11),
        ("m*" * 150 + "m", "at most 200", None),
    ],
)
def test_rejects(text, fragment, column):
    with pytest.raises(UnitError) as info:
        parse_unit(text)
    assert fragment in str(info.value)
    if column is not None:
        assert info.value.column == column


@pytest.mark.parametrize("value", [None, 1, ["m"]])
def test_rejects_non_text(value):
    with pytest.raises(UnitError):
        parse_unit(value)


def test_unit_algebra_refuses_out_of_range_scales():
    with pytest.raises(UnitError):
        parse_unit("km") ** 400
    with pytest.raises(UnitError):
        Unit(DIMENSIONLESS.dims, 0.0)


# --- unit of a gain expression -----------------------------------------------------------------------
UNITS = {
    "J1": parse_unit("kg*m^2"),
    "c": parse_unit("N*m*s/rad"),
    "r": parse_unit("m"),
    "T": parse_unit("s"),
    "a": parse_unit("m"),
    "b": parse_unit("s"),
    "d": parse_unit("mm"),
    "n": DIMENSIONLESS,
    "free": None,
}


@pytest.mark.parametrize(
    "text, expected",
    [
        ("1/J1", U(kg=-1, m=-2)),
        ("c", U(kg=1, m=2, s=-1)),
        ("2*pi*r", U(m=1)),
        ("T/J1", U(kg=-1, m=-2, s=1)),
        ("-c*T/J1", U()),  # damping * sample time / inertia: dimensionless, as a discrete gain must be
        ("J1^(1/2)", U(kg=Fraction(1, 2), m=1)),
        ("r^2 + r*a", U(m=2)),
        ("a - 0", U(m=1)),
        ("2^n", U()),
        ("(a/r)^n", U()),
        ("1", U()),
    ],
)
def test_unit_of_expr(text, expected):
    assert unit_of_expr(parse_expr(text), UNITS) == expected


def test_unit_of_expr_unknown_units_skip_the_check():
    assert unit_of_expr(parse_expr("free*J1"), UNITS) is None
    assert unit_of_expr(parse_expr("a + b + missing"), UNITS) is None


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("a + b", "cannot add 'a' [m] and 'b' [s]"),
        ("a - b", "cannot subtract"),
        ("a + d", "cannot add"),  # same dimension, different scale: numbers would be mixed up
        ("1 + a", "cannot add"),
        ("a^n", "constant exponent"),
        ("a^b", "dimensionless"),
        ("r^pi", "not a simple fraction"),
        ("r^(1/0)", "division by zero"),
    ],
)
def test_unit_of_expr_errors(text, fragment):
    with pytest.raises(UnitError) as info:
        unit_of_expr(parse_expr(text), UNITS)
    assert fragment in str(info.value)


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.text(max_size=30),
                 st.lists(st.sampled_from(["m", "kg", "s", "N", "rad", "1", "2", "*", "/", "^", "(", ")", "-",
                                           " ", ".", "mm", "x"]), max_size=20).map("".join)))
def test_arbitrary_text_only_raises_unit_error(text):
    try:
        u = parse_unit(text)
    except UnitError:
        return
    if math.isclose(u.scale, 1.0) and all(abs(d) <= 10 for d in u.dims):  # str() of a scaled unit is not parseable
        assert parse_unit(str(u)) == u


@pytest.mark.parametrize("decimal, fraction", [("V^0.5", "V^(1/2)"), ("m^1.5", "m^(3/2)"), ("m^-0.5", "m^(-1/2)"),
                                               ("s^(0.5)", "s^(1/2)"), ("V^2.0", "V^2")])
def test_decimal_exponents_are_the_simple_fraction_they_write(decimal, fraction):
    assert parse_unit(decimal) == parse_unit(fraction)
    assert parse_unit(decimal) ** 2 == parse_unit(fraction) ** 2
