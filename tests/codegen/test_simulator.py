"""Simulation of linear reference models against their analytic solutions.

RC, RLC and mass-spring-damper are integrated by :func:`codegen.simulate` at
``rtol=1e-9`` and compared with closed-form solutions written here from the
circuit/mechanics equations (not from the library's matrices): step inputs,
square waves (the integrator restarts at every edge; the reference is the
piecewise exact solution, edges falling between grid points) and a sine
force on the mass-spring-damper (forced response plus transient).

Tolerance: the maximum error over the grid must be <= 1e-6 of the signal's
maximum.  CVODES at rtol=1e-9 keeps the local error near 1e-9 of the
solution; over the few hundred steps of these runs the global error stays
below ~1e-7 (observed 5e-9 .. 3e-8), so 1e-6 is a safe bound that still
catches a wrong time constant, a missed restart (an O(1) error near an
edge) or a sign error.  The energy balance ``H(t) - H(0) = int (y^T u - dissipated)``
from the integrator's own quadratures is held to the same 1e-6 relative.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import sympy as sp

from codegen import SimulationResult, simulate, simulator
from phs import signals

ANALYTIC_TOL = 1e-6
ENERGY_TOL = 1e-6
RTOL = 1e-9


def _assert_matches(sim, ref, what):
    sim, ref = np.asarray(sim, dtype=float), np.asarray(ref, dtype=float)
    err = float(np.max(np.abs(sim - ref)))
    scale = float(np.max(np.abs(ref)))
    assert err <= ANALYTIC_TOL * scale, f"{what}: max error {err:.3g} vs signal max {scale:.3g}"


def _piecewise_linear(A, B, x0, t, edges, levels):
    """Exact solution of x' = A x + B u with u = levels[k] on [edges[k], edges[k+1]) (matrix exponentials)."""
    A, B = np.atleast_2d(A), np.asarray(B, dtype=float).reshape(-1)
    out = np.empty((len(t), len(x0)))
    x, a = np.asarray(x0, dtype=float), edges[0]
    k = 0
    bounds = list(edges[1:]) + [np.inf]
    for i, ti in enumerate(t):
        while ti > bounds[k]:  # advance the state to the next edge
            xs = -np.linalg.solve(A, B * levels[k])
            x = xs + scipy.linalg.expm(A * (bounds[k] - a)) @ (x - xs)
            a = bounds[k]
            k += 1
        xs = -np.linalg.solve(A, B * levels[k])
        out[i] = xs + scipy.linalg.expm(A * (ti - a)) @ (x - xs)
    return out


def _square_edges(amplitude, frequency, t_end):
    half = 0.5 / frequency
    edges = np.arange(0.0, t_end + half, half)
    levels = [amplitude if k % 2 == 0 else -amplitude for k in range(len(edges))]
    return edges, levels


# -- RC -------------------------------------------------------------------------------------------------------
R_, C_ = 1e3, 1e-6
TAU = R_ * C_


def test_rc_step_response(rc):
    t = np.linspace(0.0, 6e-3, 601)
    res = simulate(rc, t, u={"U": signals.step(2.0, at=1e-3)}, rtol=RTOL)
    s = np.clip(t - 1e-3, 0.0, None)
    Q = 2.0 * C_ * (1.0 - np.exp(-s / TAU))
    _assert_matches(res["C.Q"], Q, "charge")
    _assert_matches(res["v_C"], Q / C_, "measured capacitor voltage")
    i = np.where(t >= 1e-3, 2.0 / R_ * np.exp(-s / TAU), 0.0)
    _assert_matches(res["U.i"], i, "source current (port output)")
    assert res.energy_balance_error() <= ENERGY_TOL
    # the supplied energy is int U i dt = U Q(t) for a constant U after the step
    _assert_matches(res.quadratures["E_supplied"], 2.0 * Q, "supplied energy")
    np.testing.assert_allclose(res.quadratures["E_dissipated[R]"], res.quadratures["E_dissipated"], rtol=1e-12)


def test_rc_square_wave_restarts_at_edges(rc):
    """300 Hz: edges every 1.667 ms fall between the 0.02 ms grid points."""
    f = 300.0
    t = np.linspace(0.0, 8e-3, 401)
    res = simulate(rc, t, u={"U": signals.square(1.0, f)}, rtol=RTOL)
    edges, levels = _square_edges(1.0, f, t[-1])
    ref = _piecewise_linear([[-1.0 / TAU]], [1.0 / R_], [0.0], t, edges, levels)[:, 0]
    _assert_matches(res["C.Q"], ref, "charge under a square wave")
    inside = np.sum((edges > 0) & (edges < t[-1]))
    assert res.stats["runs"] >= inside + 1  # one integrator run per segment at least
    assert res.energy_balance_error() <= ENERGY_TOL


def test_parameter_override_changes_the_time_constant(rc):
    t = np.linspace(0.0, 5e-3, 101)
    res = simulate(rc, t, u={"U": 1.0}, params={"C.C": 2e-6}, rtol=RTOL)
    _assert_matches(res["C.Q"], 2e-6 * (1.0 - np.exp(-t / (R_ * 2e-6))), "charge with C = 2 uF")
    assert rc.param("C.C").value == 1e-6  # the system itself is unchanged


# -- RLC ------------------------------------------------------------------------------------------------------------
RL, LL, CL = 10.0, 1e-3, 1e-6
A_RLC = np.array([[-RL / LL, -1.0 / CL], [1.0 / LL, 0.0]])  # x = (phi, Q): phi' = U - R i - Q/C, Q' = phi/L
B_RLC = np.array([1.0, 0.0])


def test_rlc_step_response(rlc):
    t = np.linspace(0.0, 1e-3, 1001)
    U = 5.0
    res = simulate(rlc, t, u={"U": U}, rtol=RTOL)
    alpha, w0 = RL / (2 * LL), 1.0 / np.sqrt(LL * CL)
    wd = np.sqrt(w0**2 - alpha**2)  # underdamped: alpha = 5e3 < w0 = 3.16e4
    Q = CL * U * (1.0 - np.exp(-alpha * t) * (np.cos(wd * t) + alpha / wd * np.sin(wd * t)))
    i = U / (LL * wd) * np.exp(-alpha * t) * np.sin(wd * t)
    _assert_matches(res["C.Q"], Q, "charge")
    _assert_matches(res["L.phi"], LL * i, "flux linkage")
    _assert_matches(res["U.i"], i, "source current")
    assert res.energy_balance_error() <= ENERGY_TOL


def test_rlc_square_wave(rlc):
    f = 1.7e3  # edges every 0.294 ms, between grid points
    t = np.linspace(0.0, 2e-3, 801)
    res = simulate(rlc, t, u={"U": signals.square(2.0, f)}, rtol=RTOL)
    edges, levels = _square_edges(2.0, f, t[-1])
    ref = _piecewise_linear(A_RLC, B_RLC, [0.0, 0.0], t, edges, levels)
    _assert_matches(res["L.phi"], ref[:, 0], "flux linkage under a square wave")
    _assert_matches(res["C.Q"], ref[:, 1], "charge under a square wave")
    assert res.energy_balance_error() <= ENERGY_TOL


# -- mass-spring-damper ------------------------------------------------------------------------------------------
M, K, B = 1.0, 4.0, 0.4
ALPHA = B / (2 * M)
WD = np.sqrt(K / M - ALPHA**2)


def test_msd_sine_force_forced_response_and_transient(msd):
    """m x'' + b x' + k x = F0 sin(w t) from rest: particular solution plus the decaying homogeneous part."""
    F0, f = 1.0, 0.5
    w = 2 * np.pi * f
    t = np.linspace(0.0, 20.0, 2001)
    res = simulate(msd, t, u={"F": signals.sine(F0, f)}, rtol=RTOL)
    X = F0 / (K - M * w**2 + 1j * B * w)  # complex amplitude of the forced response
    xp = np.imag(X * np.exp(1j * w * t))
    vp0 = np.imag(1j * w * X)
    c1 = -np.imag(X)
    c2 = (-vp0 + ALPHA * c1) / WD
    x = xp + np.exp(-ALPHA * t) * (c1 * np.cos(WD * t) + c2 * np.sin(WD * t))
    v = np.gradient(x, t)  # only used for its scale below
    _assert_matches(res["k.l"], x, "position")
    _assert_matches(res["position"], x, "measured position")
    vel = np.imag(1j * w * X * np.exp(1j * w * t)) + np.exp(-ALPHA * t) * (
        (-ALPHA * c1 + WD * c2) * np.cos(WD * t) + (-ALPHA * c2 - WD * c1) * np.sin(WD * t))
    assert np.max(np.abs(vel - v)) < 1e-2 * np.max(np.abs(vel))  # the closed-form velocity is the derivative
    _assert_matches(res["m.p"], M * vel, "momentum")
    _assert_matches(res["F.v"], vel, "velocity (port output)")
    assert res.energy_balance_error() <= ENERGY_TOL


def test_msd_step_force(msd):
    F = 2.0
    t = np.linspace(0.0, 15.0, 751)
    res = simulate(msd, t, u={"F": F}, x0={"m.p": 0.0, "k.l": 0.0}, rtol=RTOL)
    x = F / K * (1.0 - np.exp(-ALPHA * t) * (np.cos(WD * t) + ALPHA / WD * np.sin(WD * t)))
    _assert_matches(res["k.l"], x, "position")
    assert res.energy_balance_error() <= ENERGY_TOL


def test_free_decay_from_x0_conserves_the_energy_account(msd):
    t = np.linspace(0.0, 10.0, 501)
    res = simulate(msd, t, x0={"k.l": 0.1}, rtol=RTOL)
    x = 0.1 * np.exp(-ALPHA * t) * (np.cos(WD * t) + ALPHA / WD * np.sin(WD * t))
    _assert_matches(res["k.l"], x, "free decay")
    # no input: H(t) - H(0) = -dissipated energy
    np.testing.assert_allclose(res["H"] - res["H"][0], -res.quadratures["E_dissipated"], rtol=0,
                               atol=ENERGY_TOL * res["H"][0])
    assert np.all(np.diff(res["H"]) <= 1e-12 * res["H"][0])  # passivity: H never increases without input


# -- inputs, initial states, results ----------------------------------------------------------------------------------
def test_sine_input_forms_match_the_analytic_response(rc):
    """U = 0.5 + 2 sin(w t + 0.1) given as a signal, a string, a sympy-compatible callable or a bare value."""
    t = np.linspace(0.0, 4e-3, 201)
    w, ph, off, A = 2 * np.pi * 500.0, 0.1, 0.5, 2.0
    g = C_ * A / (1.0 + (w * TAU) ** 2)
    ref = (g * (np.sin(w * t + ph) - w * TAU * np.cos(w * t + ph)) - g * (np.sin(ph) - w * TAU * np.cos(ph))
           * np.exp(-t / TAU) + C_ * off * (1.0 - np.exp(-t / TAU)))
    specs = [{"U": signals.sine(A, 500.0, phase=ph, offset=off)}, {"U": "0.5 + 2*sin(2*pi*500*t + 0.1)"},
             {"U": lambda tt: 0.5 + 2 * sp.sin(2 * sp.pi * 500 * tt + 0.1)}, "0.5 + 2*sin(2*pi*500*t + 0.1)"]
    for u in specs:
        res = simulate(rc, t, u=u, rtol=RTOL)
        _assert_matches(res["C.Q"], ref, f"charge with u={u}")
        np.testing.assert_allclose(res["U"], off + A * np.sin(w * t + ph), rtol=0, atol=1e-12)


def test_numpy_callables_and_arrays_are_sampled_on_the_grid(rc):
    """A numpy-only callable or an array is sampled on the grid and interpolated: a smooth signal (this
    sine, 100 samples per period) by a cubic spline (``step_windows``), error ~ (w h)^4 / 384 ≈ 1e-7;
    never exact (the samples are all the simulator sees)."""
    t = np.linspace(0.0, 4e-3, 201)
    exact = simulate(rc, t, u={"U": signals.sine(2.0, 500.0)}, rtol=RTOL)["C.Q"]
    for spec in (lambda tt: 2.0 * np.sin(2 * np.pi * 500.0 * tt), 2.0 * np.sin(2 * np.pi * 500.0 * t)):
        res = simulate(rc, t, u={"U": spec}, rtol=RTOL)["C.Q"]
        # (w h)^4 / 384 = (2 pi 500 * 2e-5)^4 / 384 = 1.0e-7 relative (linear: (w h)^2 / 8 = 5e-3); the RC
        # filter only reduces it
        err = np.max(np.abs(res - exact)) / np.max(np.abs(exact))
        assert 1e-10 < err < 1e-6  # sampled (not exact), by the spline's interpolation error


def test_x0_as_dict_or_array_and_default_zero(rlc):
    t = np.linspace(0.0, 1e-4, 11)
    a = simulate(rlc, t, x0={"C.Q": 1e-6})
    b = simulate(rlc, t, x0=[0.0, 1e-6])
    np.testing.assert_array_equal(a.x, b.x)
    assert a["C.Q"][0] == 1e-6 and a["L.phi"][0] == 0.0
    z = simulate(rlc, t)
    np.testing.assert_array_equal(z.x, np.zeros_like(z.x))  # at rest with no input


def test_result_is_indexed_by_name(rc, tmp_path):
    t = np.linspace(0.0, 2e-3, 21)
    res = simulate(rc, t, u={"U": 1.0}, rtol=RTOL)
    assert isinstance(res, SimulationResult)
    for name in ["C.Q", "U", "U.i", "v_C", "H", "dissipated", "supplied", "dHdt", "R", "C"]:
        assert res[name].shape == t.shape, name
    np.testing.assert_allclose(res["U"], 1.0)
    np.testing.assert_allclose(res["H"], res["C"], rtol=1e-15)  # the capacitor's energy term is all of H
    np.testing.assert_allclose(res["dHdt"], res["supplied"] - res["dissipated"], rtol=0,
                               atol=1e-12 * np.max(np.abs(res["supplied"])))
    with pytest.raises(KeyError, match="C.q"):
        res["C.q"]
    header, data = res.table()
    assert header[0] == "t" and data.shape == (len(t), len(header))
    res.to_csv(tmp_path / "rc.csv")
    back = np.loadtxt(tmp_path / "rc.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(back, data)
    assert [p.name for p in tmp_path.iterdir()] == ["rc.csv"]  # written atomically, no temporary left


def test_simulator_is_reusable_and_rejects_bad_tolerances(rc):
    sim = simulator(rc, rtol=RTOL)
    t = np.linspace(0.0, 1e-3, 11)
    a = sim.run(t, u={"U": 1.0})
    b = sim.run(t, u={"U": 1.0})
    np.testing.assert_array_equal(a.x, b.x)
    from phs import InputDataError

    with pytest.raises(InputDataError, match="rtol"):
        simulator(rc, rtol=0.0)
