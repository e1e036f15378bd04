"""Smooth stretches of a sampled input kept to one interval are integrated through the spline of their own samples
(``codegen._grid.bounded_runs``, ``local``): checked against the exact response of an RC circuit to the continuous
command the samples were taken from, where the straight lines between the samples make the current lag."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen import Simulator
from codegen._grid import bounded_runs, local_samples, smooth_to_third_order
from codegen._plan import plan_for
from phs.signals import Sampled
from systems.examples import rc_circuit


def _edges(t, level, width, starts):
    """Raised-cosine edges of ``width`` s from ``-level`` to ``level`` and back at ``starts``, held between them;
    returns the command and its time derivative."""
    u, du = np.full_like(t, -level), np.zeros_like(t)
    sign = 1.0
    for a in starts:
        s = np.clip((t - a) / width, 0.0, 1.0)
        inside = (t > a) & (t < a + width)
        lo, hi = (-level, level) if sign > 0 else (level, -level)
        after = t >= a
        u = np.where(after, lo + (hi - lo) * 0.5 * (1 - np.cos(np.pi * s)), u)
        du = np.where(inside, (hi - lo) * 0.5 * np.pi / width * np.sin(np.pi * s), du)
        sign = -sign
    return u, du


def test_a_stiff_rc_circuit_follows_smooth_edges_without_a_half_sample_lag():
    # R C = 10 µs against a 1 ms sampling step: the current is C du/dt to within R C of its course.  The straight
    # lines through the samples of a 40 ms raised-cosine edge make it the slope of the interval before each sample
    # (a half-sample lag: about 4 % of the current's peak here); the spline of the edge's own samples gives
    # C du/dt to 0.2 % (the lag R C over the edge's time scale 40 ms / π is 8e-4 of the peak).
    R, C = 100.0, 1e-7
    t = np.arange(0.0, 0.6, 1e-3)
    u, du = _edges(t, 16.0, 0.04, [0.1, 0.3, 0.45])
    sys_ = rc_circuit()
    sim = Simulator(sys_, rtol=1e-9)
    res = sim.run(t, u={"U": Sampled(tuple(t), tuple(u), hold="linear")}, x0={"C.Q": -16.0 * C},
                  params={"R.R": R, "C.C": C})
    current = (u - np.asarray(res["C.Q"]) / C) / R  # the source's current
    exact = C * du
    peak = np.max(np.abs(exact))
    assert np.max(np.abs(current - exact)) <= 2e-3 * peak
    lines = np.concatenate([[0.0], C * np.diff(u) / np.diff(t)])  # what the straight lines give after their transient
    assert np.max(np.abs(lines - exact)) >= 2e-2 * peak  # the error the local spline removes
    plan = plan_for(t, [Sampled(tuple(t), tuple(u), hold="linear")])
    assert sum(r.n for r in plan.runs if r.local) >= 3 * 39  # the three edges are integrated locally


def test_runs_are_local_only_where_their_points_are_smooth_samples():
    t = np.arange(200) * 1e-3
    u = np.sin(2 * np.pi * 20 * t)  # 50 samples per period: smooth
    u[120:] += 1.0  # a step at sample 120
    sg = Sampled(tuple(t), tuple(u), hold="linear")
    runs = list(bounded_runs([(0.0, 1e-3, 199)], [sg], (True, True)))
    assert sum(r[2] for r in runs) == 199
    for a, h, n, ms, local in runs:
        got = local_samples(t, u, a, h, n)
        if local:
            assert ms == 1.0 and got is not None and smooth_to_third_order(got[1][:, None], [0.02])
        i0 = int(round(a / h))
        if i0 < 120 < i0 + n:  # the step lies inside no local run
            assert not local


@settings(max_examples=40, deadline=None, derandomize=True)
@given(n=st.integers(8, 120), f=st.floats(0.2, 5.0), phase=st.floats(0, 6.28), noise=st.sampled_from([0.0, 1e-3, 0.3]),
       step_at=st.one_of(st.none(), st.integers(1, 119)))
def test_a_local_piece_never_holds_a_kink_in_its_interior(n, f, phase, noise, step_at):
    # whatever the samples (a sine of 0.2-5 periods, noise, a step anywhere), every local piece is smooth to third
    # order on its own samples and the pieces tile the run
    rng = np.random.default_rng(n)
    t = np.arange(n + 1) * 1e-2
    u = np.sin(2 * np.pi * f * t / t[-1] + phase) + noise * rng.normal(size=n + 1)
    if step_at is not None and step_at < n:
        u[step_at:] += 2.0
    sg = Sampled(tuple(t), tuple(u), hold="linear")
    runs = list(bounded_runs([(0.0, 1e-2, n)], [sg], (False, False)))
    assert sum(r[2] for r in runs) == n
    ends = [0]
    for a, h, m, _ms, local in runs:
        assert abs(a - ends[-1] * h) < 1e-9
        ends.append(ends[-1] + m)
        if local:
            got = local_samples(t, u, a, h, m)
            assert got is not None and len(got[1]) >= 8
            assert smooth_to_third_order(got[1][:, None], [0.01 * max(np.ptp(got[1]), 1e-300)])


@pytest.mark.parametrize("rtol", [1e-7, 1e-9])
def test_the_local_spline_is_the_integrators_course(rtol):
    # the integrator's interpolant over a local run and scipy's not-a-knot spline of the same samples agree: an RC
    # circuit (R C = 0.1 s) driven by either course reaches the same charge
    t = np.arange(0.0, 0.1, 1e-3)
    u, _ = _edges(t, 1.0, 0.04, [0.03])
    sys_ = rc_circuit()
    params = {"R.R": 1e4, "C.C": 1e-5}
    res = Simulator(sys_, rtol=rtol, atol=1e-14).run(t, u={"U": Sampled(tuple(t), tuple(u), hold="linear")},
                                                    x0={sys_.state_names[0]: -1e-5}, params=params)
    plan = plan_for(t, [Sampled(tuple(t), tuple(u), hold="linear")])
    assert any(r.local for r in plan.runs)
    from scipy.integrate import solve_ivp
    from scipy.interpolate import make_interp_spline

    courses = []
    for r in plan.runs:
        a, b = r.start, r.start + r.n * r.step
        if r.local:
            keep = (t >= a - 1e-12) & (t <= b + 1e-12)
            courses.append((a, b, make_interp_spline(t[keep], u[keep], k=3)))
        else:
            courses.append((a, b, lambda tt: np.interp(tt, t, u)))

    def course(tt):
        return next(float(c(tt)) for a, b, c in courses if a <= tt <= b)

    sol = solve_ivp(lambda tt, q: [(course(tt) - q[0] / 1e-5) / 1e4], (0.0, t[-1]), [-1e-5], t_eval=t,
                    rtol=1e-12, atol=1e-20, max_step=2e-4)
    # the charge's scale is C times the command's 1 V: a hundred times the simulator's tolerance, and 1e-9 of it;
    # the straight lines' course differs from the spline's by about 1e-4 of it here (a test that can fail)
    assert np.max(np.abs(res[sys_.state_names[0]] - sol.y[0])) <= (100 * rtol + 1e-9) * 1e-5


def test_few_kinks_with_a_curved_stretch_are_not_piecewise_linear():
    # a 3 s drive of holds joined by raised-cosine edges has kinks at 4 % of its samples (few), but every sample of
    # an edge is one: it enters through the edges' own splines, not as a restart at every sample
    t = np.arange(0.0, 3.0, 1e-3)
    u, _ = _edges(t, 16.0, 0.04, [0.5, 1.3, 2.1])
    sg = Sampled(tuple(t), tuple(u), hold="linear")
    assert sg.kinks() is None and len(sg.lines()) >= 3
    plan = plan_for(t, [sg])
    assert sum(r.n for r in plan.runs if r.local) >= 3 * 39
    # held edges (a square wave as sampled) and a ramp table stay piecewise linear
    square = np.where((t % 0.5) < 0.25, 1.0, -1.0)
    ramps = np.interp(t, [0.0, 0.7, 1.1, 2.0, 3.0], [0.0, 2.0, -1.0, -1.0, 0.5])
    for v in (square, ramps):
        assert Sampled(tuple(t), tuple(v), hold="linear").kinks() is not None


@settings(max_examples=60, deadline=None, derandomize=True)
@given(n_breaks=st.integers(1, 60), seed=st.integers(0, 10_000), held=st.booleans())
def test_a_piecewise_linear_table_holds_no_curved_stretch(n_breaks, seed, held):
    # breakpoints of a ramp table (or the edges of held levels) at random samples, of random levels: however close
    # together they fall, their kinks never make a stretch smooth to third order
    from phs.kinks import curved_stretches, linear_kinks

    rng = np.random.default_rng(seed)
    n = 400
    at = np.sort(rng.choice(np.arange(1, n - 1), size=min(n_breaks, n - 2), replace=False))
    levels = rng.uniform(-1.0, 1.0, size=len(at) + 2)
    if held:
        v = levels[np.searchsorted(at, np.arange(n), side="right")]
    else:
        v = np.interp(np.arange(n), np.concatenate([[0], at, [n - 1]]), levels)
    assert curved_stretches(v, linear_kinks(v)) == []


@pytest.mark.parametrize("delay", [1e-7, 0.3, 2.6])
def test_a_delayed_command_is_read_as_the_command_itself(delay):
    # A delay by a fraction of a sample (the time_delay element's course: the samples moved later, evenly spaced
    # still) goes through the same local splines as the undelayed command, the partial steps from its kinks (now
    # between the grid's points) to the grid included, and the input the run reports at the grid's points is that
    # spline's: the source's current (``U.i``, which feeds the input through) is C du/dt at t - tau to the
    # undelayed test's tolerance (0.2 % of its peak; measured 8e-4 at every delay), and a delay tending to zero
    # gives the undelayed run (within 1e-5 of the peak at 1e-7 of a sample).  Read as straight lines between the
    # moved samples, the current was off by 1.6 % of its peak at 0.3 samples, 3.9 % at 1e-7; with the spline
    # inside but the line reported between the samples, by 82 %.
    from components.candidates import TimeDelay

    R, C, dt = 100.0, 1e-7, 1e-3
    t = np.arange(0.0, 0.6, dt)
    u, _ = _edges(t, 16.0, 0.04, [0.1, 0.3, 0.45])
    tau = delay * dt
    times, values = TimeDelay().course(t, u, [tau])
    sim = Simulator(rc_circuit(), rtol=1e-9)

    def current(sg):
        res = sim.run(t, u={"U": sg}, x0={"C.Q": -16.0 * C}, params={"R.R": R, "C.C": C})
        return np.asarray(res["U.i"], dtype=float)

    delayed = current(Sampled(tuple(times), tuple(values), hold="linear"))
    _, du = _edges(t - tau, 16.0, 0.04, [0.1, 0.3, 0.45])
    exact = C * du
    peak = np.max(np.abs(exact))
    assert np.max(np.abs(delayed - exact)) <= 2e-3 * peak
    if delay < 1e-3:
        undelayed = current(Sampled(tuple(t), tuple(u), hold="linear"))
        assert np.max(np.abs(delayed - undelayed)) <= 1e-5 * peak
