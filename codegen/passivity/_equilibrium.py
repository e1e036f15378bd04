"""The equilibrium of the local test: given as a solver result, claimed (and checked) or solved for."""

from __future__ import annotations

import math

import numpy as np

from codegen.passivity._model import _Model
from codegen.passivity._result import _fmt_point
from phs.errors import EquilibriumError, InputDataError

EQUILIBRIUM_TOL = 1e-7
"""A claimed equilibrium's scaled rate ``max_i |x'_i| / s_i``, divided by the norm of the scaled Jacobian (the
fastest rate), must be below this."""


def _equilibrium_point(system, model: _Model, x_eq, u_eq, p, params, x0):
    """(x, u, how) of an equilibrium given as a result, a claimed state (checked) or solved for."""
    from phs.equilibria import EquilibriumResult, equilibrium

    names, inames = system.state_names, system.input_names
    uvec = np.zeros(len(inames))
    if isinstance(u_eq, dict):
        for k, v in u_eq.items():
            if k not in inames:
                raise InputDataError(f"equilibrium input: system {system.name!r} has no input {k!r} "
                                     f"(inputs: {', '.join(inames) or 'none'})")
            uvec[inames.index(k)] = _finite(v, f"equilibrium input {k!r}")
    elif u_eq is not None:
        arr = np.atleast_1d(np.asarray(u_eq, dtype=float))
        if arr.shape != uvec.shape:
            raise InputDataError(f"equilibrium input: expected {len(inames)} value(s), got {arr.size}")
        uvec = arr.astype(float)
    if isinstance(x_eq, EquilibriumResult):
        return np.asarray(x_eq.x, dtype=float), np.asarray(x_eq.u, dtype=float), "equilibrium given as a solver result"
    if x_eq is None:
        eq = equilibrium(system, u=dict(zip(inames, uvec)), x0=x0, params=params, signs=False)  # the what-if
        return eq.x, uvec, f"equilibrium solved for u = {_fmt_point(dict(zip(inames, uvec))) or 'none'}"
    x = np.array([st.initial for st in system.states])
    if isinstance(x_eq, dict):
        for k, v in x_eq.items():
            if k not in names:
                raise InputDataError(f"equilibrium: system {system.name!r} has no state {k!r} "
                                     f"(states: {', '.join(names)})")
            x[names.index(k)] = _finite(v, f"equilibrium state {k!r}")
        given = x_eq
    else:
        arr = np.asarray(x_eq, dtype=float).reshape(-1)
        if arr.shape != x.shape:
            raise InputDataError(f"equilibrium: expected {len(names)} state values, got {arr.size}")
        x = arr
        given = dict(zip(names, map(float, arr)))
    _check_equilibrium(system, model, x, uvec, p, given)
    return x, uvec, "equilibrium given and checked"


def _finite(v, what) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputDataError(f"{what}: {v!r} is not a number") from None
    if not math.isfinite(f):
        raise InputDataError(f"{what}: {v!r} is not finite")
    return f


def _check_equilibrium(system, model: _Model, x, u, p, given: dict) -> None:
    A, *_, xdot = (np.asarray(v, dtype=float) for v in model.flin(x, u, p))
    n = len(x)
    s = np.array([st.typical for st in system.states])
    ctx = (f"{_fmt_point(given)}: not an equilibrium of {system.name!r} under "
           f"{_fmt_point(dict(zip(system.input_names, u))) or 'zero input'}")
    if system.conditions:
        g = model.conditions(x[None, :], u[None, :], p[None, :])[0]
        bad = [c.label for c, v in zip(system.conditions, g) if not v >= -1e-12]
        if bad:
            raise EquilibriumError(f"equilibrium {ctx}: the state is outside the validity domain ({'; '.join(bad)})")
    xdot = xdot.reshape(-1)
    As = A.reshape(n, n) * s[None, :] / s[:, None]
    r = np.abs(xdot) / s
    rel = r / max(float(np.linalg.norm(As, 2)), 1e-300)
    if not np.all(np.isfinite(xdot)):
        raise EquilibriumError(f"equilibrium {ctx}: the dynamics are not finite there")
    if np.max(rel) > EQUILIBRIUM_TOL:
        i = int(np.argmax(rel))
        st = system.states[i]
        raise EquilibriumError(
            f"equilibrium {ctx}: the rate of {st.name} is {xdot[i]:.4g} ({st.unit})/s (scaled residual {rel[i]:.3g} > "
            f"{EQUILIBRIUM_TOL:g}); give only the inputs to have the equilibrium solved for")
