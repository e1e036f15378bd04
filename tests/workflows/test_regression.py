"""phs.workflows.regression: NNLS on powers of a signal and its derivatives, term dropping and selection."""

import numpy as np
import pytest

from phs.errors import InputDataError
from phs.signals import exponential_chirp
from phs.workflows.recording import Recording
from phs.workflows.regression import BENDER_TERMS, regress

T = np.linspace(0.0, 20.0, 4001)
X = 5.0 + 3.0 * np.sin(0.7 * T) + np.sin(2.3 * T)


def test_known_coefficients_are_recovered_with_derivatives():
    xd = 3.0 * 0.7 * np.cos(0.7 * T) + 2.3 * np.cos(2.3 * T)
    F = 0.02 * X**2 + 0.3 * xd**2 + 0.1
    r = regress({"t": T, "x": X, "F": F}, ["x'**2", "x**2", "x", "1"], select=False)
    assert r.full["x**2"] == pytest.approx(0.02, rel=1e-4)
    assert r.full["x'**2"] == pytest.approx(0.3, rel=1e-3)
    assert r.full["x"] == pytest.approx(0.0, abs=1e-4)


def test_nonnegative_keeps_coefficients_at_or_above_zero():
    F = 1.0 - 0.1 * X + 0.05 * X**2
    free = regress({"t": T, "x": X, "F": F}, ["x**2", "x", "1"], nonnegative=False, select=False)
    pos = regress({"t": T, "x": X, "F": F}, ["x**2", "x", "1"], select=False)
    assert free.full["x"] == pytest.approx(-0.1, rel=1e-8)
    assert min(pos.full.values()) >= 0.0 and pos.rmse > free.rmse


def test_selection_stops_when_one_more_term_gains_less_than_the_threshold():
    rng = np.random.default_rng(0)
    F = 0.003 * X**3 + 0.5 + 1e-3 * rng.standard_normal(len(T))
    r = regress(Recording.from_arrays(T, {"x": X, "F": F}), BENDER_TERMS)
    assert r.terms == ("x**3", "1")
    assert [s["k"] for s in r.steps] == [1, 2, 3, 4, 5, 6]
    assert r.steps[1]["decrease"] < 0.01


def test_unreadable_term_and_missing_signal_are_named():
    with pytest.raises(InputDataError, match="x\\^2"):
        regress({"t": T, "x": X, "F": X}, ["x^2"])
    with pytest.raises(InputDataError, match="'y'"):
        regress({"t": T, "x": X, "F": X}, ["y"])
    with pytest.raises(InputDataError, match="'G'"):
        regress({"t": T, "x": X, "F": X}, ["x"], target="G")


def test_exponential_chirp_instantaneous_frequency():
    """Counted from zero crossings: f(t) = f0 (f1/f0)^(t/T), f0 at the start, sqrt(f0 f1) halfway, f1 at the end."""
    f0, f1, dur = 0.5, 8.0, 40.0
    s = exponential_chirp(1.0, f0, f1, dur)
    t = np.linspace(0.0, dur, 2_000_001)
    v = s(t)
    zc = t[:-1][np.sign(v[:-1]) != np.sign(v[1:])]
    zc = zc[zc > 1e-9]
    mid = 0.5 * (zc[1:] + zc[:-1])
    freq = 0.5 / np.diff(zc)  # half a period between crossings
    for when, expected in ((2.0, f0 * 16 ** (2.0 / 40.0)), (20.0, 2.0), (39.5, f0 * 16 ** (39.5 / 40.0))):
        assert np.interp(when, mid, freq) == pytest.approx(expected, rel=2e-3)


def test_exponential_chirp_rejects_bad_frequencies():
    with pytest.raises(InputDataError, match="f0"):
        exponential_chirp(1.0, 0.0, 5.0, 10.0)
