"""Equilibrium assignment: the state and constant input at which the targets hold.

A target fixes states or measured outputs (``tip = 0.03``).  The admissible
equilibria are the rest points ``(J - R) dH/dx + (G - P) u = 0`` on the leaf of
the conserved quantities through the starting state (g-perp of the rate is
zero and the rest is held by the input).  With as many targets as controlled
inputs the unknowns (free coordinates of the leaf and the controlled inputs)
and the equations (rates of the free coordinates and the targets) are square;
they are solved by Newton's method with the dependent coordinates transported
along the leaf, continued from the equilibrium at the starting input towards
the targets.  When the branch of equilibria leaves an input's declared range or
the validity domain, or folds before the target, the continuation stops there
and says so with the numbers: the largest reachable value and what limits it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from phs.errors import EquilibriumError, InputDataError


@dataclass(frozen=True)
class Target:
    """One regulated quantity: a state or a measured output, its required value and its scale."""

    name: str
    kind: str  # "state" or "measured"
    index: int
    value: float
    unit: str


def resolve_targets(system, target: dict) -> list[Target]:
    """Check ``{name: value}`` against the system's states and measured outputs.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> [t.kind for t in resolve_targets(mass_spring_damper(), {"position": 0.5})]
    ['measured']
    """
    if not isinstance(target, dict) or not target:
        raise InputDataError("target: give at least one NAME=VALUE (a state or a measured output)")
    out = []
    for name, value in target.items():
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputDataError(f"target {name!r}: value {value!r} is not a number") from None
        if not np.isfinite(v):
            raise InputDataError(f"target {name!r}: value {value!r} is not finite")
        if name in system.state_names:
            i = system.state_names.index(name)
            out.append(Target(name, "state", i, v, system.states[i].unit))
        elif name in system.measured_names:
            i = system.measured_names.index(name)
            out.append(Target(name, "measured", i, v, system.measured[i].unit))
        else:
            raise InputDataError(f"target {name!r}: system {system.name!r} has no state or measured output of that "
                                 f"name; states: {', '.join(system.state_names)}; measured: "
                                 f"{', '.join(system.measured_names) or 'none'}")
    return out


@dataclass(frozen=True)
class Assignment:
    """The assigned equilibrium: state, full input vector, achieved targets and how it was reached."""

    x: np.ndarray
    u: np.ndarray
    achieved: dict
    residual: float
    sensitivity: np.ndarray
    open_loop_eigenvalues: np.ndarray
    path: tuple = ()
    info: dict = field(default_factory=dict)


class _Solver:
    def __init__(self, num, leaf, targets, ctrl, u_base, ranges):
        self.num, self.leaf, self.targets, self.ctrl = num, leaf, targets, list(ctrl)
        self.u_base = np.asarray(u_base, dtype=float)
        self.ranges = ranges
        self.F, self.D = leaf.free, leaf.dep
        self.sF = num.scale[self.F]
        self.su = np.array([max(abs(r[0]), abs(r[1])) if r is not None else 1.0 for r in ranges]) if ranges else np.ones(0)
        self.su[self.su == 0] = 1.0

    def u_full(self, uc):
        u = self.u_base.copy()
        u[self.ctrl] = uc
        return u

    def y(self, x, u, jac: bool = False):
        n = self.num.n
        if any(t.kind == "measured" for t in self.targets):
            ym, yx, yu = self.num.measured_jac(x, u)
        vals, jx, ju = [], [], []
        for t in self.targets:
            if t.kind == "state":
                vals.append(x[t.index])
                jx.append(np.eye(n)[t.index])
                ju.append(np.zeros(self.num.m))
            else:
                vals.append(ym[t.index])
                jx.append(yx[t.index])
                ju.append(yu[t.index])
        if not jac:
            return np.array(vals)
        return np.array(vals), np.array(jx).reshape(len(self.targets), n), np.array(ju).reshape(len(self.targets), -1)

    def system(self, x, uc, ytau, with_targets: bool):
        """Residual and Jacobian in scaled variables (x_F / s_F, u_c / s_u)."""
        u = self.u_full(uc)
        f = self.num.rate(x, u)
        A, B = self.num.jac(x, u)
        S = self.leaf.S(x)
        AF = A[:, self.F] + (A[:, self.D] @ S if self.D else 0.0)
        rows = [np.hstack([AF[self.F] * self.sF[None, :], B[self.F][:, self.ctrl] * self.su[None, :]])]
        res = [f[self.F]]
        if with_targets:
            yv, yx, yu = self.y(x, u, jac=True)
            YF = yx[:, self.F] + (yx[:, self.D] @ S if self.D else 0.0)
            rows.append(np.hstack([YF * self.sF[None, :], yu[:, self.ctrl] * self.su[None, :]]))
            res.append(yv - ytau)
        Jac = np.vstack(rows)
        R = np.concatenate(res)
        if not with_targets:
            Jac = Jac[:, : len(self.F)]
        return R, Jac

    def newton(self, x, uc, ytau, with_targets=True, tol=1e-11, max_iter=40):
        x, uc = np.asarray(x, dtype=float).copy(), np.asarray(uc, dtype=float).copy()
        nF = len(self.F)
        for _ in range(max_iter):
            R, Jac = self.system(x, uc, ytau, with_targets)
            if not (np.all(np.isfinite(R)) and np.all(np.isfinite(Jac))):
                raise EquilibriumError("the dynamics are not finite")
            rn = np.max(np.abs(Jac), axis=1)
            rn[rn == 0] = 1.0
            err = float(np.max(np.abs(R / rn))) if len(R) else 0.0
            if err < tol:
                return x, uc, err
            try:
                dz = np.linalg.solve(Jac / rn[:, None], -R / rn)
            except np.linalg.LinAlgError:
                dz = np.linalg.lstsq(Jac / rn[:, None], -R / rn, rcond=None)[0]
            alpha = 1.0
            while alpha > 1e-4:
                try:
                    xt = self.leaf.transport(x, x[self.F] + alpha * dz[:nF] * self.sF)
                    uct = uc + alpha * dz[nF:] * self.su if with_targets else uc
                    Rt, _ = self.system(xt, uct, ytau, with_targets)
                except (EquilibriumError, np.linalg.LinAlgError):
                    alpha /= 4
                    continue
                et = float(np.max(np.abs(Rt / rn))) if np.all(np.isfinite(Rt)) else np.inf
                if et < (1 - 0.25 * alpha) * err or et < tol:
                    x, uc = xt, uct
                    break
                alpha /= 4
            else:
                raise EquilibriumError(f"Newton's method stalled (scaled residual {err:.3g})")
        R, Jac = self.system(x, uc, ytau, with_targets)
        rn = np.max(np.abs(Jac), axis=1)
        rn[rn == 0] = 1.0
        err = float(np.max(np.abs(R / rn)))
        if err > 1e3 * tol:
            raise EquilibriumError(f"Newton's method did not converge (scaled residual {err:.3g})")
        return x, uc, err


def _settle(sol, system, num, x0, uc, names):
    """Equilibrium at the fixed input ``uc`` from ``x0`` (Newton on the leaf, else :func:`phs.equilibrium`)."""
    try:
        return sol.newton(x0, uc, None, with_targets=False)[0]
    except EquilibriumError:
        from phs.equilibria import equilibrium

        try:
            eq = equilibrium(system, u=dict(zip(system.input_names, sol.u_full(uc))), x0=x0,
                             params=dict(zip(system.param_names, num.p)))
        except EquilibriumError as exc:
            raise EquilibriumError(f"no equilibrium of {system.name!r} to start the target continuation from at "
                                   f"{names} = {', '.join(f'{v:.6g}' for v in uc)}: {exc}") from None
        return eq.x


def _ramp(sol, x, uc_from, uc_to, system, names):
    """Follow the equilibrium from input ``uc_from`` to ``uc_to`` (steps shortened where Newton fails)."""
    s, step = 0.0, 1.0
    while s < 1.0:
        t = min(1.0, s + step)
        try:
            x = sol.newton(x, uc_from + t * (uc_to - uc_from), None, with_targets=False)[0]
            s, step = t, min(1.0, 2 * step)
        except EquilibriumError:
            step /= 4
            if step < 1e-6:
                raise EquilibriumError(f"no equilibrium of {system.name!r} found on the way to {names} = "
                                       f"{', '.join(f'{v:.6g}' for v in uc_to)}") from None
    return x


def _sensitivity(sol, x, uc):
    """d targets / d controlled inputs along the family of equilibria at ``(x, uc)``."""
    num, leaf, ctrl = sol.num, sol.leaf, sol.ctrl
    u = sol.u_full(uc)
    A, B = num.jac(x, u)
    S = leaf.S(x)
    AF = (A[:, leaf.free] + (A[:, leaf.dep] @ S if leaf.dep else 0.0))[leaf.free]
    _, yx, yu = sol.y(x, u, jac=True)
    YF = yx[:, leaf.free] + (yx[:, leaf.dep] @ S if leaf.dep else 0.0)
    try:
        return yu[:, ctrl] - YF @ np.linalg.solve(AF, B[leaf.free][:, ctrl])
    except np.linalg.LinAlgError:
        return np.full((len(sol.targets), len(ctrl)), np.nan)


def _describe(targets, y) -> str:
    return ", ".join(f"{t.name} = {v:.6g} {t.unit}".rstrip() for t, v in zip(targets, y))


def assign(num, leaf, targets, ctrl, u_base, x0, *, u_start=None) -> Assignment:
    """Continue the equilibrium from ``x0`` (at input ``u_start``) to the targets; see the module docstring.

    Raises
    ------
    EquilibriumError
        When no admissible equilibrium meets the targets, saying why (input range, validity domain, fold).
    """
    system = num.system
    ranges = [system.inputs[j].range for j in ctrl]
    sol = _Solver(num, leaf, targets, ctrl, u_base, ranges)
    uc0 = np.zeros(len(ctrl)) if u_start is None else np.asarray(u_start, dtype=float)
    for k, r in enumerate(ranges):
        if r is not None:
            uc0[k] = min(max(uc0[k], r[0]), r[1])
    ystar = np.array([t.value for t in targets])
    names = ", ".join(system.input_names[j] for j in ctrl)
    x = _settle(sol, system, num, x0, uc0, names)
    uc = uc0.copy()
    if not np.all(np.isfinite(_sensitivity(sol, x, uc))) or np.all(np.abs(_sensitivity(sol, x, uc) * sol.su) <= 1e-9 * (
            np.abs(ystar) + np.abs(sol.y(x, sol.u_full(uc))) + 1e-300)[:, None]):
        # the targets do not move with the inputs at the start (a force quadratic in a voltage, at zero voltage):
        # start from 1 % of each input's range instead, reached by continuation in the input
        nudge = np.array([(r[1] if r[1] > 0 else r[0]) / 100 if r is not None else 1.0 for r in ranges])
        x, uc = _ramp(sol, x, uc, nudge, system, names), nudge
    y0 = sol.y(x, sol.u_full(uc))
    path = [(uc.copy(), y0.copy())]
    tau, step = 0.0, 1.0
    goal = _describe(targets, ystar)

    def solve_at(t, xs, us):
        return sol.newton(xs, us, y0 + t * (ystar - y0))

    def limit(xx, ucv):
        """Why ``(xx, ucv)`` is not admissible (an input beyond its range, the validity domain), or None."""
        for k, r in enumerate(ranges):
            if r is not None and not (r[0] - 1e-9 * max(1.0, abs(r[0])) <= ucv[k] <= r[1] + 1e-9 * max(1.0, abs(r[1]))):
                return ("range", k)
        bad = num.violated(xx, sol.u_full(ucv))
        return ("domain", bad) if bad else None

    def bisect(t_ok, state_ok, t_bad, why):
        """Last admissible point before the branch becomes inadmissible, to 1e-4 of the step."""
        for _ in range(40):
            if t_bad - t_ok < 1e-4 * max(t_bad, 1e-12):
                break
            tm = (t_ok + t_bad) / 2
            try:
                xm, um, _ = solve_at(tm, *state_ok)
            except EquilibriumError:
                t_bad = tm
                continue
            w = limit(xm, um)
            if w is not None:
                t_bad, why = tm, w
            else:
                t_ok, state_ok = tm, (xm, um)
        return state_ok, why

    while tau < 1.0:
        t_try = min(1.0, tau + step)
        try:
            xn, un, _ = solve_at(t_try, x, uc)
        except EquilibriumError:
            step /= 4
            if step < 1e-7:
                yb = sol.y(x, sol.u_full(uc))
                raise EquilibriumError(
                    f"target {goal} is not reachable: the equilibria of {system.name!r} stop at {_describe(targets, yb)} "
                    f"({names} = {', '.join(f'{v:.6g}' for v in uc)}): the branch folds there, beyond it no constant "
                    "input holds the target") from None
            continue
        why = limit(xn, un)
        if why is not None:
            (xb, ub), why = bisect(tau, (x, uc), t_try, why)
            yb = sol.y(xb, sol.u_full(ub))
            if why[0] == "range":
                k = why[1]
                inp, (lo, hi) = system.inputs[ctrl[k]], ranges[k]
                side = "maximum" if abs(ub[k] - hi) <= abs(ub[k] - lo) else "minimum"
                raise EquilibriumError(
                    f"target {goal} is not reachable: the equilibrium needs {inp.name} beyond its range [{lo:g}, {hi:g}] "
                    f"{inp.unit} (more than the {side} {inp.name}); within the range the equilibria reach "
                    f"{_describe(targets, yb)} at {inp.name} = {ub[k]:.6g} {inp.unit}")
            raise EquilibriumError(
                f"target {goal} is not reachable: the branch of equilibria leaves the validity domain of {system.name!r} "
                f"({'; '.join(why[1])}) beyond {_describe(targets, yb)} ({names} = {', '.join(f'{v:.6g}' for v in ub)})")
        tau, x, uc = t_try, xn, un
        path.append((uc.copy(), sol.y(x, sol.u_full(uc))))
        step = min(1.0, 2 * step)
    x, uc, err = sol.newton(x, uc, ystar, tol=1e-13)
    if leaf.k:  # one transport from the start removes the drift accumulated by the many small ones
        x = leaf.transport(np.asarray(x0, dtype=float), x[leaf.free])
        x, uc, err = sol.newton(x, uc, ystar, tol=1e-13)
    u = sol.u_full(uc)
    # sensitivity of the targets to the controlled inputs along the family of equilibria, and open-loop modes
    sens = _sensitivity(sol, x, uc)
    A, _ = num.jac(x, u)
    S = leaf.S(x)
    AF = (A[:, leaf.free] + (A[:, leaf.dep] @ S if leaf.dep else 0.0))[leaf.free]
    eig = np.linalg.eigvals(AF) if AF.size else np.zeros(0)
    return Assignment(x, u, {t.name: float(v) for t, v in zip(targets, sol.y(x, u))}, err, sens, eig, tuple(path),
                      {"continuation_steps": len(path) - 1})
