"""Step bounds for sampled inputs (:func:`codegen.simulator.step_windows`).

A recorded input is interpolated between its samples: linearly where it is rough, by a cubic spline
in windows where it is smooth (there CVODES may step across samples).  These tests check the windows
themselves, that the spline follows a smooth signal at least as well as the linear interpolant, that
rough parts keep the linear interpolant, and that identification recovers the truth either way.
Each tolerance is stated and justified in its test.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from codegen import simulate
from phs.workflows.identify import identify
from phs.workflows.recording import Recording
from systems.electrostatic_actuator import electrostatic_actuator
from systems.examples import mass_spring_damper

simmod = importlib.import_module("codegen._grid")  # the module of step_windows and its step factors


def test_windows_follow_the_input():
    t = np.linspace(0.0, 2.0, 2001)
    u = np.sin(2 * np.pi * 2 * t)
    u[1300:] = 0.3  # a jump in the sixth window (points 1200..1400), then constant
    w = simmod.step_windows(u)
    assert w[0][0] == 0 and w[-1][1] == 2000
    assert all(b == a2 for (_, b, _), (a2, _, _) in zip(w[:-1], w[1:]))  # contiguous
    # each window one integrator call: at most JOINED_MAX windows of 200 joined, in lengths of 200 times a power of
    # two (few distinct integrators) or a rest shorter than 200
    n = simmod.STEP_WINDOW
    assert all(0 < b - a < n or (b - a) % n == 0 and ((b - a) // n) & ((b - a) // n - 1) == 0 and b - a <= n * simmod.JOINED_MAX
               for a, b, _ in w)
    assert any(b - a > n for a, b, _ in w)  # the smooth stretch before the jump joined
    assert all(m1 != m2 or (b - a) % n == 0 for (a, b, m1), (_, _, m2) in zip(w[:-1], w[1:]))  # equal bounds only split at lengths
    fine = simmod.FINE_WINDOW
    near = [m for a, b, m in w if b > 1300 - fine and a < 1300 + fine]
    assert near and set(near) == {1}  # the jump and the intervals next to it keep one interval
    one = [(a, b) for a, b, m in w if m == 1]
    assert all(1200 - fine <= a and b <= 1400 + fine for a, b in one)  # and nothing far from it
    assert sum(b - a for a, b in one) <= 4 * fine  # (the whole window and both neighbours: 600 intervals)
    assert min(m for a, b, m in w if b <= 1200 - fine) >= 8  # a 2 Hz sine at 1 kHz: near-linear over >= 8 samples
    assert {m for a, b, m in w if a >= 1400} == {64}  # constant


def test_rough_ends_keep_one_interval_next_to_them():
    u = np.sin(2 * np.pi * np.linspace(0.0, 1.0, 1001))
    fine = simmod.FINE_WINDOW
    assert simmod.step_windows(u)[0][2] > 1
    w = simmod.step_windows(u, rough_ends=(True, True))
    assert w[0] == (0, fine, 1) and w[-1] == (1000 - fine, 1000, 1)
    assert all(m > 1 for _, _, m in w[1:-1])


def test_noise_and_zero_order_hold_keep_one_interval():
    rng = np.random.default_rng(3)
    assert {m for _, _, m in simmod.step_windows(rng.normal(size=1000))} == {1}
    zoh = np.repeat(rng.uniform(-1, 1, 100), 10)  # a new level every 10 samples
    assert {m for _, _, m in simmod.step_windows(zoh)} == {1}


def test_every_input_counts():
    t = np.linspace(0.0, 1.0, 401)
    smooth, rough = np.sin(2 * np.pi * t), np.random.default_rng(0).normal(size=401)
    assert {m for _, _, m in simmod.step_windows(np.column_stack([smooth, rough]))} == {1}


@pytest.fixture
def one_interval(monkeypatch):
    """Run with the conservative rule (one sample interval and linear interpolation everywhere)."""
    def use():
        monkeypatch.setattr(simmod, "_STEP_FACTORS", ())
    return use


SIGNAL = "15 + 10*sin(2*pi*1.5*t) + 3*sin(2*pi*4.1*t)"


def _signal(t):
    return 15 + 10 * np.sin(2 * np.pi * 1.5 * t) + 3 * np.sin(2 * np.pi * 4.1 * t)


def test_smooth_samples_follow_the_signal(one_interval):
    """Samples of a smooth signal at 1 kHz, simulated against the same signal given exactly: the
    windows' spline is closer to the signal than the linear interpolant (measured 3.2e-6 and 2.3e-5 of
    the peak at rtol 1e-7), and both within 1e-4."""
    s = electrostatic_actuator()
    t = np.arange(0.0, 4.0, 1e-3)
    exact = simulate(s, t, u={"U": SIGNAL}, rtol=1e-11)["position"]
    spline = simulate(s, t, u={"U": _signal(t)}, rtol=1e-7)["position"]
    one_interval()
    linear = simulate(s, t, u={"U": _signal(t)}, rtol=1e-7)["position"]
    peak = np.max(np.abs(exact))
    e_spline, e_linear = np.max(np.abs(spline - exact)) / peak, np.max(np.abs(linear - exact)) / peak
    assert e_spline <= 1e-4 and e_linear <= 1e-4
    assert e_spline <= e_linear


def test_rough_windows_stay_linear(one_interval):
    """A pulse inside a smooth input: the intervals at its edges (and next to them) keep the linear
    interpolant, so the run agrees with the one-interval run to the integration tolerance (1e-6 of the
    peak at rtol 1e-9, where spline and linear differ by ~1e-6 elsewhere): a spline across an edge, or
    ringing from one, would be off by the pulse's height over a sample."""
    s = mass_spring_damper(m=1.0, k=40.0, b=0.5)
    t = np.linspace(0.0, 6.0, 6001)
    F = 0.05 * np.sin(2 * np.pi * 0.3 * t)
    F[3000:3500] += 0.5
    w = simmod.step_windows(F)
    fine = simmod.FINE_WINDOW
    assert all(m == 1 for a, b, m in w if any(b > e - fine and a < e + fine for e in (3000, 3500)))
    assert any(m > 1 for a, b, m in w if 3000 < a and b < 3500)  # the smooth top of the pulse steps freely
    windowed = simulate(s, t, u={"F": F}, rtol=1e-9)["position"]
    one_interval()
    linear = simulate(s, t, u={"F": F}, rtol=1e-9)["position"]
    assert np.max(np.abs(windowed - linear)) <= 1e-5 * np.max(np.abs(linear))


def test_identification_with_smooth_samples(one_interval):
    """A fit on a recording of a true sine sampled at 1 kHz recovers the truth with either rule (1e-4:
    the two interpolants of the samples differ by ~1e-5 of the input)."""
    truth = electrostatic_actuator()
    t = np.arange(0.0, 1.5, 1e-3)
    r = simulate(truth, t, u={"U": SIGNAL}, rtol=1e-10)
    rec = Recording.from_arrays(t, {"U": _signal(t), "position": r["position"], "current": r["current"]})
    start = electrostatic_actuator(k=60.0, b=0.03)
    fit_windowed = identify(start, rec, ["k", "b"], rtol=1e-9)
    one_interval()
    fit_linear = identify(start, rec, ["k", "b"], rtol=1e-9)
    for k in ("k", "b"):
        assert fit_windowed.values[k] == pytest.approx(truth.param(k).value, rel=1e-4)
        assert fit_linear.values[k] == pytest.approx(truth.param(k).value, rel=1e-4)
