"""Equilibria of a PHSystem under constant input, on the leaf of its conserved quantities.

At rest ``(J - R) dH/dx + (G - P) u = 0``.  When ``[J - R, G - P]`` has a
left null space (conserved quantities, Casimirs: e.g. the curling HASEL's
top-film length tied to its angle), these equations are rank-deficient and
the equilibrium is fixed by the values the conserved quantities take at the
initial state.  They need not be known in closed form: the leaf through
``x0`` is followed numerically.  Dependent coordinates ``x_D`` (pivots of the
null space) are carried along a straight path of the free coordinates
``x_F`` by integrating ``W_D dx_D = -W_F dx_F``, where the rows of ``W(x)``
span the left null space at each point, and the free coordinates are found
by least squares on the rate equations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from numbers import Real

import numpy as np
import scipy.integrate
import scipy.linalg
import scipy.optimize

from phs.errors import EquilibriumError, InputDataError


@dataclass(frozen=True)
class EquilibriumResult:
    """An equilibrium: state and input vectors, the scaled residual and how it was found."""

    system_name: str
    state_names: tuple
    x: np.ndarray
    u: np.ndarray
    residual: float
    conserved: int
    dependent: tuple = ()
    info: dict = field(default_factory=dict)

    def __getitem__(self, name: str) -> float:
        if name in self.state_names:
            return float(self.x[self.state_names.index(name)])
        raise KeyError(f"no state {name!r}; states: {', '.join(self.state_names)}")

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.state_names, map(float, self.x)))


def _vector(system, spec, names, what, default) -> np.ndarray:
    out = np.array(default, dtype=float)
    if spec is None:
        return out
    if isinstance(spec, dict):
        for k, v in spec.items():
            if k not in names:
                raise InputDataError(f"{what}: system {system.name!r} has no {what.split()[0]} {k!r}; known: {names}")
            if not isinstance(v, Real) or not np.isfinite(v):
                raise InputDataError(f"{what}: value {v!r} for {k!r} is not a finite number")
            out[names.index(k)] = float(v)
        return out
    if isinstance(spec, Real) and len(names) == 1:
        out[0] = float(spec)
        return out
    arr = np.asarray(spec, dtype=float).reshape(-1)
    if arr.shape != out.shape:
        raise InputDataError(f"{what}: expected {len(names)} values, got {arr.size}")
    return arr


def equilibrium(system, u=None, x0=None, params=None, *, tol: float = 1e-10, max_nfev: int = 400) -> EquilibriumResult:
    """Equilibrium of ``system`` under the constant input ``u`` on the leaf through ``x0``.

    Parameters
    ----------
    system : PHSystem
    u : dict, float or array, optional
        Constant input (default zero).
    x0 : dict or array, optional
        Starting point; the conserved quantities of J keep their values at
        ``x0`` (default: zero clipped into the state ranges).
    params : dict, optional
        Parameter overrides.
    tol : float
        Required residual ``max_i |x'_i| / s_i`` relative to the largest scaled rate at ``x0``
        (``s_i`` are the states' typical magnitudes).

    Returns
    -------
    EquilibriumResult

    Raises
    ------
    EquilibriumError
        If no equilibrium is found (the message gives the residual and the state reached).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> eq = equilibrium(rc_circuit(), u={"U": 2.0})
    >>> round(eq["C.Q"] / 1e-6, 9)        # Q = C U
    2.0
    """
    names = system.state_names
    s = np.array([st.typical for st in system.states])
    base = np.array([min(max(0.0, st.range[0]), st.range[1]) for st in system.states])
    xs = _vector(system, x0, names, "state x0", base)
    uv = _vector(system, u, system.input_names, "input u", np.zeros(len(system.inputs)))
    p = system.param_vector(params)
    f = system.lambdify(system.dynamics)
    import sympy as sp

    A = system.lambdify(sp.Matrix.hstack(system.J - system.R, system.G - system.P))

    def rate(x):
        with np.errstate(all="ignore"):
            return np.asarray(f(x, uv, p), dtype=float).reshape(-1)

    def null_rows(x):
        M = np.asarray(A(x, uv, p), dtype=float)
        Ms = M * s[:, None] if M.size else M  # row scaling by state scales: W acts on scaled rates
        if M.size == 0:
            return np.zeros((0, len(x)))
        U, sv, _ = np.linalg.svd(Ms)
        r = int(np.sum(sv > 1e-10 * (sv[0] if sv.size and sv[0] > 0 else 1.0)))
        return (U[:, r:].T) * s[None, :]  # rows w with w^T (J-R, G-P) = 0, in unscaled state coordinates

    W0 = null_rows(xs)
    k = W0.shape[0]
    if k:
        _, _, piv = scipy.linalg.qr(W0 / s[None, :] * s[None, :] * s[None, :], pivoting=True)
        dep = sorted(piv[:k].tolist())
    else:
        dep = []
    free = [i for i in range(len(xs)) if i not in dep]
    r0 = rate(xs) / s
    rscale = max(float(np.max(np.abs(r0))) if np.all(np.isfinite(r0)) else 1.0, 1e-300)

    def complete(xf):
        if not dep:
            x = xs.copy()
            x[free] = xf
            return x
        dxf = xf - xs[free]

        def ode(_t, xd):
            x = xs.copy()
            x[free] = xs[free] + _t * dxf
            x[dep] = xd
            W = null_rows(x)
            if W.shape[0] != k:
                W = W[:k] if W.shape[0] > k else np.vstack([W, np.zeros((k - W.shape[0], len(x)))])
            return np.linalg.solve(W[:, dep], -W[:, free] @ dxf)

        sol = scipy.integrate.solve_ivp(ode, (0.0, 1.0), xs[dep], rtol=1e-11, atol=1e-13 * s[dep], method="DOP853")
        if not sol.success:
            raise EquilibriumError(f"equilibrium of {system.name!r}: could not follow the conserved quantities: {sol.message}")
        x = xs.copy()
        x[free] = xf
        x[dep] = sol.y[:, -1]
        return x

    def resid(zf):
        try:
            x = complete(zf * s[free])
        except (np.linalg.LinAlgError, EquilibriumError):
            return np.full(len(xs), 1e6)
        r = rate(x) / s / rscale
        return np.where(np.isfinite(r), r, 1e6)

    z0 = xs[free] / s[free]
    sol = scipy.optimize.least_squares(resid, z0, method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_nfev)
    x = complete(sol.x * s[free])
    res = float(np.max(np.abs(rate(x) / s))) / rscale if len(x) else 0.0
    if not np.isfinite(res) or res > tol:
        raise EquilibriumError(
            f"no equilibrium of {system.name!r} found for u={dict(zip(system.input_names, uv))}: "
            f"scaled residual {res:.3g} > {tol:g} at " + ", ".join(f"{n}={v:.6g}" for n, v in zip(names, x))
        )
    return EquilibriumResult(system.name, tuple(names), x, uv, res, k, tuple(names[i] for i in dep),
                             {"nfev": sol.nfev, "status": sol.status})
