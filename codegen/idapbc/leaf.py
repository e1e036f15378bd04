"""The leaf of the conserved quantities of J through a state, numerically.

Conserved quantities (Casimirs) of ``x' = (J - R) dH/dx + (G - P) u`` are functions
whose gradients ``w`` satisfy ``w^T [J - R, G - P] = 0``: no input and no energy
change them.  The curling HASEL has one per segment (the top-film length tied to
the angle).  A closed loop ``(J_d - R_d) dH_d/dx`` that keeps them lives on the same
leaf, so equilibria, Hessians, linearisations and sublevel sets are computed on it.

As in :mod:`phs.equilibria`, the leaf needs no closed form: the rows ``W(x)``
spanning the conserved directions come from an SVD of the scaled structure, the
dependent coordinates ``x_D`` (pivots) follow the free ones ``x_F`` through
``dx_D = S(x) dx_F`` with ``S = -W_D^-1 W_F`` (independent of the basis chosen for
``W``), and second derivatives of the leaf come from central differences of ``S``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.integrate
import scipy.linalg

from codegen._solver_errors import in_words
from phs.errors import EquilibriumError

if TYPE_CHECKING:
    import casadi as ca


class Leaf:
    """Free/dependent split, tangent basis, transport and curvature of the leaf through ``x_ref``.

    Parameters
    ----------
    struct : callable
        ``struct(x) -> [J - R, G - P]`` as an (n, n + m) array (a CasADi function is also accepted).
    scale : array
        Typical magnitudes of the states.
    x_ref : array
        A state on the leaf.

    Notes
    -----
    The split comes from an SVD at ``x_ref``.  Afterwards ``S`` needs no SVD: every rate satisfies
    ``x'_D = S x'_F``, so with ``M = [J - R, G - P]`` scaled by rows, ``S = M_D[:, C] M_F[:, C]^-1`` for any
    set ``C`` of columns on which the free rows are independent (chosen by pivoting at ``x_ref``).  When
    ``struct`` is a CasADi function the same formula gives ``S`` as a CasADi function (:attr:`S_function`).

    Examples
    --------
    >>> import numpy as np
    >>> struct = lambda x: np.array([[0.0, 1.0, 0.0], [-1.0, -0.1, 1.0]])   # a damped oscillator
    >>> Leaf(struct, np.ones(2), np.zeros(2)).k
    0
    """

    def __init__(self, struct, scale, x_ref):
        self.struct = struct
        self.s = np.asarray(scale, dtype=float)
        x_ref = np.asarray(x_ref, dtype=float)
        W0 = self._null(x_ref)
        self.k = W0.shape[0]
        if self.k:
            _, _, piv = scipy.linalg.qr(W0 * self.s[None, :], pivoting=True)
            self.dep = sorted(int(i) for i in piv[: self.k])
        else:
            self.dep = []
        self.free = [i for i in range(len(self.s)) if i not in self.dep]
        self.cols: list[int] = []
        self.S_function = None
        if self.k:
            Ms = self._scaled(x_ref)
            _, _, cp = scipy.linalg.qr(Ms[self.free], pivoting=True)
            self.cols = sorted(int(c) for c in cp[: len(self.free)])
            try:
                import casadi as ca

                if isinstance(struct, ca.Function):
                    X = ca.SX.sym("x", len(self.s))
                    M = struct(X) / ca.DM(self.s)
                    Af = M[self.free, self.cols]
                    Ad = M[self.dep, self.cols]
                    St = ca.solve(Af.T, Ad.T).T
                    S = St * ca.DM(np.outer(self.s[self.dep], 1.0 / self.s[self.free]))
                    self.S_function = ca.Function("leaf_S", [X], [S])
            except ImportError:  # pragma: no cover - casadi is a dependency of codegen
                pass

    def _scaled(self, x) -> np.ndarray:
        with np.errstate(all="ignore"):
            M = np.asarray(self.struct(x), dtype=float).reshape(len(self.s), -1)
        if not np.all(np.isfinite(M)):
            raise EquilibriumError("the structure [J - R, G - P] is not finite at " + np.array2string(np.asarray(x)))
        return M / self.s[:, None]

    def _null(self, x) -> np.ndarray:
        """Rows ``w`` (unscaled coordinates) with ``w^T [J - R, G - P] = 0``, by SVD.

        Rates are scaled by ``1/s`` and columns equilibrated, so that only exact structural dependences fall
        below the threshold (1e-12 of the largest singular value), not the slow modes of a stiff model.
        """
        Ms = self._scaled(x)
        cn = np.linalg.norm(Ms, axis=0)
        Ms = Ms[:, cn > 0] / cn[cn > 0]
        if Ms.shape[1] == 0:
            return np.diag(1 / self.s)
        U, sv, _ = np.linalg.svd(Ms)
        r = int(np.sum(sv > 1e-12 * sv[0])) if sv.size and sv[0] > 0 else 0
        return U[:, r:].T / self.s[None, :]

    def S(self, x) -> np.ndarray:
        """``dx_D / dx_F`` at ``x`` (shape (k, n - k))."""
        if not self.k:
            return np.zeros((0, len(self.free)))
        Ms = self._scaled(np.asarray(x, dtype=float))
        St = np.linalg.solve(Ms[np.ix_(self.free, self.cols)].T, Ms[np.ix_(self.dep, self.cols)].T).T
        return St * self.s[self.dep][:, None] / self.s[self.free][None, :]

    def W(self, x) -> np.ndarray:
        """Conserved directions at ``x`` (k rows ``[-S, I]`` in the (free, dependent) columns)."""
        W = np.zeros((self.k, len(self.s)))
        if self.k:
            W[:, self.dep] = np.eye(self.k)
            W[:, self.free] = -self.S(x)
        return W

    def tangent(self, x) -> np.ndarray:
        """Basis of the leaf's tangent space at ``x``: ``dx / dx_F`` (shape (n, n - k))."""
        T = np.zeros((len(self.s), len(self.free)))
        T[self.free, np.arange(len(self.free))] = 1.0
        if self.k:
            T[self.dep] = self.S(x)
        return T

    def curvature(self, x, rel_step: float = 1e-4) -> np.ndarray:
        """Second derivatives ``d^2 x / dx_Fi dx_Fj`` of the leaf at ``x`` (shape (n, nF, nF)), by central
        differences of ``S`` along the tangent directions (steps ``rel_step`` times the free states' scales)."""
        n, nF = len(self.s), len(self.free)
        K = np.zeros((n, nF, nF))
        if not self.k:
            return K
        x = np.asarray(x, dtype=float)
        T = self.tangent(x)
        for j in range(nF):
            h = rel_step * self.s[self.free[j]]
            dS = (self.S(x + h * T[:, j]) - self.S(x - h * T[:, j])) / (2 * h)
            K[self.dep, :, j] = dS
        K[self.dep] = (K[self.dep] + np.transpose(K[self.dep], (0, 2, 1))) / 2
        return K

    def stepper(self, covector=None, rtol: float = 1e-11) -> ca.Function:
        """A CasADi CVODES integrator moving along the leaf over a straight path of the free coordinates:
        ``(x_from, dx_F) -> (x_D at the end, int v . dx)``, with ``covector`` a CasADi function ``v(x)``."""
        import casadi as ca

        cache = self.__dict__.setdefault("_steppers", {})
        key = (id(covector), rtol)
        if key in cache:
            return cache[key]
        n, nF, k = len(self.s), len(self.free), self.k
        xs = ca.SX.sym("xs", n)
        d = ca.SX.sym("d", nF)
        t = ca.SX.sym("t")
        y = ca.SX.sym("y", max(k, 1))
        parts = [None] * n
        for a, i in enumerate(self.free):
            parts[i] = xs[i] + t * d[a]
        sD = ca.DM(self.s[self.dep]) if k else ca.DM.ones(1)
        for a, i in enumerate(self.dep):
            parts[i] = y[a] * sD[a]  # dependent coordinates integrated scaled by their typical magnitudes
        x = ca.vertcat(*parts)
        xdot_d = ca.mtimes(self.S_function(x), d) if k else ca.SX.zeros(1)
        ydot = xdot_d / sD
        dae = {"x": y, "p": ca.vertcat(xs, d), "t": t, "ode": ydot}
        if covector is not None:
            v = covector(x)
            dx = [None] * n
            for a, i in enumerate(self.free):
                dx[i] = d[a]
            for a, i in enumerate(self.dep):
                dx[i] = xdot_d[a]
            dae["quad"] = ca.dot(v, ca.vertcat(*dx))
        opts = {"abstol": rtol * 1e-2, "reltol": rtol, "disable_internal_warnings": True, "max_num_steps": 20000,
                "quad_err_con": covector is not None}
        F = ca.integrator("leaf_step", "cvodes", dae, 0.0, 1.0, opts)
        cache[key] = F
        return F

    def transport(self, x_from, xf_to, covector=None, rtol: float = 1e-11) -> np.ndarray | tuple[np.ndarray, float]:
        """Move along the leaf from ``x_from`` to free coordinates ``xf_to`` (straight path in ``x_F``).

        With ``covector`` (a callable ``v(x)``, or a CasADi function for the fast path), also returns
        ``int v . dx`` along the path.

        Raises
        ------
        EquilibriumError
            When the conserved quantities cannot be followed (the leaf ends, e.g. at a singular structure).
        """
        import casadi as ca

        x_from = np.asarray(x_from, dtype=float)
        x = x_from.copy()
        dxf = np.asarray(xf_to, dtype=float) - x_from[self.free]
        if not self.k and covector is None:
            x[self.free] = xf_to
            return x
        fast = (self.S_function is not None or not self.k) and (covector is None or isinstance(covector, ca.Function))
        if fast:
            F = self.stepper(covector, rtol)
            y0 = x_from[self.dep] / self.s[self.dep] if self.k else np.zeros(1)
            try:
                out = F(x0=y0, p=np.concatenate([x_from, dxf]))
            except RuntimeError as exc:
                raise EquilibriumError("could not follow the conserved quantities along the leaf: "
                                       + in_words(str(exc).splitlines()[-1], hint="")) from None
            yf = np.asarray(out["xf"], dtype=float).reshape(-1)
            if not np.all(np.isfinite(yf)):
                raise EquilibriumError("could not follow the conserved quantities along the leaf (non-finite)")
            x[self.free] = xf_to
            if self.k:
                x[self.dep] = yf * self.s[self.dep]
            if covector is None:
                return x
            return x, float(np.asarray(out["qf"], dtype=float).reshape(-1)[0])

        def ode(t, y):
            z = x_from.copy()
            z[self.free] = x_from[self.free] + t * dxf
            z[self.dep] = y[: self.k]
            dxd = self.S(z) @ dxf if self.k else np.zeros(0)
            if covector is None:
                return dxd
            v = np.asarray(covector(z), dtype=float).reshape(-1)
            return np.concatenate([dxd, [v[self.free] @ dxf + (v[self.dep] @ dxd if self.k else 0.0)]])

        y0 = np.concatenate([x_from[self.dep], [0.0]]) if covector is not None else x_from[self.dep]
        atol = np.concatenate([1e-13 * self.s[self.dep], [1e-18]]) if covector is not None else 1e-13 * self.s[self.dep]
        try:
            sol = scipy.integrate.solve_ivp(ode, (0.0, 1.0), y0, rtol=rtol, atol=atol, method="DOP853")
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise EquilibriumError(f"could not follow the conserved quantities along the leaf: {exc}") from None
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise EquilibriumError(f"could not follow the conserved quantities along the leaf: {sol.message}")
        x[self.free] = xf_to
        x[self.dep] = sol.y[: self.k, -1]
        return (x, float(sol.y[-1, -1])) if covector is not None else x
