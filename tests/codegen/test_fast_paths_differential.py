"""Every fast path of a simulation against a plain reference path, on lab-shaped recordings (:mod:`lab_inputs`).

The fast paths: a sampled input entering as straight lines between its kinks or over its straight stretches,
through a linear or a cubic B-spline interpolant window by window (with its own step bound), held inputs
restarted at every sample; plans of the integrator calls cached per grid and inputs; compiled integrators;
batches over parameters.  The references:

* **a plain integration of the declared input**: the recording says how each input behaves between its
  samples (the straight line, or held by a DAC), and the reference integrates exactly that, interval by
  interval between every sample time of every input and every output time.  For the linear models it is the
  exact solution (the matrix exponential of the system augmented by the input and its slope, from the
  Jacobians of the model's generated right-hand side: exact for a straight-line input to rounding); for the
  nonlinear one, scipy's ``solve_ivp`` (DOP853, rtol 1e-12) of the model's symbolic right-hand side
  (sympy, lambdified: independent of the CasADi translation).
* **the same simulator re-planned** (plans cleared, a fresh :class:`Simulator`): bitwise the same;
* **uncompiled** for compiled, **serial** :meth:`Simulator.run` for the batch.

Where the simulator reads a sampled input through its cubic spline (smooth windows, :func:`codegen._grid.step_windows`)
it does not integrate the declared straight line: that is a choice of path, and it must show what it costs.
Against the exact linear reference the tolerance grows by ``Σ_j ‖g_ij‖₁ δ_j``, with ``δ_j`` the largest
difference between the spline and the line over the windows where input ``j`` is splined (measured on the run's
own interpolant) and ``‖g_ij‖₁`` the L1 norm over the recording of the impulse response from input ``j`` to state
``i``: the peak-to-peak gain, the least bound that holds for every input course of that size (a DC gain is no
bound for a resonant circuit driven near its resonance).  That tolerance would excuse any spline, however
far from the samples' course, so ``δ_j`` is held to what a smooth course through the samples can differ from
their straight lines: ``max |Δ²u|`` over the splined windows (the line's own error against a smooth course is
about ``h² |u''| / 8 ≈ |Δ²u| / 8``), plus rounding.  The nonlinear model has no such gain bound, so its
reference is fed the simulator's own spline where the simulator uses it (:func:`spline_runs`): it checks
the integration paths there, and the linear models check the spline against the declared line.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest
import sympy as sp
from hypothesis import example, given, settings
from lab_inputs import LINEAR, LabCase, LabInput, lab_cases, model
from scipy.integrate import solve_ivp
from scipy.interpolate import make_interp_spline

import codegen._plan as plan_module
from codegen import Simulator
from codegen._inputs import _spline_values, input_signals
from codegen._interpolants import interpolation
from codegen._plan import plan_for
from codegen.functions import generate
from phs.signals import Sampled

pytestmark = pytest.mark.filterwarnings("ignore::phs.errors.ParameterRangeWarning")

EXAMPLES = [pytest.param(100, 150, id="default"), pytest.param(2000, 1000, id="slow", marks=pytest.mark.slow)]
"""Examples per property and the most samples of a recording: 100 of up to 150 samples (300 against the reference) in
the default suite, 2000 of up to 1000 under ``-m slow``."""

RTOL, ATOL = 1e-10, 1e-15
"""The simulator's tolerances in these comparisons (``ATOL`` on the scaled states ``x / s``, of each state's declared
scale ``s``): tighter than the default absolute one (``RTOL / 100``), so that a state the recording moves by far
less than its scale (a spring stretched by 1e-8 m of a 0.1 m scale at 50 kHz) is still integrated to ``RTOL`` of
its own size.  The paths compared do not depend on the tolerances."""
AGREE = 1e-6
"""Agreement asked of a run with its reference, relative to each state's largest magnitude over the run: CVODES at
RTOL 1e-10 keeps its local errors near 1e-10; the global error over the few hundred steps and up to 30 oscillation
periods of a recording was measured up to 5.5e-7 of the states' size on 300 generated cases (outside the splined
windows' allowance).  A line with wrong
constants, a segment off by one sample, an input read beyond its samples or a window read through the wrong
interpolant is off by 1e-3 to 1 of the size."""
ABS_STEPS = 1000
"""Global absolute error allowed, in units of ``ATOL`` times a state's scale (negligible unless the state does not
move at all)."""


# -- reference integrations ---------------------------------------------------------------------------------------------
def _parameters(case: LabCase) -> np.ndarray:
    return case.system.param_vector(case.params)


def _x0(case: LabCase) -> np.ndarray:
    s = case.system
    return np.array([case.x0.get(n, 0.0) for n in s.state_names])


def _knots(case: LabCase) -> np.ndarray:
    """The reference's interval ends: every output time and every sample time of every input inside the grid."""
    return np.union1d(case.t, case.knots())


def spline_runs(case: LabCase) -> dict:
    """Per input name, the time intervals ``(a, b, course, local)`` over which the simulator integrates it through a
    cubic spline (from the simulation's plan: runs whose step bound spans several output intervals, the input
    entering through the spline of all its samples; and runs bounded by one interval that interpolate their own
    samples, ``local``), with that spline as a function of time, computed here from the samples by scipy."""
    s = case.system
    sigs = input_signals(s, case.u, case.t)
    plan = plan_for(case.t, sigs)
    out = {n: [] for n in s.input_names}
    for r in plan.runs:
        for j, c in enumerate(r.choice):
            sg = sigs[j]
            if c is None and isinstance(sg, Sampled) and (r.local or interpolation(len(sg.arrays[0]), r.max_step) == "bspline"):
                a = r.start + plan.origin  # the plan counts time from the grid's start
                b = a + r.n * r.step
                inp = case.inputs[s.input_names[j]]
                if r.local:  # the not-a-knot cubic spline of the samples of the run's span alone: from the last
                    # at or before its start to the first at or after its end (its points, or around them)
                    s0, sh, sn = r.local
                    sa, sb = s0 + plan.origin, s0 + plan.origin + sn * sh
                    lo = np.flatnonzero(inp.times <= sa + 1e-6 * sh)[-1]
                    hi = np.flatnonzero(inp.times >= sb - 1e-6 * sh)[0]
                    assert hi - lo in (sn, sn + 1), "a local run's span is covered by its input's samples"
                    spl = make_interp_spline(inp.times[lo:hi + 1], inp.values[lo:hi + 1], k=3)
                    course = functools.partial(_scipy_course, spl)
                else:
                    course = functools.partial(_whole_course, inp.signal())
                out[s.input_names[j]].append((a, b, course, bool(r.local)))
    return out


def _scipy_course(spl, tt):
    return np.asarray(spl(np.atleast_1d(tt)), dtype=float)


def _whole_course(sg, tt):
    return _spline_values(sg, np.atleast_1d(tt))


def _containing(runs, tm: float):
    return next((run for run in runs if run[0] <= tm <= run[1]), None)


def _course(case: LabCase, name: str, splined, a: float, b: float):
    """Input ``name``'s course on ``(a, b)`` as the reference integrates it: the simulator's spline over ``splined``
    intervals, else the declared course (the line between samples, or held)."""
    inp = case.inputs[name]
    run = _containing(splined or [], 0.5 * (a + b))
    if run is not None:
        return run[2]
    if inp.hold == "zoh":
        v = float(inp(a))
        return lambda tt: np.full(np.shape(np.atleast_1d(tt)), v)
    ua, ub = float(inp(a)), float(inp(b))
    return lambda tt: ua + (ub - ua) * (np.atleast_1d(tt) - a) / (b - a)


def linear_matrices(case: LabCase):
    """``A``, ``B`` of a linear model from the Jacobians of its generated right-hand side at the case's parameters."""
    sx = generate(case.system).sx
    f = ca.Function("ab", [sx["x"], sx["u"], sx["p"]],
                    [ca.jacobian(sx["xdot"], sx["x"]), ca.jacobian(sx["xdot"], sx["u"]), sx["xdot"]])
    nx, nu = len(case.system.states), len(case.system.inputs)
    A, B, c = (np.asarray(v, dtype=float) for v in f(np.zeros(nx), np.zeros(nu), _parameters(case)))
    assert np.all(c == 0.0)  # no drift at rest: x' = A x + B u exactly
    return A, B


_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
           10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)


def expm_stack(A: np.ndarray) -> np.ndarray:
    """Matrix exponentials of a stack ``(k, n, n)`` by scaling and squaring with the degree-13 Padé approximant
    (Higham 2005, the algorithm of ``scipy.linalg.expm``, in numpy over the whole stack: scipy's takes
    milliseconds per small matrix)."""
    b = _PADE13
    norm = np.abs(A).sum(axis=1).max(axis=-1)
    s = np.maximum(0, np.ceil(np.log2(np.maximum(norm, 1e-300) / 5.371920351148152))).astype(int)
    A = A / (2.0 ** s)[:, None, None]
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye
    R = np.linalg.solve(V - U, V + U)
    for k in range(int(s.max(initial=0))):
        sel = s > k
        R[sel] = R[sel] @ R[sel]
    return R


def linear_reference(case: LabCase) -> np.ndarray:
    """The exact states on the grid of a linear model driven by the declared inputs: over each interval between
    knots every input is ``u_a + s (t - a)`` (``s = 0`` when held), and ``[x, u, s]' = [[A, B, 0], [0, 0, I], [0, 0, 0]] [x, u, s]``
    is solved by its matrix exponential."""
    A, B = linear_matrices(case)
    nx, nu = B.shape
    names = case.system.input_names
    knots = _knots(case)
    h = np.diff(knots)
    M = np.zeros((nx + 2 * nu, nx + 2 * nu))
    M[:nx, :nx], M[:nx, nx:nx + nu], M[nx:nx + nu, nx + nu:] = A, B, np.eye(nu)
    # one exponential per interval length (to 12 digits: a relative change of 1e-12 in h changes the solution
    # by about |A h| 1e-12, far below the comparison's tolerance)
    lengths, which = np.unique(np.array([float(f"{v:.12e}") for v in h]), return_inverse=True)
    E = expm_stack(M[None, :, :] * lengths[:, None, None])[which]
    ua = np.column_stack([case.inputs[n](knots[:-1]) for n in names])
    ub = np.column_stack([case.inputs[n](knots[1:]) for n in names])
    held = np.array([case.inputs[n].hold == "zoh" for n in names])
    slope = np.where(held[None, :], 0.0, (ub - ua) / h[:, None])
    X = np.empty((len(knots), nx))
    X[0] = _x0(case)
    for k in range(len(h)):
        X[k + 1] = E[k, :nx, :nx] @ X[k] + E[k, :nx, nx:nx + nu] @ ua[k] + E[k, :nx, nx + nu:] @ slope[k]
    return X[np.searchsorted(knots, case.t)]


def impulse_l1(case: LabCase, points: int = 4000) -> np.ndarray:
    """``(nx, nu)``: the L1 norms over the recording's duration of the impulse responses ``e^{A σ} B`` (trapezoids
    on ``points`` points, each norm raised by 5 % for the trapezoids' error on an oscillation)."""
    A, B = linear_matrices(case)
    D = float(case.t[-1] - case.t[0])
    step = expm_stack((A * D / points)[None])[0]
    G = np.empty((points + 1,) + B.shape)
    G[0] = B
    for k in range(points):
        G[k + 1] = step @ G[k]
    return 1.05 * D / points * (np.abs(G).sum(axis=0) - 0.5 * (np.abs(G[0]) + np.abs(G[-1])))


@functools.cache
def _symbolic_rhs(name: str):
    """The model's right-hand side from its sympy expressions (:attr:`phs.PHSystem.dynamics`), lambdified to numpy:
    ``f(x, u, p)``, independent of the CasADi translation."""
    s = model(name)
    f = sp.lambdify([s.x, s.u, s.p], list(s.dynamics), "numpy")
    return lambda x, u, p: f(list(x), list(u), list(p))


def nonlinear_reference(case: LabCase, splined: dict) -> np.ndarray:
    """States on the grid from scipy's DOP853 (rtol 1e-12, an absolute tolerance of 1e-20 of each state's scale:
    relative control, the generated time scales moving some states by 1e-10 of their scale) of the model's symbolic
    right-hand side, restarted at every knot, fed the declared inputs, or the simulator's spline over the intervals
    where it uses it (``splined``)."""
    s = case.system
    rhs = _symbolic_rhs(case.model)
    p = _parameters(case)
    knots = _knots(case)
    scale = np.array([st.typical for st in s.states])
    X = np.empty((len(knots), len(s.states)))
    X[0] = _x0(case)
    for k, (a, b) in enumerate(zip(knots[:-1], knots[1:])):
        courses = [_course(case, n, splined.get(n), a, b) for n in s.input_names]

        def f(tt, x, courses=courses):
            u = np.array([float(c(tt)[0]) for c in courses])
            return np.asarray(rhs(x, u, p), dtype=float).reshape(-1)

        sol = solve_ivp(f, (a, b), X[k], method="DOP853", rtol=1e-12, atol=1e-20 * scale)
        assert sol.success, sol.message
        X[k + 1] = sol.y[:, -1]
    return X[np.searchsorted(knots, case.t)]


def spline_departure(case: LabCase, splined: dict, per_interval: int = 16) -> tuple[dict, dict]:
    """Per input: the largest ``|spline - line|`` over the intervals it is splined on (evaluated at ``per_interval``
    points of each output interval there), and the largest ``|Δ²u|`` of its samples over those intervals and
    the three samples either side, and beyond them weakened by :data:`SPLINE_DECAY` per sample."""
    dep, curv = {}, {}
    for name, runs in splined.items():
        dep[name], curv[name] = 0.0, 0.0
        if not runs:
            continue
        inp = case.inputs[name]
        for a, b, course, local in runs:
            tt = np.linspace(a, b, max(2, int(round((b - a) / (case.t[1] - case.t[0]))) * per_interval + 1))
            dep[name] = max(dep[name], float(np.max(np.abs(course(tt) - inp(tt)))))
            d2 = np.abs(np.diff(inp.values, 2))  # d2[i]: the second difference centred on sample i + 1
            if len(d2) == 0:
                continue
            i0, i1 = int(np.searchsorted(inp.times, a)), int(np.searchsorted(inp.times, b))
            centre = np.arange(1, len(d2) + 1)
            dist = np.maximum(np.maximum(i0 - centre, centre - i1), 0)  # samples outside the run
            # a local spline sees its own samples only; the whole recording's reaches beyond the run, fading
            reach = (dist == 0).astype(float) if local else np.minimum(1.0, SPLINE_DECAY ** np.maximum(dist - 3, 0))
            curv[name] = max(curv[name], float(np.max(d2 * reach)))
    return dep, curv


SPLINE_DECAY = 2.0 - np.sqrt(3.0)
"""How an interpolating cubic spline's response to one sample falls off per sample away from it (the root of
its knot recurrence ``c_{i-1} + 4 c_i + c_{i+1} = 0``): a chirp's curvature reaches into a rest beside it,
weakened by this factor per sample beyond the three next to the run (a 0.1 V chirp beside a rest departed by
2.3e-5 over the rest, whose own second differences were 1.6e-8)."""


def _simulate(case: LabCase, **options):
    return Simulator(case.system, rtol=RTOL, atol=ATOL, **options).run(case.t, u=case.u, x0=case.x0, params=case.params)


def _state_size(case: LabCase, X: np.ndarray) -> np.ndarray:
    """Per state: its largest magnitude over the run (at least 1e-6 of its scale: a state the inputs barely move)."""
    scale = np.array([st.typical for st in case.system.states])
    return np.maximum(np.max(np.abs(X), axis=0), 1e-6 * scale)


def _allowed(case: LabCase, X: np.ndarray) -> np.ndarray:
    """Per state: :data:`AGREE` of its size, plus :data:`ABS_STEPS` times the simulator's absolute tolerance on it."""
    scale = np.array([st.typical for st in case.system.states])
    return AGREE * _state_size(case, X) + ABS_STEPS * ATOL * scale


# -- regression cases ------------------------------------------------------------------------------------------------
def samples_ending_early() -> LabCase:
    """An RLC circuit (50 ms period) on a 1 kHz grid fed by a converter at 1667 Hz whose samples, a two-tone sine (many
    kinks: baked into an interpolant), stop 10 % before the grid ends.  CasADi's interpolant extrapolated them
    linearly where the samples hold their last value: off by 73 % of the flux's size before
    :func:`codegen._interpolants._interpolant` held its ends."""
    t = 0.25 + np.arange(200) * 1e-3
    times = t[0] + 4e-4 + np.arange(300) * 6e-4
    values = np.sin(2 * np.pi * 7 * times) + 0.3 * np.sin(2 * np.pi * 40 * times)
    C, w0 = 1e-6, 2 * np.pi / 0.05
    L = 1 / (w0**2 * C)
    return LabCase("rlc", t, {"U": LabInput(times, values, "linear", "own_converter", ("multisine",))},
                   {"R.R": 0.4 * np.sqrt(L / C), "L.L": L}, {"L.phi": 0.0, "C.Q": 2e-7}, 1.0)


def samples_starting_late() -> LabCase:
    """An RLC circuit on a 100 Hz grid fed by a converter whose samples, ramps and holds (few kinks: lines between
    them), start 9 ms after the grid: held at the first value before it, a kink at the first sample that the kinks of
    the samples (interior ones only) do not name.  The first segment ran one straight line from the grid's start to
    the first interior kink: off by 1.2 % of the flux's size before :func:`codegen._inputs.plan_segments` broke at
    the samples' ends."""
    t = np.arange(256) * 0.01
    times = 0.00922853 + np.arange(116) * 0.02
    values = np.interp(times, [0.0, 0.03, 0.57, 0.72, 1.77, 2.13, 2.4], [0.2, 0.68, 0.68, 0.27, 0.27, 0.0, 0.0])
    return LabCase("rlc", t, {"U": LabInput(times, values, "linear", "own_converter", ("ramp",))},
                   {"R.R": 576193.8, "L.L": 139854.7}, {"L.phi": 1.44e-4, "C.Q": 0.0}, 1.0)


# -- the properties ----------------------------------------------------------------------------------------------------
def check_against_reference(case: LabCase) -> float:
    """Assert that the simulation of ``case`` agrees with its reference; return the largest error as a share of
    what is allowed."""
    res = _simulate(case, energy=False)
    X = np.column_stack([np.asarray(res[n]) for n in case.system.state_names])
    splined = spline_runs(case)
    if case.model in LINEAR:
        Xr = linear_reference(case)
        dep, curv = spline_departure(case, splined)
        for name in dep:  # the spline keeps to what a smooth course through the samples can be
            assert dep[name] <= curv[name] + 1e-9 * case.amplitude, (name, dep[name], curv[name])
        G = impulse_l1(case)
        allowed = _allowed(case, Xr) + G @ np.array([dep[n] for n in case.system.input_names])
    else:
        Xr = nonlinear_reference(case, splined)
        allowed = _allowed(case, Xr)
    err = np.max(np.abs(X - Xr), axis=0)
    assert np.all(err <= allowed), (err / _state_size(case, Xr), allowed / _state_size(case, Xr))
    return float(np.max(err / allowed))


@pytest.mark.parametrize("n_examples, max_samples", EXAMPLES)
def test_simulation_agrees_with_a_plain_integration_of_the_declared_inputs(n_examples, max_samples):
    @settings(max_examples=n_examples)
    @given(lab_cases(max_samples=max(max_samples, 300)))
    @example(samples_ending_early())
    @example(samples_starting_late())
    def agree(case):
        check_against_reference(case)

    agree()


def absolute_clock_time(origin: float = 1e7, rate: float = 50000.0) -> LabCase:
    """An RC circuit sampled at ``rate`` whose grid starts at a clock time ``origin`` (1e7 s is 116 days; epoch times
    are 1.7e9 s), driven by ramps and holds."""
    t = origin + np.arange(200) / rate
    v = np.interp(np.arange(200), [0, 60, 61, 140, 141, 199], [0.0, 1.0, -1.0, 0.5, 0.2, 0.7])
    return LabCase("rc", t, {"U": LabInput(t, v, "linear", "grid_linear", ("ramp",))}, {"R.R": 1e3}, {"C.Q": 0.0}, 1.0)


@pytest.mark.parametrize("origin, rate", [(1e5, 50000.0), (1e7, 50000.0), (1.7e9, 1000.0)])
def test_absolute_times_keep_their_precision(origin, rate):
    """A run counts time from its grid's start (codegen._plan.Plan.origin): in absolute time a line's constants
    c0 + c1 t cancelled to a few digits, at 1e7 s a 20 us step was resolved to 2e-9 s and the run failed with
    CV_TOO_MUCH_WORK; at 1e5 s the error was 40 times that at t0 = 0 (2.9e-8 against 7e-10 of the range)."""
    check_against_reference(absolute_clock_time(origin, rate))


def _trajectory(res) -> tuple:
    return np.asarray(res.x), np.asarray(res.u), {k: np.asarray(v) for k, v in res.quadratures.items()}


def check_replanned(case: LabCase) -> None:
    """A simulation planned afresh (plans cleared, a fresh simulator) is bitwise the planned one, and so is a
    second run of the same simulator (its integrator calls kept per plan)."""
    sim = Simulator(case.system, rtol=RTOL, atol=ATOL)
    first = _trajectory(sim.run(case.t, u=case.u, x0=case.x0, params=case.params))
    again = _trajectory(sim.run(case.t, u=case.u, x0=case.x0, params=case.params))
    plan_module._PLANS.clear()
    fresh = _trajectory(Simulator(case.system, rtol=RTOL, atol=ATOL).run(case.t, u=case.u, x0=case.x0, params=case.params))
    for other in (again, fresh):
        assert np.array_equal(first[0], other[0]) and np.array_equal(first[1], other[1])
        assert first[2].keys() == other[2].keys() and all(np.array_equal(first[2][k], other[2][k]) for k in first[2])


@pytest.mark.parametrize("n_examples, max_samples", EXAMPLES)
def test_planned_and_replanned_simulations_are_identical(n_examples, max_samples):
    @settings(max_examples=n_examples)
    @given(lab_cases(max_samples=max_samples))
    def identical(case):
        check_replanned(case)

    identical()


def _variants(case: LabCase) -> list[dict]:
    """The case's parameters and a variant (each parameter scaled by 1.25)."""
    return [dict(case.params), {k: 1.25 * v for k, v in case.params.items()}]


def check_batch(case: LabCase, threads: int = 2) -> None:
    """A batch over parameter variants is bitwise the serial :meth:`Simulator.run` of each (its documented
    promise: the same integrators, called in the same order, whatever the threads)."""
    from codegen.batch import BatchSimulator

    variants = _variants(case)
    batch = BatchSimulator(case.system, case.t, rtol=RTOL, atol=ATOL, threads=threads).run(variants, u=case.u, x0=case.x0)
    sim = Simulator(case.system, rtol=RTOL, atol=ATOL)
    for k, params in enumerate(variants):
        assert batch.errors[k] is None, batch.errors[k]
        ref = sim.run(case.t, u=case.u, x0=case.x0, params=params)
        for n in case.system.state_names:
            assert np.array_equal(np.asarray(batch[k][n]), np.asarray(ref[n])), (k, n)


@pytest.mark.parametrize("n_examples, max_samples", EXAMPLES)
def test_batches_equal_serial_runs(n_examples, max_samples):
    @settings(max_examples=n_examples)
    @given(lab_cases(max_samples=max_samples))
    def equal(case):
        check_batch(case)

    equal()


class OneLibrary:
    """The compiled path of many simulations at the cost of one compiler call: a :class:`Simulator` with
    ``compile=True`` hands each integrator's dynamics to its ``compiler``; :meth:`collect` keeps them (renamed
    apart) and returns them uncompiled (the reference run), :meth:`build` generates C for all of them with
    their Jacobians (as :func:`codegen.compile.compiled` does for one) and compiles it once, and :meth:`load`
    serves each from that library (the compiled run)."""

    def __init__(self):
        self.funs: dict = {}
        self.lib = None

    def collect(self, fun, key):
        if key not in self.funs:
            args = fun.sx_in()
            self.funs[key] = ca.Function(f"fast_path_{len(self.funs)}", args, fun.call(args), fun.name_in(), fun.name_out())
        return fun

    def build(self, directory: str) -> None:
        cg = ca.CodeGenerator("fast_paths.c", {"with_header": False})
        for f in self.funs.values():
            cg.add(f)
            cg.add(f.jacobian())
        cg.generate(directory + os.sep)
        cc = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
        self.lib = os.path.join(directory, "fast_paths.so")
        subprocess.run([cc, "-O2", "-shared", "-fPIC", os.path.join(directory, "fast_paths.c"), "-o", self.lib, "-lm"],
                       check=True, capture_output=True)

    def load(self, fun, key):
        return ca.external(self.funs[key].name(), self.lib)


@pytest.mark.skipif(shutil.which(os.environ.get("CC", "gcc")) is None and shutil.which("cc") is None,
                    reason="no C compiler")
@pytest.mark.parametrize("n_examples, max_samples", EXAMPLES)
def test_compiled_runs_agree_with_uncompiled(n_examples, max_samples, tmp_path):
    """Compiled integrators (the model's dynamics, inputs' templates and interpolants as C) against the same
    integrators evaluated by CasADi's virtual machine: the same arithmetic in another order, so they agree to the
    integration's tolerance (:func:`_allowed`), not bitwise.  The cases are drawn first and compiled in one library per
    hundred (a library per case costs a compiler call of ~2 s); a disagreement names its case."""
    chunks: list = []

    @settings(max_examples=n_examples)
    @given(lab_cases(max_samples=max_samples))
    def collect(case):
        if not chunks or len(chunks[-1][1]) >= 100:
            chunks.append((OneLibrary(), []))
        lib, runs = chunks[-1]
        res = Simulator(case.system, rtol=RTOL, atol=ATOL, compile=True, compiler=lib.collect).run(
            case.t, u=case.u, x0=case.x0, params=case.params)
        runs.append((case, np.asarray(res.x).copy()))

    collect()
    bad = []
    for k, (lib, runs) in enumerate(chunks):
        directory = tmp_path / f"chunk{k}"
        directory.mkdir()
        lib.build(str(directory))
        for case, X in runs:
            try:
                Xc = np.asarray(Simulator(case.system, rtol=RTOL, atol=ATOL, compile=True, compiler=lib.load).run(
                    case.t, u=case.u, x0=case.x0, params=case.params).x)
            except Exception as exc:  # the compiled path crashes where the reference ran
                bad.append((case, repr(exc)[:200]))
                continue
            err = np.max(np.abs(Xc - X), axis=0)
            if not np.all(err <= _allowed(case, X)):
                bad.append((case, (err / _state_size(case, X)).tolist()))
    assert not bad, bad[:3]


def test_compiled_spline_and_linear_windows_of_one_input_are_two_libraries(tmp_path, monkeypatch):
    """A sampled input read through its spline in smooth windows and linearly in rough ones: the two integrators'
    dynamics differ only in the interpolant's kind, which the compiled library's key once left out, so a compiled
    run used whichever was compiled first for both (a two-force Duffing oscillator off by 1.6e-3 of its size)."""
    monkeypatch.setenv("PHS_CACHE_DIR", str(tmp_path))
    t = 0.4 + np.arange(300) * 1e-3
    u = np.sin(2 * np.pi * 3 * t)
    u[150:] += 0.2 * np.random.default_rng(3).standard_normal(150)  # smooth, then noise
    case = LabCase("rc", t, {"U": LabInput(t, u, "linear", "grid_linear", ("multisine", "noise"))},
                   {"R.R": 2e4}, {"C.Q": 1e-7}, 1.0)
    assert spline_runs(case)["U"] and len(spline_runs(case)["U"]) < len(t) - 1  # splined windows, and linear ones
    X = np.asarray(_simulate(case).x)
    Xc = np.asarray(_simulate(case, compile=True).x)
    assert np.all(np.max(np.abs(Xc - X), axis=0) <= _allowed(case, X))
