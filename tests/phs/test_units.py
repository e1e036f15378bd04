"""Dimensional analysis: unit strings, expression dimensions, and the unit check of PHSystem.check()."""

from __future__ import annotations

from fractions import Fraction

import pytest
import sympy as sp

from components import Capacitor, Resistor, VoltageSource
from phs import Param, UnitError, interconnect, series
from phs.units import DIMENSIONLESS, JOULE, dimension, format_dim, parse_unit


@pytest.mark.parametrize(("unit", "si"), [
    ("J", "kg*m**2/s**2"),
    ("N*m", "kg*m**2/s**2"),
    ("N*m/rad", "kg*m**2/s**2"),
    ("V*A", "kg*m**2/s**3"),
    ("W", "kg*m**2/s**3"),
    ("F", "s**4*A**2/(kg*m**2)"),
    ("Ohm", "kg*m**2/(s**3*A**2)"),
    ("Ω", "kg*m**2/(s**3*A**2)"),
    ("H", "kg*m**2/(s**2*A**2)"),
    ("C/F", "kg*m**2/(s**3*A)"),  # a charge over a capacitance is a voltage
    ("m^2", "m**2"),
    ("kg*m**2", "kg*m**2"),
    ("1", "1"),
    ("", "1"),
    ("rad", "1"),
    ("Hz", "1/s"),
    ("mm", "m"),
])
def test_parse_unit_gives_si_dimensions(unit, si):
    assert format_dim(parse_unit(unit)) == si


def test_equivalent_units_have_equal_dimensions():
    assert parse_unit("N*m/rad") == parse_unit("J") == JOULE
    assert parse_unit("V") == parse_unit("W/A") == parse_unit("J/C")
    assert parse_unit("Ohm") == parse_unit("V/A") == parse_unit("1/S")
    assert parse_unit("F") == parse_unit("C/V")
    assert parse_unit("H*A") == parse_unit("Wb")
    assert parse_unit("kg*m**(1/2)")[0] == Fraction(1, 2)


@pytest.mark.parametrize("bad", ["furlong", "m+s", "sin(m)", "m**x", "N*"])
def test_unreadable_units_raise_naming_the_unit(bad):
    with pytest.raises(UnitError) as err:
        parse_unit(bad)
    assert repr(bad) in str(err.value)


def test_dimension_of_expressions():
    k, x, C, Q, w, t = sp.symbols("k x C Q w t")
    units = {k: parse_unit("N/m"), x: parse_unit("m"), C: parse_unit("F"), Q: parse_unit("C"),
             w: parse_unit("rad/s"), t: parse_unit("s")}
    assert dimension(k * x**2 / 2, units) == JOULE
    assert dimension(Q**2 / (2 * C), units) == JOULE
    assert dimension(sp.sin(w * t) * Q**2 / C, units) == JOULE
    assert dimension(sp.sqrt(k * x**2), units) == tuple(Fraction(e, 2) for e in JOULE)
    assert dimension(sp.Integer(3), units) == DIMENSIONLESS
    assert dimension(sp.Max(x, 2 * x), units) == parse_unit("m")


@pytest.mark.parametrize(("expr", "message"), [
    ("k*x**2 + x", "sum mixes dimensions"),
    ("sin(x)", "argument of sin is not dimensionless"),
    ("exp(k)", "argument of exp is not dimensionless"),
    ("x**k", "non-integer power"),
    ("y*x", "no unit known for symbol y"),
])
def test_dimension_errors_name_the_subexpression(expr, message):
    k, x = sp.symbols("k x")
    with pytest.raises(UnitError, match=message):
        dimension(sp.sympify(expr, locals={"k": k, "x": x}), {k: parse_unit("N/m"), x: parse_unit("m")})


def test_check_reports_a_unit_mismatch_naming_the_component():
    """A capacitance declared in F*m makes the capacitor's energy J/m: check() names 'Cbad'."""
    C = Param("Cbad.C", 1e-6, "F*m", "capacitance with a wrong unit")
    s = interconnect("wrong", [VoltageSource("U"), Resistor("R", R=1e3), Capacitor("Cbad", C=C)],
                     [series("U", "R", "Cbad")])
    rep = s.check(samples=10)
    assert not rep.ok
    item = rep["units"]
    assert item.verdict == "fail"
    assert "'Cbad'" in item.detail and "kg*m/s**2" in item.detail and "not joules" in item.detail
    assert "'R'" not in item.detail  # the resistor stores no energy, the other terms are fine
    assert "FAILED" in str(rep)


def test_check_passes_when_units_agree(rc):
    assert rc.check(samples=10)["units"].verdict == "pass"


def test_units_are_read_by_the_safe_parser():
    assert parse_unit("m**2.5/s")[0] == Fraction(5, 2)  # a decimal exponent is read exactly
    assert parse_unit("m^(1/2)")[0] == Fraction(1, 2)
    for bad, culprit in [("__import__('os')", "'__import__'"), ("m**1001", "exponent 1001"), ("m**(9**9**9)", "exponent"),
                         ("'m'", "string constants"), ("m." + "s", "attribute access"), ("m" * 201, "longer than 200")]:
        with pytest.raises(UnitError, match=culprit) as err:
            parse_unit(bad, "states[0].unit")
        assert str(err.value).startswith("states[0].unit: ")
