"""A sampled input with many kinks (a sine or chirp) still enters as a straight line over its long straight
stretches (holds, ramps: ``Sampled.lines``, ``plan_segments``): checked on where the stretches are, on the
segments that use them, and against the exact solution of an RC circuit driven by holds, a ramp, a sine
and jumps, with the linear interpolant of the samples as its input."""

import numpy as np
import pytest

from codegen import Simulator
from codegen._inputs import plan_segments
from phs.kinks import LINE_RUN
from phs.signals import Sampled
from systems.examples import rc_circuit

T = np.arange(4001) * 1e-3


def _mixed():
    """Hold 0.4 V, a ramp to 1 V, a 3 Hz sine, a jump to -0.5 V held, a jump to 0.2 V held."""
    u = np.full_like(T, 0.4)
    ramp = (T >= 0.5) & (T < 1.0)
    u[ramp] = 0.4 + 1.2 * (T[ramp] - 0.5)
    sine = (T >= 1.0) & (T < 2.5)
    u[sine] = 1.0 + 0.5 * np.sin(2 * np.pi * 3 * (T[sine] - 1.0))
    u[T >= 2.5] = -0.5
    u[T >= 3.2] = 0.2
    return u


def test_lines_of_a_mixed_input():
    s = Sampled(tuple(T), tuple(_mixed()))
    assert s.kinks() is None  # many kinks (the sine)
    lines = s.lines()
    # the hold, the ramp, the two later holds (between the jumps' kinks)
    assert np.allclose(lines, [[0.0, 0.5], [0.5, 1.0], [2.5, 3.199], [3.2, 4.0]], rtol=0, atol=1e-12)
    assert np.all(np.diff(lines, axis=1) >= LINE_RUN * 1e-3 - 1e-12)
    assert Sampled(tuple(T), tuple(np.sin(7 * T))).lines().shape == (0, 2)  # no stretch
    assert Sampled(tuple(T), tuple(np.where(T < 2.0, 0.0, 1.0))).lines().shape == (0, 2)  # few kinks: lines everywhere already


def test_segments_use_the_lines_and_the_interpolant_between():
    s = Sampled(tuple(T), tuple(_mixed()))
    segs, slots = plan_segments([s], T)
    on_line = [(a, b) for a, b, c in segs if c[0] is not None]
    interpolated = [(a, b) for a, b, c in segs if c[0] is None]
    assert np.allclose(on_line, [(0.0, 0.5), (0.5, 1.0), (2.5, 3.199), (3.2, 4.0)], rtol=0, atol=1e-12)
    assert np.allclose(interpolated, [(1.0, 2.5), (3.199, 3.2)], rtol=0, atol=1e-12)
    for a, b, c in segs:  # a line's constants reproduce the samples at its ends
        if c[0] is not None:
            c0, c1 = c[0][1]
            assert c0 + c1 * a == pytest.approx(float(s(a)), abs=1e-12)
            assert c0 + c1 * b == pytest.approx(float(s(b)), abs=1e-12)


def test_rc_circuit_against_its_exact_solution():
    # v' = (u - v) / tau with u linear between samples: v(t_k+1) = u_k+1 - s tau + (v_k - u_k + s tau) e^(-h/tau).
    # The run follows the samples' cubic spline where they are smooth (the sine), which differs from the
    # linear interpolant by at most (w h)^2 / 8 of the amplitude ~ 2e-5 V at 3 Hz and 1 kHz: 1e-4 of the
    # range.  A line with wrong constants, or a spline across a jump, would be off by ~0.1 of the range.
    tau = 5e-3
    u = _mixed()
    v = np.zeros_like(T)
    for k in range(len(T) - 1):
        h = T[k + 1] - T[k]
        s = (u[k + 1] - u[k]) / h
        v[k + 1] = u[k + 1] - s * tau + (v[k] - u[k] + s * tau) * np.exp(-h / tau)
    r = Simulator(rc_circuit(R=1.0, C=tau), rtol=1e-9).run(T, u={"U": Sampled(tuple(T), tuple(u))})
    err = np.abs(np.asarray(r["v_C"]) - v)
    assert np.max(err) < 1e-4 * np.ptp(v)
    holds = (T >= 2.7) & (T <= 3.19) | (T >= 3.4)  # on the holds, after the jumps' transients: the integration's error only
    assert np.max(err[holds]) < 1e-7 * np.ptp(v)


def test_identification_integrates_the_inputs_as_the_simulator_does():
    # identification's segments are the simulator's runs of the same recording: the same output steps, the same
    # integrator (lines over the holds, the interpolant with its step bound between) and the same parameter tail
    import phs.workflows.identify.sensitivities as ident
    from codegen._plan import plan_for
    from phs.workflows.recording import Recording

    u = _mixed()
    s = Sampled(tuple(T), tuple(u))
    rec = Recording.from_arrays(T, {"U": u, "v_C": np.zeros(len(T))})
    prob = ident._Problem(rc_circuit(), rec, ["R.R"], [], ["v_C"], {"v_C": 1.0}, np.zeros(1), [], 1e-9, None)
    plan = plan_for(T, [s])
    sim = Simulator(rc_circuit(), rtol=1e-9, energy=False, integrator_options={"second_order_correction": False})
    assert len(prob.segments) == len(plan.runs)
    kinds = set()
    for sg, r in zip(prob.segments, plan.runs, strict=True):
        F, layout = sim._integrator(r.n, plan.slots, [g if c is None else None for g, c in zip(plan.sampled, r.choice)],
                                    r.max_step)
        assert np.array_equal(sg.rows, r.j[r.on]) and sg.layout == layout
        np.testing.assert_array_equal(sg.tail, sim._pvec(np.zeros(0), r.start, r.step, layout, r.choice))
        kinds.add(0.0 if r.choice[0] is not None else r.max_step)
    assert {0.0, 1.0} < kinds  # lines, one-interval windows and longer steps all occur


def test_batch_runs_equal_the_simulator_on_a_mixed_input():
    # the batch plans the same integrator calls (lines over the holds, the interpolant between): bitwise
    # the simulator's trajectory
    from codegen.batch import BatchSimulator

    s = rc_circuit(R=1.0, C=5e-3)
    u = Sampled(tuple(T), tuple(_mixed()))
    res = BatchSimulator(s, T, threads=1).run([{}, {"C.C": 1e-2}], u={"U": u})
    for k, params in enumerate([{}, {"C.C": 1e-2}]):
        ref = Simulator(s).run(T, u={"U": u}, params=params)
        assert np.array_equal(np.asarray(res[k]["v_C"]), np.asarray(ref["v_C"]))
