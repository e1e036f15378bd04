"""Closed-loop simulation of a plant under an IDA-PBC controller (CVODES through CasADi).

The closed loop is the plant's generated right-hand side with its controlled
inputs replaced by the control law, plus the integral-action states.  The
plant may differ from the controller's model: other parameter values
(mismatch), and storages the design neglected (the controller reads only the
states it was designed on).  States are integrated scaled by their typical
magnitudes; ``Phi`` (the part of ``H_d`` without closed form) is a quadrature
``dPhi/dt = v(x) . x'`` of the same run, so ``H_d`` is evaluated exactly along
the trajectory.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from codegen._solver_errors import describe
from codegen.functions import generate
from codegen.idapbc.model import state_vector
from codegen.results import signal, write_csv_atomic
from phs._results import ResultMixin, finish, panels, require_pandas
from phs.errors import DomainError, InputDataError, SimulationError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure


class ClosedLoopResult(ResultMixin):
    """A closed-loop trajectory: plant states, controller states, inputs, measured outputs and ``H_d``.

    ``res["tip"]``, ``res["seg1.theta"]``, ``res["U"]``, ``res["H_d"]`` (desired energy minus its value at
    the assigned equilibrium), ``res["H_cl"]`` (the closed loop's storage: ``H_d`` plus the integrator's
    ``xi^T K_i xi / 2`` with passive integral action), ``res["xi"]``; :meth:`plot` draws the run,
    :meth:`to_pandas` gives a DataFrame indexed by time.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen.idapbc import design
    >>> from systems.examples import mass_spring_damper
    >>> res = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).simulate(np.linspace(0, 5, 51))
    >>> res.max_increase("H_d") <= 0.0
    True
    """

    def __init__(self, controller, plant, t, x, xi, u, measured, H_d, H_cl, params, info):
        self.controller, self.system = controller, plant
        self.t, self.x, self.xi, self.u = t, x, xi, u
        self.measured, self.H_d, self.H_cl = measured, H_d, H_cl
        self.params = params
        self.info = dict(info)

    def __getitem__(self, name: str) -> np.ndarray:
        return signal(self.system, name, x=self.x, u=self.u, measured=self.measured,
                      extra={"H_d": self.H_d, "H_cl": self.H_cl, "xi": self.xi}, known=self.columns)

    @property
    def columns(self) -> list[str]:
        s = self.system
        return s.state_names + s.input_names + s.measured_names + ["H_d", "H_cl"]

    def max_increase(self, name: str = "H_cl") -> float:
        """Largest increase of a signal between consecutive samples (<= 0 when non-increasing)."""
        v = self[name]
        return float(np.max(np.diff(v))) if len(v) > 1 else 0.0

    def error(self, name: str | None = None) -> np.ndarray:
        """Relative error of a target signal, ``(y - y*) / |y*|`` (the first target by default)."""
        tg = self.controller.targets[0] if name is None else next(t for t in self.controller.targets if t.name == name)
        return (self[tg.name] - tg.value) / max(abs(tg.value), 1e-300)

    def settling_time(self, tol: float = 0.01, name: str | None = None) -> float:
        """First time after which the target stays within ``tol`` (relative) of its value (inf if never)."""
        out = np.abs(self.error(name)) > tol
        if not out.any():
            return float(self.t[0])
        last = int(np.max(np.nonzero(out)[0]))
        return float(self.t[last + 1]) if last + 1 < len(self.t) else float("inf")

    def table(self) -> tuple[list[str], np.ndarray]:
        cols = self.columns
        return ["t"] + cols, np.column_stack([self.t] + [self[c] for c in cols])

    def to_csv(self, path) -> None:
        write_csv_atomic(path, *self.table())

    def to_pandas(self) -> pd.DataFrame:
        """Every signal of :attr:`columns` as a pandas DataFrame indexed by time ``t``; units in ``df.attrs["units"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen.idapbc import design
        >>> from systems.examples import mass_spring_damper
        >>> res = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).simulate(np.linspace(0, 5, 51))
        >>> df = res.to_pandas()  # doctest: +SKIP
        >>> round(float(df["position"].iloc[-1]), 1), df.attrs["units"]["H_d"]  # doctest: +SKIP
        (0.5, 'J')
        """
        pd = require_pandas("ClosedLoopResult.to_pandas()")
        header, data = self.table()
        df = pd.DataFrame({name: data[:, k] for k, name in enumerate(header) if name != "t"},
                          index=pd.Index(self.t, name="t"))
        s = self.system
        units = {"t": "s", "H_d": "J", "H_cl": "J"} | {st.name: st.unit for st in s.states}
        units |= {i.name: i.unit for i in s.inputs} | {m.name: m.unit for m in s.measured}
        df.attrs["units"] = {c: units[c] for c in header if c in units}
        return df

    def plot(self, path=None, *, ax=None, fig=None, reference=None) -> Figure:
        """Targets (and their set points), controlled inputs and the closed loop's storage against time.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).  A matplotlib Figure given
            here is taken as ``fig`` (the earlier call form ``plot(fig)``).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these three axes instead.
        fig : matplotlib Figure, optional
            Draw the three panels on this figure.
        reference : ignored
            Accepted for earlier callers; the set points are drawn from the controller's targets.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> import numpy as np
        >>> from codegen.idapbc import design
        >>> from systems.examples import mass_spring_damper
        >>> res = design(mass_spring_damper(), {"position": 0.5}, damping=1.0).simulate(np.linspace(0, 5, 51))
        >>> [a.get_ylabel() for a in res.plot().axes]
        ['target', 'input', 'H_d - H_d(x*) [J]']
        """
        if path is not None and hasattr(path, "subplots"):  # plot(fig): the earlier positional form
            fig, path = path, None
        ctrl = self.controller
        if fig is not None and ax is None:
            axes = fig.subplots(3, 1, sharex=True)
        else:
            fig, grid = panels(ax, 3, figsize=(8, 7), sharex=True, what="ClosedLoopResult.plot")
            axes = grid[:, 0]
        for tg in ctrl.targets:
            axes[0].plot(self.t, self[tg.name], label=tg.name)
            axes[0].axhline(tg.value, color="k", ls=":", lw=1, label=f"{tg.name}* = {tg.value:g}")
        axes[0].set_ylabel("target")
        for nm in ctrl.input_names:
            axes[1].plot(self.t, self[nm], label=nm)
        axes[1].set_ylabel("input")
        axes[2].plot(self.t, self.H_cl, label="H_d (+ integrator)" if ctrl.integral == "passive" else "H_d")
        axes[2].set_ylabel("H_d - H_d(x*) [J]")
        axes[2].set_xlabel("t [s]")
        for a in axes:
            a.grid(True, alpha=0.3)
            a.legend(loc="best", fontsize="small")
        return finish(fig, path)

    def _headline(self) -> str:
        return f"{self.system.name!r}, {len(self.t)} samples, t={self.t[0]:g}..{self.t[-1]:g}"

    def _table(self) -> tuple[list, list]:
        """Each target: its set point, final value and settling time (1 %); each controlled input's range."""
        rows = [(tg.name, "target", tg.value, float(self[tg.name][-1]), self.settling_time(0.01, tg.name))
                for tg in self.controller.targets]
        rows += [(nm, "input", "", float(self[nm][-1]), f"{np.min(self[nm]):.4g}..{np.max(self[nm]):.4g}")
                 for nm in self.controller.input_names]
        return ["signal", "kind", "set point", "final", "settling time [s] / range"], rows


def _plant_setup(ctrl, plant, params):
    if plant is None:
        plant = ctrl.system
        p = plant.param_vector({**ctrl.params, **(params or {})})
    else:
        p = plant.param_vector(params)
    missing = [nm for nm in ctrl.system.state_names if nm not in plant.state_names]
    if missing:
        raise InputDataError(f"the plant {plant.name!r} lacks the controller's state(s) {missing}")
    missing = [nm for nm in ctrl.input_names if nm not in plant.input_names]
    if missing:
        raise InputDataError(f"the plant {plant.name!r} lacks the controlled input(s) {missing}")
    idx = [plant.state_names.index(nm) for nm in ctrl.system.state_names]
    return plant, p, idx


def simulate_closed_loop(ctrl, t, *, x0=None, plant=None, params: dict | None = None, xi0=None,
                         saturate: bool = False, rtol: float = 1e-9, atol: float | None = None,
                         max_steps: int = 200000) -> ClosedLoopResult:
    """Simulate ``plant`` (default: the controller's own model) under the controller on the grid ``t``.

    Parameters
    ----------
    ctrl : Controller
    t : array
        Increasing output times.
    x0 : dict or array, optional
        Plant initial state (default: the controller's ``x0``; the plant's other states at zero clipped
        into their ranges).
    plant : PHSystem, optional
        The plant, e.g. the full model when the design neglected storages.
    params : dict, optional
        Plant parameter overrides (plant/controller mismatch).
    xi0 : array, optional
        Initial integrator state (default 0).
    saturate : bool
        Clip the controlled inputs into their declared ranges (otherwise they are only reported).
    rtol, atol : float
        CVODES tolerances (``atol`` on states scaled by their typical magnitudes; default ``rtol / 100``).

    Returns
    -------
    ClosedLoopResult

    Raises
    ------
    DomainError
        When the plant leaves its validity domain (time, condition and state named).
    SimulationError
        When the integrator fails.
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputDataError("time grid must be a strictly increasing 1-D array of at least 2 finite values")
    plant, p, idx = _plant_setup(ctrl, plant, params)
    fx = ctrl._fx
    fn = generate(plant)
    sx = fn.sx
    n, m = len(plant.states), len(plant.inputs)
    if x0 is None:
        xs = state_vector(plant, None)
        xs[idx] = ctrl.x0
    else:
        xs = state_vector(plant, x0)
    nxi = ctrl.n_xi
    xi_start = np.zeros(nxi) if xi0 is None else np.asarray(xi0, dtype=float).reshape(nxi)
    s = np.array([st.typical for st in plant.states])
    s_xi = np.ones(nxi)
    if nxi:
        ref = np.maximum(np.abs(ctrl.u_star), 1.0)
        s_xi = np.abs(np.linalg.solve(ctrl.K_i, ref)) if np.linalg.matrix_rank(ctrl.K_i) == nxi else np.ones(nxi)
        s_xi[~np.isfinite(s_xi) | (s_xi == 0)] = 1.0
    Z = ca.SX.sym("z", n + nxi)
    X = Z[:n] * ca.DM(s)
    Xi = Z[n:] * ca.DM(s_xi) if nxi else ca.SX(0, 1)  # a one-state plant: Z[1:] of a 1x1 Z is 1x0, not 0x1
    Xd = X[idx]
    u_ctrl = fx["law"](Xd, Xi)
    ranges = [plant.inputs[plant.input_names.index(nm)].range for nm in ctrl.input_names]
    if saturate:
        u_ctrl = ca.vertcat(*[ca.fmin(ca.fmax(u_ctrl[k], r[0]), r[1]) if r is not None else u_ctrl[k]
                              for k, r in enumerate(ranges)])
    fixed = {nm: float(ctrl.u_base[j]) for j, nm in enumerate(ctrl.system.input_names) if j not in ctrl.ctrl}
    parts = []
    for nm in plant.input_names:
        parts.append(u_ctrl[ctrl.input_names.index(nm)] if nm in ctrl.input_names else ca.SX(fixed.get(nm, 0.0)))
    U = ca.vertcat(*parts) if parts else ca.SX(0, 1)
    xdot = ca.substitute(sx["xdot"], ca.vertcat(sx["x"], sx["u"], sx["p"]), ca.vertcat(X, U, ca.DM(p)))
    xi_rate = fx["xi_rate"](Xd, Xi) if nxi else ca.SX(0, 1)
    if ctrl.integral == "passive":  # the law's own passive-output integrator (same as xi_rate)
        pass
    ode = ca.vertcat(xdot / ca.DM(s), xi_rate / ca.DM(s_xi)) if nxi else xdot / ca.DM(s)
    quad = ca.dot(fx["v"](Xd), xdot[idx]) if ctrl.phi_implicit else ca.SX(0, 1)
    dae = {"x": Z, "ode": ode}
    if ctrl.phi_implicit:
        dae["quad"] = quad
    opts = {"abstol": atol if atol is not None else rtol / 100, "reltol": rtol, "max_num_steps": max_steps,
            "disable_internal_warnings": True, "quad_err_con": True}
    F = ca.integrator("closed_loop", "cvodes", dae, float(t[0]), list(t[1:]), opts)
    z0 = np.concatenate([xs / s, xi_start / s_xi])
    try:
        out = F(x0=z0)
    except RuntimeError as exc:
        k, zk = _reached(F, z0, len(t) - 1)  # the last output time the integrator got to, and the state there
        raise SimulationError(describe(exc, plant, t0=float(t[k]), t1=float(t[k + 1]), x=zk[:n] * s, p=p, max_steps=max_steps,
                                       subject=f"closed-loop simulation of {plant.name!r} under {ctrl.name!r}")) from None
    Zs = np.hstack([z0[:, None], np.asarray(out["xf"], dtype=float)]).T
    if not np.all(np.isfinite(Zs)):
        k = int(np.argmax(~np.all(np.isfinite(Zs), axis=1)))
        raise SimulationError(f"closed-loop simulation of {plant.name!r}: the state became non-finite at t={t[k]:.6g}")
    Xt, XIt = Zs[:, :n] * s, Zs[:, n:] * s_xi
    Q = np.concatenate([[0.0], np.asarray(out["qf"], dtype=float).reshape(-1)]) if ctrl.phi_implicit else np.zeros(len(t))
    Xd_t = Xt[:, idx]
    nt = len(t)
    ufun = ca.Function("u_plant", [Z], [U]).map(nt)
    Ut = np.asarray(ufun(Zs.T), dtype=float).T.reshape(nt, m)
    gfun = fn.conditions.map(nt)
    if plant.conditions:
        G = np.asarray(gfun(Xt.T, Ut.T, np.repeat(p[:, None], nt, axis=1)), dtype=float).reshape(len(plant.conditions), nt)
        bad = (G < -1e-12) | ~np.isfinite(G)
        if bad.any():
            k = int(np.argmax(bad.any(axis=0)))
            c = plant.conditions[int(np.argmax(bad[:, k]))]
            raise DomainError(f"closed-loop simulation of {plant.name!r} left the validity domain at t={t[k]:.6g}: "
                              f"{c.label}; state: " + ", ".join(f"{nm}={v:.6g}" for nm, v in zip(plant.state_names, Xt[k])))
    meas = (np.asarray(fn.measured.map(nt)(Xt.T, Ut.T, np.repeat(p[:, None], nt, axis=1)), dtype=float).T
            .reshape(nt, len(plant.measured))) if plant.measured else np.zeros((nt, 0))
    Hd_exp = np.asarray(fx["Hd"].map(nt)(Xd_t.T), dtype=float).reshape(-1) - float(fx["Hd"](ctrl.x_star))
    phi0, on_leaf = 0.0, True
    if ctrl.phi_implicit:
        lf = ctrl.leaf
        try:
            xl, phi0 = lf.transport(ctrl.x_star, Xd_t[0][lf.free],
                                    covector=fx["v"])
            on_leaf = bool(np.all(np.abs(xl[lf.dep] - Xd_t[0][lf.dep]) <= 1e-7 * ctrl.num.scale[lf.dep]))
        except Exception:  # noqa: BLE001 - a state off the leaf: H_d is then known up to a constant
            on_leaf = False
    H_d = Hd_exp + phi0 + Q
    H_cl = H_d.copy()
    if ctrl.integral == "passive":
        H_cl = H_d + 0.5 * np.einsum("ti,ij,tj->t", XIt, ctrl.K_i, XIt)
    info = {"on_leaf": on_leaf, "input_ranges": {}, "rtol": rtol}
    for nm, r in zip(ctrl.input_names, ranges):
        if r is not None:
            col = Ut[:, plant.input_names.index(nm)]
            info["input_ranges"][nm] = {"min": float(col.min()), "max": float(col.max()), "range": list(r),
                                        "exceeded": bool(col.min() < r[0] - 1e-9 * abs(r[0]) or col.max() > r[1] + 1e-9 * abs(r[1]))}
    return ClosedLoopResult(ctrl, plant, t, Xt, XIt, Ut, meas, H_d, H_cl, p, info)


def _reached(F, z0, n: int) -> tuple[int, np.ndarray]:
    """``(k, z)``: the index of the last output time (0: the start) an integrator ``F`` over ``n`` output
    times reaches from ``z0`` before it fails, and the state there (its outputs land in numpy as reached)."""
    zs = np.full((n, len(z0)), np.nan)
    buf, trigger = F.buffer()
    z0 = np.ascontiguousarray(z0, dtype=float)
    buf.set_arg(0, memoryview(z0))
    buf.set_res(0, memoryview(zs))
    try:
        trigger()
    except RuntimeError:
        pass
    ok = np.all(np.isfinite(zs), axis=1)
    k = int(np.argmin(ok)) if not ok.all() else n - 1  # the first output time not reached
    return k, (zs[k - 1] if k > 0 else z0)
