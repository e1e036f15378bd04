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

from codegen._solver_errors import CODES, describe, failure_code
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
    :meth:`to_pandas` gives a DataFrame indexed by time.  ``info["loaded"]`` names the states a load moved
    from their declared rest at the start (``""`` otherwise; see :func:`start_state`).

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


def start_state(ctrl, plant=None, x0=None, params: dict | None = None) -> tuple[np.ndarray, str]:
    """The plant state a closed-loop run starts from, and the states a load moved, in words (else ``""``).

    Without ``x0``: each plant state at its declared rest (``StateInfo.initial``, the default of the open-loop
    :func:`codegen.simulate`), the controller's states at the design's ``x0`` (the same unless one was given to
    :func:`codegen.idapbc.design`).  When that state is not at rest under the inputs held constant (the
    uncontrolled inputs at their fixed values, the controlled ones at 0 moved into their ranges), e.g. a model
    under a weight or a preload, the run starts at the equilibrium the plant settles at under them, on the leaf
    of its conserved quantities: Newton's method on the generated functions when it finds a stable
    equilibrium, else :func:`phs.equilibrium`; when neither finds one the declared rest is kept.  A dict
    ``x0`` replaces those values for the states it names; an array gives every state.  ``phs control
    --t-end`` starts from the same state.

    Parameters
    ----------
    ctrl : Controller
    plant : PHSystem, optional
        Default: the controller's model.
    x0 : dict or array, optional
    params : dict, optional
        Plant parameter overrides.

    Returns
    -------
    x : numpy array
        One value per plant state.
    loaded : str
        ``"name=value, ..."`` of the states where the load holds them, or ``""``.

    Raises
    ------
    InputDataError
        For an ``x0`` naming no plant state, a value that is not a finite number, or an array of the wrong length.

    Examples
    --------
    >>> from codegen.idapbc import design
    >>> from components import Damper, ForceSource, LinearSpring, Mass
    >>> from phs import interconnect, series
    >>> plant = interconnect("msd", [ForceSource("F"), Mass("m", m=1.0), LinearSpring("k", K=4.0, L0=0.3),
    ...                              Damper("b", b=0.4)], [series("F", "m", "k", "b")])
    >>> ctrl = design(plant, {"k.l": 0.5})
    >>> start_state(ctrl)[0].tolist(), start_state(ctrl, x0={"m.p": 0.1})[0].tolist()
    ([0.0, 0.3], [0.1, 0.3])
    >>> start_state(ctrl, x0={"k.l": float("nan")})
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: x0: value nan of state 'k.l' is not a finite number
    """
    plant, p, idx = _plant_setup(ctrl, plant, params)
    return _start(ctrl, plant, p, idx, x0)


def _start(ctrl, plant, p, idx, x0) -> tuple[np.ndarray, str]:
    if x0 is not None and not isinstance(x0, dict):
        return state_vector(plant, x0), ""
    given = dict(x0 or {})
    xg = state_vector(plant, given)  # checks the names and values
    xs = state_vector(plant, None)
    xs[idx] = ctrl.x0
    loaded = ""
    if len(given) < len(plant.states):
        rest = _rest(ctrl, plant, p, xs)
        if rest is not None:
            xs = rest
            loaded = ", ".join(f"{nm}={v:.4g}" for nm, v in zip(plant.state_names, xs) if nm not in given)
    for nm in given:
        k = plant.state_names.index(nm)
        xs[k] = xg[k]
    return xs, loaded


def _rest(ctrl, plant, p, xs) -> np.ndarray | None:
    """The equilibrium a loaded plant settles at from ``xs`` without control (None when ``xs`` is at rest or
    none is found); see :func:`start_state`."""
    from codegen.idapbc.leaf import Leaf
    from codegen.idapbc.model import Numeric
    from codegen.idapbc.target import _Solver
    from phs.equilibria import equilibrium
    from phs.errors import EquilibriumError

    fixed = {nm: float(ctrl.u_base[j]) for j, nm in enumerate(ctrl.system.input_names) if j not in ctrl.ctrl}
    u = np.array([(0.0 if info.range is None else min(max(0.0, info.range[0]), info.range[1]))
                  if info.name in ctrl.input_names else fixed.get(info.name, 0.0) for info in plant.inputs])
    typical = np.array([st.typical for st in plant.states])
    xdot = np.asarray(generate(plant).rhs(xs, u, p), dtype=float).reshape(-1)
    if np.all(np.isfinite(xdot)) and np.all(np.abs(xdot) <= 1e-9 * typical):  # at rest (rates over 1e-9 scales/s)
        return None
    rest = None
    try:
        num = Numeric(plant, dict(zip(plant.param_names, p)))
        leaf = Leaf(num.struct_function, num.scale, xs)
        sol = _Solver(num, leaf, [], [], u, [])
        xr = sol.newton(xs, np.zeros(0), None, with_targets=False)[0]
        A, _ = num.jac(xr, u)
        S = leaf.S(xr)
        AF = (A[:, leaf.free] + (A[:, leaf.dep] @ S if leaf.dep else 0.0))[leaf.free]
        if (not num.violated(xr, u)) and (AF.size == 0 or np.max(np.linalg.eigvals(AF).real) < 0):
            rest = xr
    except (EquilibriumError, np.linalg.LinAlgError, ArithmeticError):
        rest = None
    if rest is None:  # an unstable or no equilibrium near the declared rest: follow the dynamics (pseudo-transient)
        try:
            rest = equilibrium(plant, u=u, x0=xs, params=dict(zip(plant.param_names, p))).x
        except (EquilibriumError, ArithmeticError):
            return None
    rest = np.asarray(rest, dtype=float)
    if not (np.all(np.isfinite(rest)) and np.any(np.abs(rest - xs) > 1e-9 * typical)):
        return None
    return np.where(np.abs(rest) < 1e-12 * typical, 0.0, rest)  # rounding noise: 0


def simulate_closed_loop(ctrl, t, *, x0=None, plant=None, params: dict | None = None, xi0=None,
                         saturate: bool = False, rtol: float = 1e-9, atol: float | None = None,
                         max_steps: int = 200000, seconds: float | None = None) -> ClosedLoopResult:
    """Simulate ``plant`` (default: the controller's own model) under the controller on the grid ``t``.

    Parameters
    ----------
    ctrl : Controller
    t : array
        Increasing output times.
    x0 : dict or array, optional
        Plant initial state: ``{state: value}`` (the other states as by default) or one value per plant
        state.  Default (:func:`start_state`): the state the plant rests in before the controller acts, the
        same as ``phs control --t-end`` starts from: each state at its declared rest (the default of the
        open-loop :func:`codegen.simulate`), the controller's states at the design's ``x0``, and, when that
        state is not at rest under the inputs held constant (a weight, a preload), the equilibrium the plant
        settles at.
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
    max_steps : int
        CVODES's limit of internal steps per output interval.
    seconds : float, optional
        Limit of the integration in CPU seconds of this process (enforced in the main thread; elsewhere
        none): a run still integrating then stops with a :class:`~phs.errors.SimulationError` saying so.
        The certificates' runs use :data:`codegen.idapbc.certificates.RUN_SECONDS` and ``RUN_STEPS``.

    Returns
    -------
    ClosedLoopResult

    Raises
    ------
    InputDataError
        For an ``x0`` naming no plant state, a value that is not a finite number (the state named), an array
        of the wrong length, or a start outside the validity domain.
    DomainError
        When the plant leaves its validity domain (time, condition and state named).
    SimulationError
        When the integrator fails; its attribute ``out_of_budget`` is True when the run was stopped by
        ``max_steps`` or ``seconds`` (unfinished: its outcome unknown) rather than by the model.

    Examples
    --------
    A spring of rest length 0.3 m (its declared rest) stretched to 0.5 m; the run starts at rest, ``H_d`` never
    increases, and ``x0`` by name or as an array are the same start:

    >>> import numpy as np
    >>> from codegen.idapbc import design
    >>> from components import Damper, ForceSource, LinearSpring, Mass
    >>> from phs import interconnect, series
    >>> plant = interconnect("msd", [ForceSource("F"), Mass("m", m=1.0), LinearSpring("k", K=4.0, L0=0.3),
    ...                              Damper("b", b=0.4)], [series("F", "m", "k", "b")])
    >>> ctrl = design(plant, {"k.l": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
    >>> res = simulate_closed_loop(ctrl, np.linspace(0, 10, 201))
    >>> res.x[0].tolist(), round(float(res["k.l"][-1]), 4), res.max_increase("H_d") <= 1e-9
    ([0.0, 0.3], 0.5, True)
    >>> a = simulate_closed_loop(ctrl, [0, 1], x0={"k.l": 0.2})
    >>> b = simulate_closed_loop(ctrl, [0, 1], x0=[0.0, 0.2])
    >>> bool(np.array_equal(a.x, b.x))
    True
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputDataError("time grid must be a strictly increasing 1-D array of at least 2 finite values")
    plant, p, idx = _plant_setup(ctrl, plant, params)
    fx = ctrl._fx
    fn = generate(plant)
    sx = fn.sx
    n, m = len(plant.states), len(plant.inputs)
    xs, loaded = _start(ctrl, plant, p, idx, x0)
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
    if x0 is not None and plant.conditions:  # a start given outside the validity domain: said before any run
        u0 = np.asarray(ca.Function("u0", [Z], [U])(z0), dtype=float).reshape(-1)
        g0 = np.asarray(fn.conditions(xs, u0, p), dtype=float).reshape(-1)
        bad = [c.label for c, v in zip(plant.conditions, g0) if not (v >= -1e-12)]
        if bad:
            raise InputDataError(f"x0 is outside the validity domain of {plant.name!r}: {'; '.join(bad)}")
    try:
        out = _timed(lambda: F(x0=z0), seconds)
    except _OutOfTime:
        err = SimulationError(f"closed-loop simulation of {plant.name!r} under {ctrl.name!r} did not finish in "
                              f"{seconds:g} CPU seconds (t = {t[0]:g}..{t[-1]:g} s from "
                              + ", ".join(f"{nm}={v:.4g}" for nm, v in list(zip(plant.state_names, xs))[:4])
                              + (", ..." if n > 4 else "") + "): the closed loop is too fast or stiff there")
        err.out_of_budget = True  # the run was not finished, not refused: its outcome is unknown
        raise err from None
    except RuntimeError as exc:
        k, zk = _reached(F, z0, len(t) - 1)  # the last output time the integrator got to, and the state there
        err = SimulationError(describe(exc, plant, t0=float(t[k]), t1=float(t[k + 1]), x=zk[:n] * s, p=p, max_steps=max_steps,
                                       subject=f"closed-loop simulation of {plant.name!r} under {ctrl.name!r}"))
        err.out_of_budget = CODES.get(failure_code(str(exc))) == "work"  # its step limit, not a failure of the model
        raise err from None
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
    info = {"on_leaf": on_leaf, "input_ranges": {}, "rtol": rtol, "loaded": loaded}
    for nm, r in zip(ctrl.input_names, ranges):
        if r is not None:
            col = Ut[:, plant.input_names.index(nm)]
            info["input_ranges"][nm] = {"min": float(col.min()), "max": float(col.max()), "range": list(r),
                                        "exceeded": bool(col.min() < r[0] - 1e-9 * abs(r[0]) or col.max() > r[1] + 1e-9 * abs(r[1]))}
    return ClosedLoopResult(ctrl, plant, t, Xt, XIt, Ut, meas, H_d, H_cl, p, info)


class _OutOfTime(Exception):
    pass


def _timed(fn, seconds: float | None):
    """``fn()`` stopped after ``seconds`` of CPU time by SIGVTALRM (main thread only; elsewhere, or without
    ``seconds``, no limit).  CasADi turns the handler's exception into its own RuntimeError: a flag tells them
    apart, and :class:`_OutOfTime` is raised."""
    import signal
    import threading

    if seconds is None or threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        return fn()
    fired = []

    def handler(signum, frame):
        fired.append(True)
        raise _OutOfTime()

    old = signal.signal(signal.SIGVTALRM, handler)
    signal.setitimer(signal.ITIMER_VIRTUAL, max(float(seconds), 1e-3))
    try:
        return fn()
    except RuntimeError:
        if fired:
            raise _OutOfTime() from None
        raise
    finally:
        signal.setitimer(signal.ITIMER_VIRTUAL, 0)
        signal.signal(signal.SIGVTALRM, old)


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
