"""The linear-time B-spline of a long sampled input (codegen._interpolants.banded_bspline) against CasADi's own
global spline through the same samples, and the cost of building it."""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from codegen._interpolants import BSPLINE_BANDED_FROM, _digest, _interpolant, banded_bspline, spline_values


def _smooth(n: int, jitter: bool):
    """A chirp plus a multisine sampled at 10 kHz (on a jittered grid when ``jitter``)."""
    k = np.arange(n, dtype=float)
    t = 1e-4 * (k + (0.3 * np.random.default_rng(3).uniform(-1, 1, n) if jitter else 0.0))
    v = np.sin(2 * np.pi * (0.5 + 3.0 * t) * t) + 0.4 * np.sin(2 * np.pi * 37.0 * t + 1.0) + 0.1 * np.cos(2 * np.pi * 210.0 * t)
    return t, v


def _at(f, x):
    return np.asarray(f(np.reshape(x, (1, -1))), dtype=float).reshape(-1)


def test_banded_spline_is_casadis_spline_to_rounding():
    # the same spline (cubic, not-a-knot, the same knots): the two differ by how their solves round; CasADi's
    # sparse least squares misses the samples by ~1e-13 of their range at 10^4..10^5 samples (measured:
    # 1.4e-13 at 10^4, 3e-13 at 10^5), the banded solve by ~1e-16. 1e-12 of the range bounds both, with margin
    for jitter in (False, True):
        t, v = _smooth(12_000, jitter)
        ours, ref = banded_bspline("u", t, v), ca.interpolant("u", "bspline", [t], v)
        x = np.sort(np.random.default_rng(1).uniform(t[0], t[-2], 5000))  # CasADi's B-spline is 0 on its last knot
        rng = np.ptp(v)
        assert np.max(np.abs(_at(ours, x) - _at(ref, x))) <= 1e-12 * rng
        assert np.max(np.abs(_at(ours, t[:-1]) - v[:-1])) <= 1e-14 * rng  # it interpolates the samples


def test_a_long_input_enters_through_the_banded_spline_held_at_its_ends():
    n = BSPLINE_BANDED_FROM + 5000
    t, v = _smooth(n, False)
    f = _interpolant(t, v, "bspline", _digest((t, v)))
    ref = ca.interpolant("u", "bspline", [t], v)  # the global spline, built the quadratic way (0.3 s here)
    x = np.linspace(t[0], t[-2], 7001)
    assert np.max(np.abs(_at(f, x) - _at(ref, x))) <= 1e-12 * np.ptp(v)  # as above
    # held beyond the samples, not extrapolated (to rounding: the spline's value at its end knots)
    assert np.max(np.abs(_at(f, [t[0] - 1.0, t[-1] + 1.0]) - [v[0], v[-1]])) <= 1e-14 * np.ptp(v)
    # the values a result reports (scipy's evaluation of the same spline): within rounding of the integrator's
    assert np.max(np.abs(spline_values(t, v, _digest((t, v)), x) - _at(f, x))) <= 1e-14 * np.ptp(v)


def test_building_the_banded_spline_is_linear():
    # four times the samples, four times the work; quadratic growth would be 16 (CasADi's own build took 4.9
    # times longer for twice the samples at 10^5: 2.2 s against 11 s at 2*10^5).  The build's own CPU time,
    # best of three: wall time failed the bound of 6 once under a load of 4 on 2 cores; 8 keeps room for it
    def seconds(n):
        t, v = _smooth(n, False)
        best = np.inf
        for _ in range(3):
            w = time.process_time()
            banded_bspline("u", t, v)
            best = min(best, time.process_time() - w)
        return best

    assert seconds(400_000) / seconds(100_000) < 8.0
