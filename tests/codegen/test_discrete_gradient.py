"""Tests of the discrete-gradient integrator: exact energy balance for non-quadratic H, second order, failures."""

import numpy as np
import pytest

from codegen.discrete_gradient import _run, discrete_gradient, discrete_gradient_simulate
from phs.errors import InputDataError, SimulationError
from systems.examples import duffing_oscillator, mass_spring_damper


def _drift(res) -> float:
    return float(np.max(np.abs(res.H - res.H[0])) / res.H[0])


@pytest.mark.parametrize("k3", [0.5, 2.0])
def test_undamped_duffing_conserves_energy_where_midpoint_does_not(k3):
    s = duffing_oscillator(k3=k3)
    t = np.linspace(0.0, 100.0, 10001)  # 1e4 steps of h = 0.01
    x0 = {"s.q": 1.0, "m.p": 0.0}
    res = discrete_gradient_simulate(s, t, x0=x0)
    # Newton residual <= 1e-13 per step; accumulated over 1e4 steps this stays far below 1e-10
    assert _drift(res) <= 1e-10
    assert res.stats["method"] == "discrete_gradient" and res.stats["discrete_energy_residual"] < 1e-12
    assert res.stats["seconds"] < 2.0
    # implicit midpoint with the same Newton machinery is exact only for quadratic H: the test above would catch it
    mid = _run(s, t, None, x0, None, 1e-13, midpoint=True)
    assert _drift(mid) > 1e-8
    # both are second-order accurate, so they agree with each other to O(h^2) over the run
    assert np.max(np.abs(mid["s.q"] - res["s.q"])) < 1e-2


def test_energy_conserved_on_nonuniform_grid():
    s = duffing_oscillator(k3=1.0)
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.005, 0.05, 2000)])
    res = discrete_gradient_simulate(s, t, x0=np.array([0.5, 1.0]))
    assert _drift(res) <= 1e-11


def test_discrete_gradient_is_a_discrete_gradient():
    s = duffing_oscillator(k3=2.0)
    H, dH = s.lambdify(s.H, with_u=False), s.lambdify(s.grad_H, with_u=False)
    dbar, p = discrete_gradient(s), s.param_vector()
    rng = np.random.default_rng(1)
    for _ in range(20):
        x0, x1 = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
        g = np.asarray(dbar(x0, x1, p)).ravel()
        assert abs(g @ (x1 - x0) - (H(x1, (), p) - H(x0, (), p))) <= 1e-13 * (1 + abs(H(x0, (), p)))
        assert np.allclose(np.asarray(dbar(x0, x0, p)).ravel(), np.ravel(dH(x0, (), p)), rtol=1e-14, atol=0)


def test_forced_damped_discrete_energy_balance_every_step():
    s = mass_spring_damper()
    t = np.linspace(0.0, 20.0, 4001)
    res = discrete_gradient_simulate(s, t, u={"F": "2*sin(3*t)"}, x0={"k.l": 0.05})
    X, p, h = res.x, res.p, np.diff(t)
    u_mid = 2 * np.sin(3 * (t[:-1] + h / 2))
    H = s.lambdify(s.H, with_u=False)  # sympy, independent of the generated functions
    R, G = np.asarray(s.lambdify(s.R, with_u=False)(X[0], (), p), float), np.asarray(s.G, float)
    dbar = np.asarray(discrete_gradient(s).map(len(h))(X[:-1].T, X[1:].T, p)).T
    dissipated = h * np.einsum("ki,ij,kj->k", dbar, R, dbar)
    supplied = h * (dbar @ G)[:, 0] * u_mid
    Hk = np.array([H(x, (), p) for x in X])
    gap = np.abs(np.diff(Hk) - (supplied - dissipated))
    # relative to the energy exchanged in each step, with a floor at the round-off of evaluating H itself
    assert np.all(gap <= 1e-10 * (np.abs(dissipated) + np.abs(supplied) + np.abs(np.diff(Hk))) + 16e-16 * Hk[1:])
    assert np.max(dissipated) > 0 and np.max(np.abs(supplied)) > 0


def _msd_exact(t, l0, F0, m=1.0, k=4.0, b=0.4):
    """Closed-form response of m l'' + b l' + k l = F0 from l(0) = l0, l'(0) = 0 (underdamped)."""
    sig, wd = b / (2 * m), np.sqrt(k / m - (b / (2 * m)) ** 2)
    A = l0 - F0 / k
    B = sig * A / wd
    e = np.exp(-sig * t)
    l = F0 / k + e * (A * np.cos(wd * t) + B * np.sin(wd * t))
    v = e * ((B * wd - sig * A) * np.cos(wd * t) - (A * wd + sig * B) * np.sin(wd * t))
    return np.column_stack([m * v, l])  # states in order m.p, k.l


def test_second_order_convergence_on_linear_msd():
    s = mass_spring_damper()
    errors = []
    for n in (50, 100, 200):
        t = np.linspace(0.0, 5.0, n + 1)
        res = discrete_gradient_simulate(s, t, u={"F": 0.3}, x0={"k.l": 0.05})
        errors.append(np.max(np.abs(res.x - _msd_exact(t, 0.05, 0.3))))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3) & (ratios < 5)), ratios


def test_escaping_softening_spring_raises_naming_time_and_state():
    s, t = duffing_oscillator(k3=-1.0), np.linspace(0, 10, 101)
    run = dict(x0={"s.q": 2.0})  # k3 < 0 (declared so, not overridden): the mass escapes over the potential barrier
    with pytest.raises(SimulationError) as err:
        discrete_gradient_simulate(s, t, **run)
    msg = str(err.value)
    assert "from t=0.8 to t=0.9" in msg and "Newton" in msg
    last = discrete_gradient_simulate(s, t[:9], **run).x[-1]  # the state reached at t=0.8 is named in the message
    assert f"state at t=0.8: m.p={last[0]:.6g}, s.q={last[1]:.6g}" in msg


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        ({"t": [0.0, 1.0, 1.0]}, "index 2"),
        ({"x0": {"s.x": 1.0}}, "s.x"),
        ({"u": {"F": 1.0}}, "F"),
        ({"newton_tol": 0.0}, "newton_tol"),
    ],
)
def test_invalid_arguments_name_the_culprit(kwargs, culprit):
    args = {"t": np.linspace(0, 1, 11), **kwargs}
    with pytest.raises(InputDataError, match=culprit):
        discrete_gradient_simulate(duffing_oscillator(), **args)
