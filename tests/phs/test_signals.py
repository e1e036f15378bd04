"""Input signals: values, breakpoints, parsing and validation."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from phs import InputDataError
from phs.signals import (
    Combined,
    Constant,
    Expression,
    Periodic,
    Piecewise,
    Sampled,
    as_signal,
    chirp,
    parse_expression,
    sine,
    square,
    staircase,
    step,
    t,
)


# -- square -------------------------------------------------------------------------------------------------
def test_square_values_and_breakpoints():
    sq = square(5000.0, frequency=2.0)
    np.testing.assert_array_equal(sq.breakpoints(0.0, 1.0), [0.25, 0.5, 0.75])
    # high on [k T, k T + T/2), low on [k T + T/2, (k+1) T): an edge belongs to the new level
    np.testing.assert_array_equal(sq(np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.99])), [5e3, 5e3, -5e3, -5e3, 5e3, -5e3])
    assert isinstance(sq(0.1), float)


def test_square_duty_offset_unipolar_and_delayed_start():
    w = square(1.0, 1.0, duty=0.25, offset=0.5, bipolar=False)
    np.testing.assert_array_equal(w.breakpoints(-0.5, 2.2), [0.25, 1.0, 1.25, 2.0])
    np.testing.assert_array_equal(w(np.array([0.1, 0.3, 1.1, 1.9])), [1.5, 0.5, 1.5, 0.5])
    late = square(1.0, 2.0, start=0.3)
    np.testing.assert_array_equal(late.breakpoints(0.0, 1.0), [0.3, 0.55, 0.8])
    np.testing.assert_array_equal(late(np.array([0.1, 0.3, 0.5, 0.55, 0.8])), [0.0, 1.0, 1.0, -1.0, 1.0])


def test_breakpoints_lie_strictly_inside_the_interval():
    sq = square(1.0, 1.0)
    np.testing.assert_array_equal(sq.breakpoints(0.5, 1.5), [1.0])
    assert sq.breakpoints(0.5, 1.0).size == 0
    assert sq.breakpoints(0.0, 0.5).size == 0


@pytest.mark.parametrize("kw", [{"frequency": 0.0}, {"frequency": -1.0}, {"frequency": 1.0, "duty": 1.0},
                                {"frequency": 1.0, "duty": 0.0}])
def test_square_rejects_bad_shape(kw):
    with pytest.raises(InputDataError, match="frequency|duty"):
        square(1.0, **kw)


# -- step, staircase, piecewise ----------------------------------------------------------------------------------
def test_step_values():
    s = step(5000.0, at=0.1, before=-1.0)
    np.testing.assert_array_equal(s(np.array([-5.0, 0.0, 0.0999, 0.1, 3.0])), [-1.0, -1.0, -1.0, 5000.0, 5000.0])
    assert 0.1 in s.breakpoints(0.0, 1.0)


def test_staircase_values():
    s = staircase(-1000.0, every=2.0, n_steps=3, start=1.0)
    np.testing.assert_array_equal(s(np.array([-0.5, 0.5, 1.5, 3.5, 5.5, 9.0])),
                                  [0.0, 0.0, -1000.0, -2000.0, -3000.0, -3000.0])
    assert {1.0, 3.0, 5.0} <= set(s.breakpoints(0.0, 10.0).tolist())


@pytest.mark.parametrize(("signal", "expected"), [(step(1.0, at=2.0), [2.0]),
                                                  (staircase(1.0, every=1.0, n_steps=3, start=2.0), [2.0, 3.0, 4.0])])
def test_step_and_staircase_breakpoints_are_only_their_jumps(signal, expected):
    np.testing.assert_array_equal(signal.breakpoints(0.0, 10.0), expected)


def test_piecewise_holds_levels_and_validates():
    s = Piecewise((0.0, 2.0, 4.0), (0.0, -1000.0, -2000.0))
    np.testing.assert_array_equal(s(np.array([-1.0, 1.0, 2.0, 3.0, 4.0, 9.0])), [0, 0, -1000, -1000, -2000, -2000])
    np.testing.assert_array_equal(s.breakpoints(0.0, 5.0), [2.0, 4.0])
    with pytest.raises(InputDataError, match="strictly increasing"):
        Piecewise((1.0, 0.5), (0.0, 1.0))
    with pytest.raises(InputDataError, match="equal length"):
        Piecewise((1.0,), (0.0, 1.0))


def test_periodic_validation():
    with pytest.raises(InputDataError, match="duty"):
        Periodic(1.0, 0.0, 1.0, duty=1.0)
    with pytest.raises(InputDataError, match="period"):
        Periodic(1.0, 0.0, 0.0)


# -- smooth signals -------------------------------------------------------------------------------------------------
def test_sine_and_chirp_values():
    tt = np.linspace(0.0, 2.0, 41)
    np.testing.assert_allclose(sine(2.0, 1.5, phase=0.3, offset=1.0)(tt), 1.0 + 2.0 * np.sin(3 * np.pi * tt + 0.3),
                               rtol=0, atol=1e-14)
    # linear chirp 1 -> 3 Hz over 2 s: phase 2 pi (f0 t + (f1 - f0) / (2 T) t^2)
    np.testing.assert_allclose(chirp(1.0, 1.0, 3.0, 2.0)(tt), np.sin(2 * np.pi * (tt + 0.5 * tt**2)),
                               rtol=0, atol=1e-13)
    assert sine(1.0, 1.0).breakpoints(0.0, 10.0).size == 0
    assert chirp(1.0, 1.0, 3.0, 2.0).breakpoints(0.0, 10.0).size == 0


def test_expression_breakpoints_from_heaviside_and_piecewise():
    e = Expression(sp.Heaviside(t - 1) * 2 + sp.Piecewise((1, t < 3), (0, True)))
    np.testing.assert_array_equal(e.breakpoints(0.0, 5.0), [1.0, 3.0])
    np.testing.assert_array_equal(e(np.array([0.5, 1.5, 3.5])), [1.0, 3.0, 2.0])
    with pytest.raises(InputDataError, match="unknown symbols"):
        Expression(sp.Symbol("y") * t)


def test_combined_signals_add_values_and_merge_breakpoints():
    c = square(1.0, 1.0) + step(2.0, at=0.3) * 0.5 - 1.0
    assert isinstance(c, Combined)
    assert {0.3, 0.5, 1.0} <= set(c.breakpoints(0.0, 1.2).tolist())
    np.testing.assert_array_equal(c(np.array([0.1, 0.4, 0.6])), [0.0, 1.0, -1.0])


# -- parsing ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "times", "values", "breakpoints"), [
    ("2500 + square(2500, 2)", [0.1, 0.3], [5000.0, 0.0], [0.25, 0.5, 0.75]),
    ("5000*sin(2*pi*t)", [0.25, 0.75], [5000.0, -5000.0], []),
    ("step(2, 0.5) + sine(1, 2)", [0.25, 0.625], [0.0, 3.0], [0.5]),
    ("-staircase(1000, 0.25, 2)", [0.1, 0.3, 0.9], [-1000.0, -2000.0, -2000.0], [0.25]),
    ("chirp(1, 1, 1, 1)", [0.25], [1.0], []),
    ("3.5", [0.0, 10.0], [3.5, 3.5], []),
])
def test_parse_expression(text, times, values, breakpoints):
    s = parse_expression(text)
    np.testing.assert_allclose(s(np.array(times)), values, rtol=0, atol=1e-9)
    assert set(breakpoints) <= set(s.breakpoints(0.0, 1.0).tolist())


@pytest.mark.parametrize(("text", "culprit"), [
    ("x + square(1, 2)", "'x'"),
    ("square(1, 2).high", "attribute"),
    ("1 +", "'1 +'"),
    ("square(1, 0)", "frequency"),
    ("sin(x)", "'x'"),
])
def test_parse_expression_errors_name_the_culprit(text, culprit):
    with pytest.raises(InputDataError) as err:
        parse_expression(text)
    assert culprit in str(err.value)


@pytest.mark.parametrize(("text", "culprit"), [("foo(1)", "foo"), ("foo(t)", "foo"), ('__import__("os")', "__import__"),
                                                ("nan", "nan")])
def test_parse_expression_rejects_unknown_names_without_evaluating_them(text, culprit):
    with pytest.raises(InputDataError) as err:
        parse_expression(text)
    assert culprit in str(err.value)


def test_as_signal():
    assert as_signal(2.0) == Constant(2.0)
    assert isinstance(as_signal(sp.sin(t)), Expression)
    assert as_signal(sp.Integer(3)) == Constant(3.0)
    sq = square(1.0, 1.0)
    assert as_signal(sq) is sq
    with pytest.raises(InputDataError, match="not finite"):
        as_signal(float("inf"))
    with pytest.raises(InputDataError, match="list"):
        as_signal([1.0, 2.0])


# -- sampled --------------------------------------------------------------------------------------------------------
def test_sampled_interpolation():
    lin = Sampled((0.0, 1.0, 2.0), (0.0, 2.0, 0.0))
    np.testing.assert_array_equal(lin(np.array([0.5, 1.0, 1.5, 3.0])), [1.0, 2.0, 1.0, 0.0])
    zoh = Sampled((0.0, 1.0, 2.0), (0.0, 2.0, 0.0), hold="zoh")
    np.testing.assert_array_equal(zoh(np.array([0.5, 1.0, 1.5, 3.0])), [0.0, 2.0, 2.0, 0.0])


@pytest.mark.parametrize(("times", "values", "hold", "culprit"), [
    ((0.0, 1.0), (0.0, np.nan), "linear", "index 1 (t=1.0) is not finite"),
    ((0.0, 1.0, 1.0), (0.0, 1.0, 2.0), "linear", "not strictly increasing at index 2"),
    ((0.0, 2.0, 1.0), (0.0, 1.0, 2.0), "linear", "not strictly increasing at index 2"),
    ((0.0,), (1.0,), "linear", "length >= 2"),
    ((0.0, 1.0), (0.0, 1.0, 2.0), "linear", "equal length"),
    ((0.0, 1.0), (0.0, 1.0), "cubic", "'cubic'"),
])
def test_sampled_validation(times, values, hold, culprit):
    with pytest.raises(InputDataError) as err:
        Sampled(times, values, hold)
    assert culprit in str(err.value)
