"""Stiff simulation of PHSystems with SUNDIALS CVODES through CasADi.

Design
------
* The model's generated functions are integrated in scaled states
  ``z = x / s`` (``s`` from the states' declared ranges or scales), so a single
  tolerance serves charges of 1e-7 C and angles of 1 rad.
* Inputs are piecewise-smooth signals (:mod:`phs.signals`).  The integrator is
  restarted at every breakpoint (square-wave edges, staircase steps): CVODES
  would otherwise step blindly over the discontinuity.  Between breakpoints an
  input is a sympy expression of time whose numbers become integrator
  parameters, so one integrator serves every segment of the same shape.
* Time is normalised per run (``t = a + h * tau``, outputs at integer ``tau``),
  so an integrator built once for ``n`` output steps serves every uniform run
  of ``n`` steps; integrators are cached per system.
* Energy accounts (supplied and dissipated energy, per resistive element) are
  quadratures integrated by the same CVODES run.
* A state leaving the validity domain, a non-finite value or an integrator
  failure raises an error naming the time and the state; nothing is silently
  truncated.
"""

from __future__ import annotations

import hashlib
import time as _time
from numbers import Real

import casadi as ca
import numpy as np
import sympy as sp

from codegen.functions import _model_hash, generate
from codegen.results import SimulationResult
from codegen.translate import Translator
from phs.errors import DomainError, InputDataError, SimulationError
from phs.params import TIME
from phs.signals import Piecewise, Sampled, Signal, as_signal


def simulate(system, t, u=None, x0=None, params=None, rtol: float = 1e-8, atol: float | None = None,
             method: str = "cvodes", compile: bool = False):
    """Simulate ``system`` on the time grid ``t``; see :class:`Simulator`.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> res = simulate(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0})
    >>> round(float(res["v_C"][-1]), 6)   # 1 - exp(-5) of a 1 ms time constant
    0.993262
    """
    if method == "discrete_gradient":
        from codegen.discrete_gradient import discrete_gradient_simulate

        return discrete_gradient_simulate(system, t, u=u, x0=x0, params=params)
    if method != "cvodes":
        raise InputDataError(f"unknown simulation method {method!r}; use 'cvodes' or 'discrete_gradient'")
    return simulator(system, rtol=rtol, atol=atol, compile=compile).run(t, u=u, x0=x0, params=params)


def simulator(system, rtol: float = 1e-8, atol: float | None = None, max_steps: int = 20000,
              compile: bool = False, energy: bool = True) -> Simulator:
    """Build a reusable :class:`Simulator` (integrators are cached across runs).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import mass_spring_damper
    >>> sim = simulator(mass_spring_damper(), rtol=1e-9)
    >>> res = sim.run(np.linspace(0, 1, 11), u={"F": 1.0})
    >>> res["position"].shape
    (11,)
    """
    return Simulator(system, rtol=rtol, atol=atol, max_steps=max_steps, compile=compile, energy=energy)


class Simulator:
    """CVODES simulator of one system with restarts at input breakpoints.

    Parameters
    ----------
    system : PHSystem
    rtol : float
        Relative tolerance.
    atol : float, optional
        Absolute tolerance on the scaled states ``x / s`` (default ``rtol / 100``),
        i.e. in units of each state's typical magnitude ``s``.
    max_steps : int
        Maximum number of internal steps per output interval.
    compile : bool
        Compile the model's dynamics to C (cached on disk by a hash of the model,
        see :mod:`codegen.compile`) instead of evaluating CasADi's SX virtual machine.
    energy : bool
        Integrate the energy accounts (supplied, dissipated in total and per element) as
        quadratures of the same run (default); False skips them.
    integrator_options : dict, optional
        Extra CVODES options passed to CasADi (e.g. ``{"second_order_correction": False}``).
    compiler : callable, optional
        ``compiler(fun, key) -> casadi.Function`` used instead of :func:`codegen.compile.compiled`
        when ``compile`` is true (e.g. to put derivatives of the dynamics in the same library).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> sim = Simulator(rc_circuit(), rtol=1e-9)
    >>> res = sim.run(np.linspace(0, 1e-3, 11), u={"U": 1.0})
    >>> round(float(res["v_C"][-1]), 6)   # 1 - exp(-1)
    0.632121
    """

    def __init__(self, system, rtol=1e-8, atol=None, max_steps=20000, compile=False, energy=True,
                 integrator_options=None, compiler=None):
        self.system = system
        self.f = generate(system)
        if not (0 < rtol < 1) or (atol is not None and not atol > 0):
            raise InputDataError(f"tolerances must be positive (rtol in (0, 1)); got rtol={rtol}, atol={atol}")
        self.rtol = float(rtol)
        self.atol = float(atol) if atol is not None else self.rtol / 100
        self.max_steps = int(max_steps)
        self.compile = bool(compile)
        self.energy = bool(energy)
        self.integrator_options = dict(integrator_options or {})
        self.compiler = compiler
        self.scale = np.array([s.typical for s in system.states], dtype=float)
        self._integrators: dict = {}
        self._templates: dict = {}
        self._cond_maps: dict = {}

    # -- inputs ------------------------------------------------------------------------
    def _signals(self, u, t) -> list[Signal]:
        s = self.system
        names = s.input_names
        if u is None:
            u = {}
        if not isinstance(u, dict):
            if len(names) != 1:
                raise InputDataError(f"system {s.name!r} has inputs {names}; give u as a dict by name")
            u = {names[0]: u}
        unknown = [k for k in u if k not in names]
        if unknown:
            raise InputDataError(f"system {s.name!r} has no input {', '.join(map(repr, unknown))}; inputs: {names}")
        out = []
        for name in names:
            spec = u.get(name, 0.0)
            if isinstance(spec, (np.ndarray, list, tuple)):
                arr = np.asarray(spec, dtype=float)
                if arr.shape != t.shape:
                    raise InputDataError(f"input {name!r}: array of shape {arr.shape} does not match the time grid {t.shape}")
                spec = Sampled(tuple(t), tuple(arr))
            elif callable(spec) and not isinstance(spec, Signal):
                try:
                    e = sp.sympify(spec(TIME))
                    spec = as_signal(e)
                except Exception:  # a numpy-only callable: sample it on the grid
                    spec = Sampled(tuple(t), tuple(np.asarray(spec(t), dtype=float)))
            if isinstance(spec, Sampled) and spec.hold == "zoh":  # held samples jump: restart at each change
                vals = np.asarray(spec.values, dtype=float)
                tt = np.asarray(spec.times, dtype=float)
                spec = Piecewise(tuple(tt[1:]), tuple(vals[1:]), float(vals[0])) if len(tt) > 1 else float(vals[0])
            try:
                out.append(as_signal(spec))
            except InputDataError as exc:
                raise InputDataError(f"input {name!r}: {exc}") from None
        return out

    # -- integrator construction ------------------------------------------------------------
    def _template(self, expr: sp.Expr):
        """Replace numbers of an input expression by placeholders: (key, template, values)."""
        floats = sorted(expr.atoms(sp.Float), key=lambda f: sp.default_sort_key(f))
        if expr.is_Float:
            floats = [expr]
        ph = [sp.Symbol(f"_c{k}", real=True) for k in range(len(floats))]
        tmpl = expr.xreplace(dict(zip(floats, ph))) if not expr.is_Float else ph[0]
        key = sp.srepr(tmpl)
        return key, tmpl, [float(f) for f in floats]

    def _plan(self, sigs, t):
        """Segments between breakpoints with per-input (template index, constants)."""
        t0, t1 = float(t[0]), float(t[-1])
        bps = sorted({float(b) for s in sigs if not isinstance(s, Sampled) for b in s.breakpoints(t0, t1)})
        edges = [t0] + [b for b in bps if t0 < b < t1] + [t1]
        slots: list[list] = [[] for _ in sigs]  # per input: list of (key, template, n_constants)
        segs = []
        for a, b in zip(edges[:-1], edges[1:]):
            if b <= a:
                continue
            choice = []
            for j, s in enumerate(sigs):
                if isinstance(s, Sampled):
                    choice.append(None)
                    continue
                key, tmpl, vals = self._template(sp.sympify(s.expr_on(a, b)))
                keys = [k for k, _, _ in slots[j]]
                if key not in keys:
                    slots[j].append((key, tmpl, len(vals)))
                    keys.append(key)
                choice.append((keys.index(key), vals))
            segs.append((a, b, choice))
        return segs, slots

    def _integrator(self, n: int, slots, sampled, max_step: float = 1.0):
        """CVODES integrator over ``n`` output steps for the given input templates and sampled inputs.

        ``sampled[j]`` is ``(times, values)`` for an input given by samples (baked into a linear
        interpolant: evaluation costs O(log n), not O(n)), else None.  With a sampled input the step
        is bounded by ``max_step`` output intervals (see :func:`step_windows`).
        """
        key = (n, float(max_step), tuple(tuple(k for k, _, _ in sl) for sl in slots),
               tuple(hashlib.sha1(np.ascontiguousarray(g[0]).tobytes() + np.ascontiguousarray(g[1]).tobytes()).hexdigest()
                     if g is not None else None for g in sampled))
        hit = self._integrators.get(key)
        if hit is not None:
            return hit
        sx = self.f.sx
        nx, nu, npar = len(self.system.states), len(self.system.inputs), len(self.system.params)
        z = ca.SX.sym("z", nx)
        tau = ca.SX.sym("tau")
        pp = ca.SX.sym("p", npar)
        a = ca.SX.sym("a")
        h = ca.SX.sym("h")
        tt = a + h * tau
        extra, uexpr = [], []
        layout = []
        for j in range(nu):
            if sampled[j] is not None:
                grid, values = sampled[j]
                # in a smooth window a cubic spline through the same samples: without a kink at every
                # sample CVODES steps across samples (5-15 times fewer steps on sines sampled at 1 kHz)
                kind = "bspline" if max_step > 1 and len(grid) >= 8 else "linear"
                interp = ca.interpolant(f"u{j}", kind, [np.asarray(grid, dtype=float)], np.asarray(values, dtype=float))
                uexpr.append(interp(tt))
                layout.append(("sampled", 0))
                continue
            terms = []
            lay = []
            for k, (_key, tmpl, nc) in enumerate(slots[j]):
                w = ca.SX.sym(f"w{j}_{k}")
                cs = ca.SX.sym(f"c{j}_{k}", nc)
                tr = Translator({TIME: tt, **{sp.Symbol(f"_c{i}", real=True): cs[i] for i in range(nc)}})
                terms.append(w * tr(tmpl))
                extra += [w, cs]
                lay.append(nc)
            uexpr.append(sum(terms) if terms else ca.SX(0))
            layout.append(("slots", lay))
        uu = ca.vertcat(*uexpr) if nu else ca.SX(0, 1)
        x = z * self.scale
        subs_in = [sx["x"], sx["u"], sx["p"]]
        xdot, supplied, dissipated, dparts = ca.substitute(
            [sx["xdot"], sx["supplied"], sx["dissipated"], sx["dissipators"]], subs_in, [x, uu, pp]
        )
        ode = h * xdot / self.scale
        quad = h * ca.vertcat(supplied, dissipated, dparts) if self.energy else ca.SX(0, 1)
        P = ca.vertcat(pp, a, h, *extra)
        empty = ca.SX(0, 1)
        dae = ca.Function(f"{self.f.rhs.name()}_dae", [tau, z, empty, P, empty], [ode, empty, quad, empty],
                          ca.dyn_in(), ca.dyn_out())
        if self.compile:
            from codegen.compile import compiled

            dae = (self.compiler or compiled)(dae, f"{_model_hash(self.system)}|{key[2:]}|{self.scale.tolist()}")
        opts = {"abstol": self.atol, "reltol": self.rtol, "max_num_steps": self.max_steps, "quad_err_con": False,
                "disable_internal_warnings": True, "show_eval_warnings": False}  # failures are reported as PHS errors instead
        if any(g is not None for g in sampled):
            # a sampled input may change after a long constant stretch: never step over a feature of it
            opts["max_step_size"] = float(max_step)
        opts.update(self.integrator_options)
        F = ca.integrator(f"{self.f.rhs.name()}_cvodes{n}", "cvodes", dae, 0.0, np.arange(1.0, n + 1.0), opts)
        self._integrators[key] = (F, layout)
        return F, layout

    # -- running ------------------------------------------------------------------------------
    def run(self, t, u=None, x0=None, params=None) -> SimulationResult:
        """Integrate on the grid ``t`` and return a :class:`SimulationResult`.

        Parameters
        ----------
        t : array
            Strictly increasing output times (the first is the initial time).
        u : dict, Signal, number, str, array or callable
            Inputs by name (a bare value when the system has one input):
            numbers, :mod:`phs.signals` signals, expressions of ``t`` as
            strings or sympy, arrays on the grid (interpolated linearly, or by a cubic
            spline where they are smooth: :func:`step_windows`), or
            callables of ``t``.  Missing inputs are zero.
        x0 : dict or array, optional
            Initial state (default: zero, clipped into each state's range).
        params : dict, optional
            Parameter overrides by name.

        Raises
        ------
        DomainError
            When the state leaves the model's validity domain (time, state and condition named).
        SimulationError
            When the integrator fails or the solution becomes non-finite.
        """
        s = self.system
        wall = _time.perf_counter()
        t = np.asarray(t, dtype=float)
        if t.ndim != 1 or len(t) < 2:
            raise InputDataError("time grid must be a 1-D array with at least 2 points")
        if not np.all(np.isfinite(t)):
            raise InputDataError(f"time grid has a non-finite value at index {int(np.argmin(np.isfinite(t)))}")
        d = np.diff(t)
        if np.any(d <= 0):
            i = int(np.argmax(d <= 0)) + 1
            raise InputDataError(f"time grid is not strictly increasing at index {i} (t={t[i]})")
        p = s.param_vector(params)
        x = self.initial_state(x0)
        self._check_domain(x[None, :], t[:1], p, np.zeros((1, len(s.inputs))))
        sigs = self._signals(u, t)
        segs, slots = self._plan(sigs, t)
        sampled = [(np.asarray(sg.times), np.asarray(sg.values)) if isinstance(sg, Sampled) else None for sg in sigs]
        nq = 2 + len(s.dissipators) if self.energy else 0
        X = np.empty((len(t), len(x)))
        Q = np.zeros((len(t), nq))
        X[0] = x
        U = np.zeros((len(t), len(s.inputs)))
        if segs:
            U[0] = self._eval_inputs(sigs, slots, segs[0][2], t[:1])[0]
        z = x / self.scale
        qacc = np.zeros(nq)
        nrun = 0
        if len(x) == 0:  # a static network: nothing to integrate, outputs follow the inputs
            return self._static_result(t, sigs, segs, slots, p, wall)
        for a, b, choice in segs:
            # inputs are right-continuous: a grid point on a breakpoint sees the new segment's input
            ja = int(np.searchsorted(t, a - 1e-12 * max(1.0, abs(a))))
            if ja < len(t) and abs(t[ja] - a) <= 1e-9 * max(1.0, abs(a)):
                U[ja] = self._eval_inputs(sigs, slots, choice, np.array([a]))[0]
            i0 = int(np.searchsorted(t, a, side="left"))
            i1 = int(np.searchsorted(t, b, side="left"))
            # output indices strictly inside (a, b], plus b itself if it is a grid point
            idx_in = [i for i in range(i0, min(i1 + 1, len(t))) if a < t[i] <= b + 1e-12 * max(1.0, abs(b))]
            pts = [a] + [float(t[i]) for i in idx_in]
            if pts[-1] < b - 1e-12 * max(1.0, abs(b)):
                pts.append(b)
            for ra, rh, rn, ms in _bounded(_runs(pts), sigs):
                F, layout = self._integrator(rn, slots, sampled, ms)
                P = self._pvec(p, ra, rh, layout, choice)
                try:
                    zs, qs = _call_into_numpy(F, z, P, len(x), rn, nq)
                except RuntimeError as exc:
                    self._localize_failure(F, z, p, ra, rh, rn, slots, sampled, layout, choice, exc, sigs)
                times = ra + rh * np.arange(1, rn + 1)
                xs = zs * self.scale
                if not np.all(np.isfinite(xs)):
                    k = int(np.argmin(np.all(np.isfinite(xs), axis=1)))
                    raise SimulationError(f"simulation of {s.name!r}: non-finite state at t={times[k]:.6g}: " + _fmt_state(s, xs[k]))
                uu = self._eval_inputs(sigs, slots, choice, times)
                self._check_domain(xs, times, p, uu)
                j = np.minimum(np.searchsorted(t, times - 1e-12 * np.maximum(1.0, np.abs(times))), len(t) - 1)
                on_grid = np.abs(t[j] - times) <= 1e-9 * np.maximum(np.maximum(1.0, np.abs(times)), rh)
                X[j[on_grid]] = xs[on_grid]
                Q[j[on_grid]] = qacc + qs[on_grid]
                keep = on_grid & (np.abs(times - b) > 1e-12 * max(1.0, abs(b)))  # b belongs to the next segment
                U[j[keep]] = uu[keep]
                if abs(times[-1] - b) <= 1e-12 * max(1.0, abs(b)) and b >= t[-1] - 1e-12 * max(1.0, abs(b)):
                    U[j[-1]] = uu[-1]  # the final time has no next segment
                qacc = qacc + qs[-1]
                z = zs[-1]
                nrun += 1
        res = SimulationResult(s, t, X, U, p, stats={"runs": nrun, "seconds": _time.perf_counter() - wall,
                                                     "method": "cvodes", "rtol": self.rtol, "atol": self.atol})
        if self.energy:
            res.quadratures = {"E_supplied": Q[:, 0], "E_dissipated": Q[:, 1]}
            for k, (label, _) in enumerate(s.dissipators):
                res.quadratures[f"E_dissipated[{label}]"] = Q[:, 2 + k]
        return res

    def _static_result(self, t, sigs, segs, slots, p, wall) -> SimulationResult:
        U = np.zeros((len(t), len(sigs)))
        for a, b, choice in segs:
            sel = (t >= a) & ((t < b) | (b >= t[-1]))
            U[sel] = self._eval_inputs(sigs, slots, choice, t[sel])
        res = SimulationResult(self.system, t, np.zeros((len(t), 0)), U, p,
                               stats={"runs": 0, "seconds": _time.perf_counter() - wall, "method": "static"})

        def cumtrapz(v):
            return np.concatenate([[0.0], np.cumsum(np.diff(t) * (v[1:] + v[:-1]) / 2)])

        res.quadratures = {"E_supplied": cumtrapz(res.supplied), "E_dissipated": cumtrapz(res.dissipated)}
        for label, power in res.dissipator_powers.items():
            res.quadratures[f"E_dissipated[{label}]"] = cumtrapz(power)
        return res

    def initial_state(self, x0) -> np.ndarray:
        """Initial state vector from a dict/array (default zero clipped into the ranges)."""
        s = self.system
        base = np.array([min(max(0.0, st.range[0]), st.range[1]) for st in s.states])
        if x0 is None:
            return base
        if isinstance(x0, dict):
            unknown = [k for k in x0 if k not in s.state_names]
            if unknown:
                raise InputDataError(f"x0: system {s.name!r} has no state {', '.join(map(repr, unknown))}")
            for k, v in x0.items():
                if not isinstance(v, Real) or not np.isfinite(v):
                    raise InputDataError(f"x0: value {v!r} of state {k!r} is not a finite number")
                base[s.state_names.index(k)] = float(v)
            return base
        arr = np.asarray(x0, dtype=float).reshape(-1)
        if arr.shape != base.shape:
            raise InputDataError(f"x0 has {arr.size} values but {s.name!r} has {base.size} states")
        if not np.all(np.isfinite(arr)):
            raise InputDataError(f"x0 has a non-finite value for state {s.state_names[int(np.argmin(np.isfinite(arr)))]!r}")
        return arr.copy()

    def _pvec(self, p, a, h, layout, choice):
        parts = [p, [a, h]]
        for j, lay in enumerate(layout):
            if lay[0] == "sampled":  # baked into the integrator
                continue
            active, vals = choice[j]
            for k, nc in enumerate(lay[1]):
                parts.append([1.0 if k == active else 0.0])
                parts.append(vals if k == active else [0.0] * nc)
        return np.concatenate([np.asarray(v, dtype=float).reshape(-1) for v in parts])

    def _eval_inputs(self, sigs, slots, choice, times) -> np.ndarray:
        """Inputs at ``times`` inside one segment, from the segment's templates and constants."""
        out = np.empty((len(times), len(sigs)))
        for j, sg in enumerate(sigs):
            if isinstance(sg, Sampled):
                out[:, j] = sg(times)
                continue
            k, vals = choice[j]
            key, tmpl, nc = slots[j][k]
            f = self._templates.get(key)
            if f is None:
                f = sp.lambdify([TIME] + [sp.Symbol(f"_c{i}", real=True) for i in range(nc)], tmpl, "numpy")
                self._templates[key] = f
            out[:, j] = np.broadcast_to(np.asarray(f(times, *vals), dtype=float), times.shape)
        return out

    def _inputs_at(self, sigs, times) -> np.ndarray:
        if not sigs:
            return np.zeros((len(times), 0))
        return np.column_stack([np.broadcast_to(np.asarray(sg(times), dtype=float), times.shape) for sg in sigs])

    def _check_domain(self, xs, times, p, uu) -> None:
        s = self.system
        if not s.conditions:
            return
        n = len(times)
        fm = self._cond_maps.get(n)
        if fm is None:
            fm = self._cond_maps[n] = self.f.conditions.map(n)
        buf, trigger = fm.buffer()
        X = np.ascontiguousarray(xs, dtype=float)  # (n, nx) C-order = (nx, n) column-major
        Uu = np.ascontiguousarray(uu, dtype=float)
        Pp = np.ascontiguousarray(np.broadcast_to(p, (n, len(p))), dtype=float)
        gT = np.empty((n, len(s.conditions)))
        buf.set_arg(0, memoryview(X))
        buf.set_arg(1, memoryview(Uu))
        buf.set_arg(2, memoryview(Pp))
        buf.set_res(0, memoryview(gT))
        trigger()
        g = gT.T
        bad = (g < -1e-12) | ~np.isfinite(g)
        if np.any(bad):
            k = int(np.argmax(np.any(bad, axis=0)))
            c = s.conditions[int(np.argmax(bad[:, k]))]
            raise DomainError(
                f"simulation of {s.name!r} left the validity domain at t={times[k]:.6g}: {c.label}"
                + (f" ({c.description})" if c.description else "") + f", value {g[:, k][int(np.argmax(bad[:, k]))]:.4g}; "
                + "state: " + _fmt_state(s, xs[k])
            )

    def _check_predicted_domain(self, x, tk, h, p, uk) -> None:
        """The integrator failed in [tk, tk + h] from a state inside the domain: when the predicted
        trajectory crosses a validity condition (an arcsin argument passing 1 makes the right-hand
        side NaN and CVODES give up), report that as the domain error it is."""
        s = self.system
        if not s.conditions:
            return
        for frac, xp in _predicted_states(self.f.rhs, x, uk[0], p, h):
            g = np.asarray(self.f.conditions(xp, uk[0], p), dtype=float).reshape(-1)
            bad = (g < -1e-12) | ~np.isfinite(g)
            if np.any(bad):
                c = s.conditions[int(np.argmax(bad))]
                raise DomainError(
                    f"simulation of {s.name!r} left the validity domain between t={tk:.6g} and "
                    f"t={tk + frac * h:.6g}: {c.label}" + (f" ({c.description})" if c.description else "")
                    + "; last state inside: " + _fmt_state(s, x)
                )

    def _localize_failure(self, F, z, p, a, h, n, slots, sampled, layout, choice, exc, sigs):
        """Re-run the failed run one output step at a time to name the failing interval and state."""
        s = self.system
        F1, _ = self._integrator(1, slots, sampled)
        zc = z
        for k in range(n):
            P = self._pvec(p, a + k * h, h, layout, choice)
            try:
                zc = np.asarray(F1(x0=zc, p=P)["xf"]).reshape(-1)
            except RuntimeError:
                xs = zc * self.scale
                tk = a + k * h
                uk = self._eval_inputs(sigs, slots, choice, np.array([tk]))
                self._check_domain(xs[None, :], np.array([tk]), p, uk)
                self._check_predicted_domain(xs, tk, h, p, uk)
                raise SimulationError(
                    f"simulation of {s.name!r}: the integrator failed between t={tk:.6g} and t={tk + h:.6g}; "
                    f"state at t={tk:.6g}: " + _fmt_state(s, xs) + f" ({str(exc).splitlines()[-1][:200]})"
                ) from None
            if not np.all(np.isfinite(zc)):
                break
        raise SimulationError(f"simulation of {s.name!r}: the integrator failed in [{a:.6g}, {a + n * h:.6g}] "
                              f"({str(exc).splitlines()[-1][:200]})") from None


def _predicted_states(f_rhs, x, u, p, h):
    """Explicit-Euler predictions of the state over a failed step (fractions 1/8 .. 1 of it)."""
    xdot = np.asarray(f_rhs(x, u, p), dtype=float).reshape(-1)
    return [(frac, x + frac * h * xdot) for frac in (0.125, 0.25, 0.5, 1.0)]


def _call_into_numpy(F, z0, P, nx: int, n: int, nq: int):
    """Call an integrator writing its outputs straight into numpy arrays (no DM -> numpy copy).

    CasADi stores the (nx, n) output column-major, which is the memory layout of a
    C-ordered (n, nx) array: the rows are the states at each output time.
    """
    buf, trigger = F.buffer()
    z0 = np.ascontiguousarray(z0, dtype=float)
    P = np.ascontiguousarray(P, dtype=float)
    zs = np.empty((n, nx))
    qs = np.empty((n, nq))
    buf.set_arg(0, memoryview(z0))
    buf.set_arg(2, memoryview(P))
    buf.set_res(0, memoryview(zs))
    buf.set_res(2, memoryview(qs))
    trigger()
    return zs, qs


STEP_WINDOW = 200  # output intervals per window of a sampled input with its own step bound
_STEP_FACTORS = (64, 32, 16, 8, 4, 2)
_STEP_REL_TOL = 0.01  # of the input's range: a window's input must be this close to linear between step ends


def step_windows(values, window: int = STEP_WINDOW) -> list[tuple[int, int, int]]:
    """Windows of a uniformly sampled input and the longest integration step each allows.

    ``values`` (n,) or (n, k): inputs at n equally spaced points.  Returns ``(i0, i1, m)``: points
    ``i0..i1`` (at most ``window`` intervals) and ``m``, the largest of 64, 32, ..., 2, 1 intervals such
    that every input, linearly interpolated through every m-th point of the window, reproduces all
    its points to within 1 % of its range over the record; ``m`` is 1 where an input is not smooth to
    third order (its third differences exceed half its largest second difference: kinks of a
    piecewise-linear table, steps, noise) and where a neighbouring window's ``m`` is 1.
    A BDF step only evaluates the dynamics at its ends, so a step must not cross a feature of the
    input; steps of ``m`` intervals cross none (to 1 %).  In windows with ``m > 1`` the simulator
    interpolates the samples by a cubic spline instead of linearly: the linear interpolant's kink at
    every sample would otherwise hold CVODES to about a step per sample.  Smooth, finely sampled
    inputs (sines, chirps, slow ramps at 1 kHz) get long steps; an input that changes character at
    every sample (noise, multisines near the Nyquist frequency, a zero-order hold) keeps one interval
    and its linear interpolation.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 1001)
    >>> [w[2] for w in step_windows(np.sin(2 * np.pi * 5 * t))]   # 5 Hz at 1 kHz: steps of 8 samples
    [8, 8, 8, 8, 8]
    >>> {w[2] for w in step_windows(np.random.default_rng(0).normal(size=1001))}
    {1}
    """
    V = np.asarray(values, dtype=float)
    V = V.reshape(len(V), -1)
    n = len(V)
    tol = _STEP_REL_TOL * np.maximum(np.ptp(V, axis=0), 1e-300) if n else np.zeros(V.shape[1])
    out = []
    for i0 in range(0, max(n - 1, 0), window):
        i1 = min(i0 + window, n - 1)
        w = V[i0: i1 + 1]
        k = np.arange(len(w))
        best = 1
        # smooth to third order: the second differences vary slowly (a sampled sine or chirp), not in
        # spikes (the kinks of a piecewise-linear waveform table, a step, noise); a channel that
        # follows the input's derivative (a capacitor's current) must see the kinks where they are
        d2, d3 = np.abs(np.diff(w, 2, axis=0)), np.abs(np.diff(w, 3, axis=0))
        if len(w) < 8 or not np.all(d3.max(axis=0, initial=0.0) <= 0.5 * d2.max(axis=0, initial=0.0) + 1e-12 * tol):
            out.append((i0, i1, 1))
            continue
        for m in _STEP_FACTORS:
            if m >= len(w):
                continue
            idx = np.unique(np.append(np.arange(0, len(w), m), len(w) - 1))
            err = max((np.max(np.abs(w[:, j] - np.interp(k, idx, w[idx, j]))) / tol[j] for j in range(w.shape[1])), default=0.0)
            if err <= 1.0:
                best = m
                break
        out.append((i0, i1, best))
    # a spline through a rough window rings into its neighbours for a few samples: a smooth window
    # next to a rough one keeps one interval (and the linear interpolant)
    rough = [m == 1 for _, _, m in out]
    return [(a, b, 1 if (k > 0 and rough[k - 1]) or (k + 1 < len(out) and rough[k + 1]) else m)
            for k, (a, b, m) in enumerate(out)]


def _bounded(runs, sigs):
    """Runs ``(start, step, n)`` cut into windows with their step bound ``(start, step, n, max_step)``
    when inputs are sampled (:func:`step_windows`); one window bounded by one interval when a sampled
    input is finer than the output grid, and unbounded runs (``max_step`` 1, unused) without samples."""
    samp = [sg for sg in sigs if isinstance(sg, Sampled)]
    for ra, rh, rn in runs:
        if not samp or any(float(np.min(np.diff(sg.times))) < rh * (1 - 1e-9) for sg in samp):
            yield ra, rh, rn, 1.0
            continue
        tt = ra + rh * np.arange(rn + 1)
        for i0, i1, m in step_windows(np.column_stack([np.asarray(sg(tt), dtype=float) for sg in samp])):
            yield ra + i0 * rh, rh, i1 - i0, float(m)


def _runs(pts):
    """Split output points into runs of equal spacing: (start, step, n_steps)."""
    out = []
    i = 0
    m = len(pts)
    while i < m - 1:
        h = pts[i + 1] - pts[i]
        j = i + 1
        while j < m - 1 and abs((pts[j + 1] - pts[j]) - h) <= 1e-9 * max(h, 1e-300) + 1e-12 * abs(pts[j]):
            j += 1
        n = j - i
        h = (pts[j] - pts[i]) / n
        out.append((pts[i], h, n))
        i = j
    return out


def _fmt_state(system, x) -> str:
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(system.state_names, x))
