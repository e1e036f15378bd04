"""Bounded symbolic work (phs._budget): the price of an expansion is an upper bound computed without expanding,
and mpmath evaluates what overflows in floating point."""

from __future__ import annotations

import time

import mpmath
import pytest
import sympy as sp

from phs._budget import MAX_TERMS, affordable, expanded_terms, is_zero, mp_values, scaled_block

a, b, c = sp.symbols("a b c", real=True)


@pytest.mark.parametrize("expr", [
    (a + b) ** 2 * (a - c), (a + b + c) ** 4, a * (b + 1) + (c - 2) ** 3 / a, sp.sin(a + b) * (a + 1) ** 2,
])
def test_price_bounds_the_expanded_terms(expr):
    """The price is never below the true count of terms (the bound must not let a large expansion through)."""
    assert expanded_terms(expr) >= len(sp.Add.make_args(sp.expand(expr)))


def test_price_of_a_power_of_a_sum_is_exact():
    """(a + b + 1)**120 has C(122, 2) = 7381 monomials: the multinomial count, computed without expanding."""
    assert expanded_terms((a + b + 1) ** 120) == 7381
    assert len(sp.Add.make_args(sp.expand((a + b + 1) ** 12))) == expanded_terms((a + b + 1) ** 12) == 91


def test_over_budget_is_refused_at_once():
    """A difference of 120th powers would expand to ~15 000 terms: refused, in well under a second
    (measured 0.002 s; 1 s leaves room for a loaded machine)."""
    e = (a + b + 1) ** 120 - (a + b + 2) ** 120
    t = time.perf_counter()
    assert not affordable(e) and is_zero(e) is None
    assert time.perf_counter() - t < 1.0
    assert affordable((a + b + 1) ** 3) and expanded_terms((a + b + 1) ** 3) <= MAX_TERMS


def test_is_zero_decides_within_budget():
    assert is_zero((a + 1) ** 2 - a**2 - 2 * a - 1) is True
    assert is_zero(sp.sin(a) ** 2 + sp.cos(a) ** 2 - 1) is True
    assert is_zero(a - b) is False


def test_mpmath_evaluates_what_overflows():
    """1001**120 - 1002**120 ≈ -1.435e359 (float: inf - inf = nan): finite and negative with mpmath; it agrees
    with mpmath's default 15 digits to 1e-12 (the reference's own rounding is 2e-16)."""
    v = mp_values([(a + 1) ** 120 - (a + 2) ** 120], [a], [1000.0])[0]
    expected = mpmath.mpf(1001) ** 120 - mpmath.mpf(1002) ** 120
    assert v < 0 and abs(v / expected - 1) < 1e-12
    m, e = scaled_block([v, mpmath.mpf("1e-3")])
    assert m[0] == -1.0 and 0 <= m[1] < 1e-300  # 1e-3 / 1.4e359 underflows to 0 and round(e) == 359


def test_undefined_stays_nan():
    v = mp_values([sp.Piecewise((a, a > 0), (sp.nan, True))], [a], [-1.0])[0]
    assert v != v


def test_expressions_inside_functions_and_conditions_are_priced():
    """A large power hidden in a Piecewise branch or under Abs is priced like one outside (501 terms > 400)."""
    big = (a + 2) ** 500
    assert not affordable(sp.Piecewise((big, a > 0), (1, True))) and not affordable(sp.Abs(big - a))
    assert affordable(sp.Piecewise(((a + 2) ** 3, a > 0), (1, True)))
