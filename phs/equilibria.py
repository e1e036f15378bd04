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
by pseudo-transient continuation (backward-Euler steps of growing size, ending
in Newton's method) on the free rate equations, each trial point transported
along the leaf from the previous one (the leaf is path-independent) and the
Jacobian restricted to the leaf by the chain rule ``dx_D/dx_F = -W_D^-1 W_F``.
Started from a state at rest it converges to the stable equilibrium the
dynamics would reach.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from numbers import Real

import numpy as np
import scipy.integrate
import scipy.linalg

from phs._results import ResultMixin, finish, panels, require_pandas
from phs.errors import EquilibriumError, InputDataError


@dataclass(frozen=True, repr=False)
class EquilibriumResult(ResultMixin):
    """An equilibrium: state and input vectors, the scaled residual and how it was found.

    ``eq["k.l"]`` is a state's value, :meth:`as_dict` all of them; :meth:`plot` draws the states (over their
    typical sizes when the system gives them), :meth:`to_pandas` lists states and inputs.  It is accepted
    wherever an operating point is, e.g. ``linearize(s, equilibrium(s, u=...))`` or ``certify(s, equilibrium=eq)``.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> eq = equilibrium(mass_spring_damper(), u={"F": 2.0})
    >>> round(eq["k.l"], 9), eq.conserved
    (0.5, 0)
    >>> eq  # doctest: +ELLIPSIS
    EquilibriumResult('msd', m.p=..., k.l=0.5; F=2; stable, residual ...)
    """

    system_name: str
    state_names: tuple
    x: np.ndarray
    u: np.ndarray
    residual: float
    conserved: int
    dependent: tuple = ()
    info: dict = field(default_factory=dict)
    input_names: tuple = ()
    typical: tuple = ()
    """The states' typical magnitudes (the scale :meth:`plot` divides by), when known."""

    def __getitem__(self, name: str) -> float:
        if name in self.state_names:
            return float(self.x[self.state_names.index(name)])
        raise KeyError(f"no state {name!r}; states: {', '.join(self.state_names)}")

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.state_names, map(float, self.x)))

    def _inputs(self) -> list[str]:
        return list(self.input_names) or [f"u[{k}]" for k in range(len(self.u))]

    def _headline(self) -> str:
        def point(keys, vals):
            shown = ", ".join(f"{k}={float(v):.4g}" for k, v in list(zip(keys, vals))[:6])
            return shown + (f", ... ({len(keys) - 6} more)" if len(keys) > 6 else "")

        stable = self.info.get("stable")
        return (f"{self.system_name!r}, {point(self.state_names, self.x)}; {point(self._inputs(), self.u) or 'no input'}"
                + ("" if stable is None else "; stable" if stable else "; unstable")
                + f", residual {self.residual:.2g}" + (f", {self.conserved} conserved" if self.conserved else ""))

    def _table(self) -> tuple[list, list]:
        rows = [(n, "state" + (" (dependent)" if n in self.dependent else ""), float(v))
                for n, v in zip(self.state_names, self.x)]
        rows += [(n, "input", float(v)) for n, v in zip(self._inputs(), self.u)]
        return ["name", "kind", "value"], rows

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """States and inputs, one row each (``kind``: state, dependent state or input; ``value``), indexed by name.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> round(float(equilibrium(mass_spring_damper(), u={"F": 2.0}).to_pandas().loc["k.l", "value"]), 9)  # doctest: +SKIP
        0.5
        """
        pd = require_pandas("EquilibriumResult.to_pandas()")
        header, rows = self._table()
        return pd.DataFrame({c: [r[k] for r in rows] for k, c in enumerate(header[1:], start=1)},
                            index=pd.Index([r[0] for r in rows], name="name"))

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """The equilibrium's states as horizontal bars, each divided by its typical size when known.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes, optional
            Draw into this axes.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> fig = equilibrium(mass_spring_damper(), u={"F": 2.0}).plot()
        >>> [t.get_text() for t in fig.axes[0].get_yticklabels()]   # top to bottom
        ['m.p', 'k.l']
        """
        n = len(self.state_names)
        fig, grid = panels(ax, 1, figsize=(7, 0.35 * n + 1.6), what="EquilibriumResult.plot")
        a = grid[0, 0]
        scale = np.asarray(self.typical, dtype=float) if len(self.typical) == n else np.ones(n)
        a.barh(np.arange(n)[::-1], self.x / scale, color=["tab:gray" if s in self.dependent else "tab:blue"
                                                          for s in self.state_names])
        a.set_yticks(np.arange(n)[::-1], list(self.state_names))
        a.axvline(0.0, color="k", lw=0.6)
        a.set_xlabel("state / typical size [1]" if len(self.typical) == n else "state value")
        u = ", ".join(f"{k}={float(v):.4g}" for k, v in zip(self._inputs(), self.u))
        a.set_title(f"{self.system_name}: equilibrium at {u or 'zero input'}", fontsize=9)
        return finish(fig, path)


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


def equilibrium(system, u=None, x0=None, params=None, *, guess=None, tol: float = 1e-10,
                max_nfev: int = 500, h0: float = 1e-6, stable: bool = True, signs: bool = True,
                _growth: float = 10.0) -> EquilibriumResult:
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
        Parameter overrides (a value of the wrong sign is refused, see :meth:`PHSystem.param_vector`).
    guess : dict, optional
        Starting values of some states (moved onto the leaf through ``x0`` first).
    max_nfev : int
        Maximum number of pseudo-transient steps.
    h0 : float
        First pseudo-time step [s]; it grows as the residual falls.
    stable : bool
        Prefer a stable equilibrium: when the one found is unstable (an eigenvalue of the
        linearisation on the leaf with positive real part), retry following the dynamics more
        closely; ``info["stable"]`` reports the outcome.
    signs : bool
        ``False`` accepts a parameter override of the wrong sign (only for analyses that report
        what it does, such as the passivity certificate's what-if).
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
    base = np.array([st.initial for st in system.states])
    xs = _vector(system, x0, names, "state x0", base)
    uv = _vector(system, u, system.input_names, "input u", np.zeros(len(system.inputs)))
    p = system.param_vector(params, signs=signs)
    fdyn = system.lambdify(system.dynamics)
    import sympy as sp

    A = system.lambdify(sp.Matrix.hstack(system.J - system.R, system.G - system.P))

    fcond = system.lambdify([c.expr for c in system.conditions]) if system.conditions else None

    def inside(x) -> bool:
        if fcond is None:
            return True
        with np.errstate(all="ignore"):
            g = np.asarray(fcond(x, uv, p), dtype=float).reshape(-1)
        return bool(np.all(g >= -1e-12))

    def rate(x):
        with np.errstate(all="ignore"):
            return np.asarray(fdyn(x, uv, p), dtype=float).reshape(-1)

    def null_rows(x):
        """Rows w (in state coordinates) with w^T [J - R, G - P] = 0: the conserved directions.

        Rows (rates) are scaled by 1/s and columns equilibrated, so that only exact structural
        dependences fall below the threshold, not the slow modes of a stiff model (their singular
        values are ~1e-8 of the largest in an electrostatic actuator, structural zeros ~1e-16).
        """
        with np.errstate(all="ignore"):
            M = np.asarray(A(x, uv, p), dtype=float)
        if M.size == 0:
            return np.zeros((0, len(x)))
        if not np.all(np.isfinite(M)):
            raise EquilibriumError(f"equilibrium of {system.name!r}: the structure is not finite along the leaf")
        Ms = M / s[:, None]
        cn = np.linalg.norm(Ms, axis=0)
        Ms = Ms[:, cn > 0] / cn[cn > 0]
        if Ms.shape[1] == 0:
            return np.diag(1 / s)
        U, sv, _ = np.linalg.svd(Ms)
        r = int(np.sum(sv > 1e-12 * sv[0])) if sv.size and sv[0] > 0 else 0
        return U[:, r:].T / s[None, :]

    W0 = null_rows(xs)
    k = W0.shape[0]
    if k:
        _, _, piv = scipy.linalg.qr(W0 * s[None, :], pivoting=True)  # pivot on scaled coordinates
        dep = sorted(piv[:k].tolist())
    else:
        dep = []
    free = [i for i in range(len(xs)) if i not in dep]
    r0 = rate(xs) / s
    rscale = max(float(np.max(np.abs(r0))) if np.all(np.isfinite(r0)) else 1.0, 1e-300)

    def transport(x_from, xf_to):
        """Move along the leaf from ``x_from`` to free coordinates ``xf_to`` (straight path in x_F)."""
        x = x_from.copy()
        if not dep:
            x[free] = xf_to
            return x
        dxf = xf_to - x_from[free]

        def ode(_t, xd):
            y = x_from.copy()
            y[free] = x_from[free] + _t * dxf
            y[dep] = xd
            W = null_rows(y)[:k]
            return np.linalg.solve(W[:, dep], -W[:, free] @ dxf)

        try:
            sol = scipy.integrate.solve_ivp(ode, (0.0, 1.0), x_from[dep], rtol=1e-11, atol=1e-13 * s[dep],
                                            method="DOP853")
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise EquilibriumError(f"equilibrium of {system.name!r}: could not follow the conserved quantities: {exc}") from None
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise EquilibriumError(f"equilibrium of {system.name!r}: could not follow the conserved quantities: {sol.message}")
        x[free] = xf_to
        x[dep] = sol.y[:, -1]
        return x

    fjac = system.lambdify(system.dynamics_jacobian)

    def jac_full(x):
        """d rate / d (x / s), exact (finite differences lose the slow modes of stiff models)."""
        with np.errstate(all="ignore"):
            Jx = np.asarray(fjac(x, uv, p), dtype=float).reshape(len(x), len(x))
        return Jx * s[None, :]

    def on_leaf(Jx, x):
        """Restrict to the free coordinates with the chain rule x_D(x_F): dx_D/dx_F = -W_D^-1 W_F."""
        JF = Jx[:, free]
        if dep:
            W = null_rows(x)[:k] * s[None, :]  # in scaled coordinates
            JF = JF - Jx[:, dep] @ np.linalg.solve(W[:, dep], W[:, free])
        return JF

    # Pseudo-transient continuation on the leaf: backward-Euler steps of growing size h on the
    # free coordinates, (I/h - df_F/dx_F) dx_F = f_F, the dependent coordinates transported along
    # the leaf.  Small h follows the dynamics (robust from far away, towards stable equilibria);
    # as h grows the step becomes Newton's on f_F = 0, which is square: on the leaf the dependent
    # rates follow from the free ones (w^T x' = 0).
    x = xs.copy()
    if guess is not None:
        xg = _vector(system, guess, names, "state guess", xs)
        x = transport(xs, xg[free])
    f = rate(x)
    if not np.all(np.isfinite(f)):
        raise EquilibriumError(f"equilibrium of {system.name!r}: the dynamics are not finite at the starting point")
    nfev, h, growth = 0, float(h0), float(_growth)
    stalled = False
    norm = float(np.linalg.norm(f[free] / s[free]))
    for _ in range(max_nfev):
        if np.max(np.abs(f / s)) / rscale <= tol * 1e-2:
            break
        JF = on_leaf(jac_full(x), x)[free]  # d (f_F / s_F) / d (x_F / s_F) up to the row scaling below
        JF = JF / s[free][:, None]
        accepted = False
        for _try in range(30):
            M = np.eye(len(free)) / h - JF
            try:
                dz = np.linalg.solve(M, f[free] / s[free])
            except np.linalg.LinAlgError:
                h /= 10
                continue
            try:
                xt = transport(x, x[free] + dz * s[free])
            except EquilibriumError:
                h /= 10
                continue
            nfev += 1
            ft = rate(xt)
            nt = float(np.linalg.norm(ft[free] / s[free])) if np.all(np.isfinite(ft)) and inside(xt) else np.inf
            if nt == np.inf:  # non-finite or outside the validity domain: a smaller pseudo-time step
                h /= 10
                continue
            # switched evolution relaxation: backward Euler is stable for any h on stable dynamics,
            # so every finite step is kept and h grows as the residual falls
            x, f = xt, ft
            h = min(h * min(max(norm / max(nt, 1e-300), 0.5), growth) * 1.5, 1e15)
            norm = nt
            accepted = True
            break
        if not accepted:
            stalled = True
            break
    res = float(np.max(np.abs(rate(x) / s))) / rscale if len(x) else 0.0
    if res <= tol and not inside(x):
        bad = [c.label for c, g in zip(system.conditions, np.asarray(fcond(x, uv, p), dtype=float).reshape(-1)) if g < -1e-12]
        raise EquilibriumError(f"the equilibrium of {system.name!r} found for u={dict(zip(system.input_names, map(float, uv)))} "
                               f"lies outside the validity domain: {'; '.join(bad)}")
    if not np.isfinite(res) or res > tol:
        raise EquilibriumError(
            f"no equilibrium of {system.name!r} found for u={dict(zip(system.input_names, map(float, uv)))}: "
            f"scaled residual {res:.3g} > {tol:g} at " + ", ".join(f"{n}={v:.6g}" for n, v in zip(names, x))
            + (" (the continuation could not go on without leaving the validity domain or the dynamics becoming "
               "non-finite: no equilibrium is reachable from x0, e.g. beyond a pull-in or saturation)" if stalled
               else " (none may exist, e.g. beyond a pull-in or a saturation; otherwise give a starting point with guess=)")
        )
    Jl = on_leaf(jac_full(x), x)[free] / s[free][:, None]
    ev = np.linalg.eigvals(Jl) if Jl.size else np.zeros(0)
    is_stable = bool(np.all(ev.real <= 1e-9 * max(1.0, float(np.max(np.abs(ev))) if ev.size else 1.0)))
    if stable and not is_stable and growth > 2.0:
        try:
            return equilibrium(system, u=u, x0=x0, params=params, guess=guess, tol=tol, max_nfev=4 * max_nfev, h0=h0,
                               stable=True, signs=signs, _growth=1.3)
        except EquilibriumError:
            pass
    return EquilibriumResult(system.name, tuple(names), x, uv, res, k, tuple(names[i] for i in dep),
                             {"nfev": nfev, "stable": is_stable, "eigenvalues": ev}, tuple(system.input_names), tuple(s))
