r"""Energy-exact simulation of port-Hamiltonian systems with a discrete gradient.

For ``x' = (J - R) dH/dx + (G - P) u`` one step from ``x`` to ``x'`` over ``h``
replaces ``dH/dx`` by Gonzalez' discrete gradient in the metric
``W = diag(1 / s_i**2)`` (``s_i`` the states' typical magnitudes):

.. math::

    \bar\nabla H(x, x') = \nabla H(\bar x)
        + \frac{H(x') - H(x) - \nabla H(\bar x)^T \Delta x}{\Delta x^T W \Delta x} W \Delta x,
    \qquad \bar x = \tfrac12 (x + x'), \quad \Delta x = x' - x,

    x' = x + h \left[ (J - R)(\bar x)\, \bar\nabla H + (G - P)(\bar x)\, u(t + h/2) \right].

Since :math:`\bar\nabla H^T \Delta x = H(x') - H(x)` for any ``H``, the step
satisfies the discrete energy balance

.. math::

    H(x') - H(x) = -h\, \bar\nabla H^T R\, \bar\nabla H + h\, \bar\nabla H^T (G - P)\, u

up to the tolerance of the Newton solve (implicit midpoint, the special case
``\bar\nabla H = \nabla H(\bar x)``, does so only for quadratic ``H``).  The
correction term is dropped when it is at the level of round-off in ``H``
or ``\Delta x^T W \Delta x`` is tiny (then ``H(x') - H(x) - \nabla H(\bar x)^T \Delta x``
is zero to working precision anyway): dividing round-off by a small
``\Delta x^T W \Delta x`` would make the Newton residual noisy near rest.
"""

from __future__ import annotations

import time as _time
import weakref
from numbers import Real

import casadi as ca
import numpy as np

from codegen._domain import DomainCheck, fmt_state
from codegen._grid import time_grid
from codegen._inputs import initial_state, input_signals, inputs_at
from codegen._solver_errors import state_story
from codegen.functions import generate
from codegen.results import SimulationResult
from phs.errors import InputDataError, SimulationError
from phs.params import c_identifier

_EPS = np.finfo(float).eps
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_CHUNK = 500


def discrete_gradient(system, midpoint: bool = False) -> ca.Function:
    """The discrete gradient ``dbarH(x0, x1, p)`` of ``system``'s Hamiltonian as a CasADi function.

    Parameters
    ----------
    system : PHSystem
    midpoint : bool
        Return ``dH((x0 + x1) / 2)`` instead (the implicit-midpoint gradient, for comparisons).

    Examples
    --------
    >>> from systems.examples import duffing_oscillator
    >>> s = duffing_oscillator()
    >>> dbar, H = discrete_gradient(s), generate(s).hamiltonian
    >>> x0, x1, p = np.array([0.3, 1.0]), np.array([-0.2, 0.7]), s.param_vector()
    >>> gap = float(H(x1, [], p) - H(x0, [], p) - ca.dot(dbar(x0, x1, p), x1 - x0))
    >>> abs(gap) < 1e-15
    True
    """
    sx = generate(system).sx
    scale = np.array([s.typical for s in system.states], dtype=float)
    x0, x1 = ca.SX.sym("x0", len(scale)), ca.SX.sym("x1", len(scale))
    H = ca.Function("H", [sx["x"], sx["p"]], [sx["H"]])
    dH = ca.Function("dH", [sx["x"], sx["p"]], [sx["dH"]])
    g = dH((x0 + x1) / 2, sx["p"])
    if not midpoint:
        dx = x1 - x0
        wdx = dx / scale**2
        den = ca.dot(dx, wdx)
        H0, H1 = H(x0, sx["p"]), H(x1, sx["p"])
        num = H1 - H0 - ca.dot(g, dx)
        roundoff = 64 * _EPS * (ca.fabs(H0) + ca.fabs(H1) + ca.sum1(ca.fabs(g * dx)))
        keep = ca.logic_and(den > 1e-24, ca.fabs(num) > roundoff)
        g = g + ca.if_else(keep, num / ca.if_else(keep, den, 1), 0) * wdx
    kind = "midpoint_gradient" if midpoint else "discrete_gradient"
    return ca.Function(f"{c_identifier(system.name)}_{kind}", [x0, x1, sx["p"]], [g], ["x0", "x1", "p"], ["dH"])


def _stepper(system, newton_tol: float, midpoint: bool = False) -> ca.Function:
    """``_CHUNK`` chained steps ``(x, u_mid, p, h) -> (x', scaled Newton residual, H(x'), energy residual, flows)``.

    Chunks of fixed length are cached and chained from Python: building a
    ``mapaccum`` costs time proportional to its length, evaluating it ~5 us per step.
    """
    key = ("implicit_midpoint" if midpoint else "discrete_gradient", newton_tol)
    hit = _CACHE.setdefault(system, {}).get(key)
    if hit is not None:
        return hit
    f = generate(system)
    sx = f.sx
    scale = np.array([s.typical for s in system.states], dtype=float)
    nx = len(scale)
    x, u, p, h = ca.SX.sym("x", nx), sx["u"], sx["p"], ca.SX.sym("h")
    z = ca.SX.sym("z", nx)  # x' / scale, the Newton unknown
    x1 = z * scale
    dbar = discrete_gradient(system, midpoint)(x, x1, p)
    mats = ca.Function("mats", [sx["x"], sx["p"]], [sx["J"] - sx["R"], sx["G"] - sx["P"], sx["R"]])
    JR, GP, R = mats((x + x1) / 2, p)
    flow = ca.mtimes(JR, dbar) + ca.mtimes(GP, u)
    resid = (x1 - x - h * flow) / ca.fmax(scale, ca.fabs(x))  # relative to the state once it exceeds its scale
    par = ca.vertcat(x, u, p, h)
    opts = {"abstol": newton_tol / 10, "abstolStep": newton_tol / 10, "max_iter": 50, "error_on_fail": False}
    name = f"{c_identifier(system.name)}_{key[0]}"
    solve = ca.rootfinder(f"{name}_newton", "newton", {"x": z, "p": par, "g": resid}, opts)
    guess = (x + h * ca.substitute(sx["xdot"], ca.vertcat(sx["x"], sx["u"]), ca.vertcat(x, u))) / scale
    zs = solve(guess, par)
    Hx = ca.Function("H", [sx["x"], p], [sx["H"]])
    energy_residual = Hx(x1, p) - Hx(x, p) - h * ca.dot(dbar, flow)
    energy_flow = h * (ca.fabs(ca.dot(dbar, ca.mtimes(R, dbar))) + ca.fabs(ca.dot(dbar, ca.mtimes(GP, u))))
    post = ca.Function("post", [z, par], [x1, ca.mmax(ca.fabs(resid)), Hx(x1, p), energy_residual, energy_flow])
    step = ca.Function(f"{name}_step", [x, u, p, h], post(zs, par),
                       ["x", "u", "p", "h"], ["x_next", "residual", "H_next", "energy_residual", "energy_flow"])
    _CACHE[system][key] = step.mapaccum(_CHUNK)
    return _CACHE[system][key]


def discrete_gradient_simulate(system, t, u=None, x0=None, params=None, newton_tol: float = 1e-13) -> SimulationResult:
    r"""Simulate ``system`` on the grid ``t`` with the energy-exact discrete-gradient scheme.

    One step per grid interval ``[t_k, t_{k+1}]`` (uniform or not):

    .. math::

        x_{k+1} = x_k + h_k \left[ (J - R)(\bar x)\, \bar\nabla H(x_k, x_{k+1})
                  + (G - P)(\bar x)\, u(t_k + h_k / 2) \right],
        \qquad h_k = t_{k+1} - t_k,

    solved by Newton's method (exact Jacobian by automatic differentiation)
    in the scaled unknown ``x_{k+1} / s``; the discrete energy balance
    ``H(x_{k+1}) - H(x_k) = -h_k dbarH^T R dbarH + h_k dbarH^T (G - P) u``
    holds to the Newton tolerance for any Hamiltonian.  See the module
    docstring for ``dbarH``.

    Parameters
    ----------
    system : PHSystem
    t : array (nt,)
        Strictly increasing times; ``t[0]`` is the initial time.
    u : dict, optional
        Inputs by name, as for :func:`codegen.simulate`: numbers,
        :mod:`phs.signals` signals, expressions of ``t`` as strings, or
        arrays of samples on ``t`` (linearly interpolated).  They are
        evaluated at interval midpoints, so put grid points on input jumps.
        Missing inputs are zero.
    x0 : dict or array, optional
        Initial state by name or in order (default: zero clipped into each state's range).
    params : dict, optional
        Parameter overrides by name.
    newton_tol : float
        Accepted Newton residual (max norm) in units of ``max(s, |x_k|)`` per
        state: absolute in scaled states ``x / s``, relative once a state
        exceeds its typical magnitude ``s``.

    Returns
    -------
    SimulationResult
        With ``stats["method"] == "discrete_gradient"`` and
        ``stats["discrete_energy_residual"]``, the largest per-step mismatch of
        the discrete energy balance relative to ``max |H|`` (or to the largest
        per-step energy flow if larger).

    Raises
    ------
    SimulationError
        When Newton's method does not converge or the state becomes
        non-finite, naming the time reached and the state there.
    DomainError
        When the state leaves the model's validity domain.
    InputDataError
        For a malformed grid, input, initial state or tolerance.

    Examples
    --------
    >>> from systems.examples import duffing_oscillator
    >>> t = np.linspace(0.0, 100.0, 10001)
    >>> res = discrete_gradient_simulate(duffing_oscillator(k3=1.0), t, x0={"s.q": 1.0, "m.p": 0.0})
    >>> bool(np.max(np.abs(res.H - res.H[0])) / res.H[0] < 1e-10)
    True
    >>> res.stats["method"], res.stats["discrete_energy_residual"] < 1e-12
    ('discrete_gradient', True)
    """
    return _run(system, t, u, x0, params, newton_tol, midpoint=False)


def _run(s, t, u, x0, params, newton_tol, midpoint: bool) -> SimulationResult:
    """The simulation loop; ``midpoint=True`` runs implicit midpoint with the same machinery (for comparisons)."""
    wall = _time.perf_counter()
    if not isinstance(newton_tol, Real) or not 0 < newton_tol < 1:
        raise InputDataError(f"newton_tol must be a number in (0, 1), not {newton_tol!r}")
    t = time_grid(t)
    f = generate(s)
    p = s.param_vector(params)
    x = initial_state(s, x0)
    sigs = input_signals(s, u, t)
    h = np.diff(t)
    mid = t[:-1] + h / 2
    u_mid, u_grid = inputs_at(sigs, mid), inputs_at(sigs, t)

    n, nx, run = len(h), len(x), _stepper(s, float(newton_tol), midpoint)
    pad = -n % _CHUNK  # padding steps of length 0 keep the state
    U = np.vstack([u_mid, np.zeros((pad, u_mid.shape[1]))]).T
    hh = np.concatenate([h, np.zeros(pad)])[None, :]
    chunks, xc = [], x  # chunk rows: x' (nx), Newton residual, H(x'), energy residual, energy flow
    for c in range(0, n + pad, _CHUNK):
        chunks.append(np.vstack([np.asarray(v) for v in run(xc, U[:, c : c + _CHUNK], p, hh[:, c : c + _CHUNK])]))
        xc = chunks[-1][:nx, -1]
        if not np.all(chunks[-1][nx] <= newton_tol):  # also catches NaN: stop at the first failing chunk
            break
    out = np.hstack(chunks)[:, :n]
    X = np.vstack([x, out[:nx].T])
    res, Hs, err, flow = out[nx:]
    bad = ~(res <= newton_tol) | ~np.all(np.isfinite(X[1:]), axis=1)
    k = int(np.argmax(bad)) if np.any(bad) else len(res)
    DomainCheck(s, f)(X[: k + 1], t[: k + 1], p, u_grid[: k + 1])
    if k < len(res):
        what = "the state became non-finite" if not np.all(np.isfinite(X[k + 1])) else (
            f"Newton's method did not converge (scaled residual {res[k]:.3g} > {newton_tol:.3g})")
        rates = np.asarray(f.rhs(X[k], u_mid[k], p), dtype=float).reshape(-1)
        raise SimulationError(f"discrete-gradient simulation of {s.name!r} failed in the step from t={t[k]:.6g} "
                              f"to t={t[k + 1]:.6g}: {what}; state at t={t[k]:.6g}: {fmt_state(s, X[k])}: "
                              f"{state_story(s, X[k], rates, h[k], u_mid[k], p)}; try a finer grid (--dt, or more points "
                              "in t) or the cvodes method, which adapts its steps")
    H0 = float(f.hamiltonian(X[0], u_grid[0], p))
    energy_scale = max(abs(H0), float(np.max(np.abs(Hs))), float(np.max(flow)), 1e-300)
    stats = {"method": "implicit_midpoint" if midpoint else "discrete_gradient", "steps": n, "newton_tol": newton_tol,
             "discrete_energy_residual": float(np.max(np.abs(err))) / energy_scale,
             "seconds": _time.perf_counter() - wall}
    return SimulationResult(s, t, X, u_grid, p, stats=stats)
