"""Linear analysis of an IDA-PBC closed loop on the leaf of the conserved quantities at ``x*``.

The closed loop's Jacobian is restricted to the leaf (free state coordinates,
then the integrator states): its eigenvalues are the closed-loop modes, its
inverse gives the static gain from an input offset to the passive output, and
both set the gain of integral action (:func:`integral_gain`).  The Hessian of
``H_d`` along the leaf includes the leaf's own curvature.  Every function takes
the controller (:class:`codegen.idapbc.Controller`) as its argument.
"""

from __future__ import annotations

import numpy as np

from phs.errors import InputDataError


def _leaf_linear(ctrl):
    """Closed-loop Jacobian on the leaf at (x*, xi = 0): free state coordinates then integrator states."""
    lf, n, nxi = ctrl.leaf, ctrl.num.n, ctrl.n_xi
    x = ctrl.x_star
    Afull = np.asarray(ctrl._fx["cl_jac"](x, np.zeros(nxi)), dtype=float).reshape(n + nxi, n + nxi)
    T = lf.tangent(x)
    F = lf.free
    top = np.hstack([Afull[F][:, :n] @ T, Afull[F][:, n:]])
    bottom = np.hstack([Afull[n:, :n] @ T, Afull[n:, n:]])
    return np.vstack([top, bottom]), T


def closed_loop_modes(ctrl) -> np.ndarray:
    """Eigenvalues of the closed loop linearised on the leaf at ``x*``.

    Examples
    --------
    >>> from codegen.idapbc import design
    >>> from systems.examples import mass_spring_damper
    >>> ev = closed_loop_modes(design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0))
    >>> np.round(np.sort(ev.real), 6).tolist()   # s**2 + 2.4 s + 10 = 0
    [-1.2, -1.2]
    """
    A, _ = _leaf_linear(ctrl)
    return np.linalg.eigvals(A) if A.size else np.zeros(0)


def static_gain(ctrl, with_reference: bool = False) -> np.ndarray | tuple[np.ndarray, float]:
    """DC gain of the target closed loop from an input offset to the passive output ``y_d = g^T dH_d/dx``
    (and, with ``with_reference``, the bound ``|C| |A^-1| |g|`` it is compared with to call it zero)."""
    lf = ctrl.leaf
    x = ctrl.x_star
    A, T = _leaf_linear(ctrl.with_integral(None) if ctrl.integral else ctrl)
    g = np.asarray(ctrl._fx["g"](x), dtype=float).reshape(ctrl.num.n, -1)
    C = np.asarray(ctrl._fx["yd_jac"](x), dtype=float).reshape(-1, ctrl.num.n) @ T
    sF = ctrl.num.scale[lf.free]
    try:
        G = -C @ np.linalg.solve(A, g[lf.free])
        # the same product in states scaled by their typical magnitudes (mixed units would make it meaningless)
        As = A * sF[None, :] / sF[:, None]
        ref = (np.linalg.norm(C * sF[None, :], 2) * np.linalg.norm(np.linalg.inv(As), 2)
               * np.linalg.norm(g[lf.free] / sF[:, None], 2))
    except np.linalg.LinAlgError:
        G, ref = np.full((g.shape[1], g.shape[1]), np.nan), np.nan
    return (G, ref) if with_reference else G


def leaf_hessian(ctrl) -> np.ndarray:
    """Hessian of ``H_d`` along the leaf at ``x*`` in the free coordinates scaled by their typical magnitudes."""
    lf, x = ctrl.leaf, ctrl.x_star
    n = ctrl.num.n
    T = lf.tangent(x)
    Hx = np.asarray(ctrl._fx["hess"](x), dtype=float).reshape(n, n)
    dHd = np.asarray(ctrl._fx["dHd"](x), dtype=float).reshape(n)
    K = lf.curvature(x)
    Hs = T.T @ Hx @ T + np.einsum("k,kij->ij", dHd, K)
    Hs = (Hs + Hs.T) / 2
    sF = ctrl.num.scale[lf.free]
    return Hs * sF[:, None] * sF[None, :]


def integral_gain(ctrl, kind: str, time: float | None = None) -> np.ndarray:
    """The gain ``K_i`` of integral action ``kind`` with time constant ``time`` for ``ctrl`` (without integral action).

    ``"output"``: ``K_i = S^+ / time`` with ``S`` the sensitivity of the targets to the controlled inputs along the
    family of equilibria; ``"passive"``: ``K_i = G^-1 / time`` with ``G`` the :func:`static_gain`.  The default
    ``time`` is 5 times the slowest closed-loop time constant.

    Raises
    ------
    InputDataError
        For a time that is not positive, or a passive output without static response to the input.

    Examples
    --------
    >>> from codegen.idapbc import design
    >>> from systems.examples import mass_spring_damper
    >>> ctrl = design(mass_spring_damper(), {"position": 0.5}, damping=1.0)
    >>> integral_gain(ctrl, "output", 2.0).round(6).tolist()   # 1 / (tau * dq/dF) = 4 / 2
    [[2.0]]
    """
    if time is None:
        ev = closed_loop_modes(ctrl)
        slow = np.min(np.abs(ev.real)) if ev.size and np.all(ev.real < 0) else 1.0
        time = 5.0 / slow
    if not (np.isfinite(time) and time > 0):
        raise InputDataError(f"integral_time must be a positive number, got {time!r}")
    if kind == "output":
        sens = np.atleast_2d(ctrl.assignment.sensitivity)
        return np.linalg.pinv(sens) / time
    Gdc, ref = static_gain(ctrl, with_reference=True)
    if not np.all(np.isfinite(Gdc)) or np.min(np.abs(np.linalg.svd(Gdc, compute_uv=False))) <= 1e-8 * ref:
        raise InputDataError("the passive output does not respond statically to the input here "
                             "(no dissipation along g at x*): give integral_gain")
    return np.linalg.inv(Gdc) / time
