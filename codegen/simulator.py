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

What this simulator shares with :mod:`codegen.discrete_gradient` and
:mod:`codegen.batch` lives below all three: input signals and segments
(:mod:`codegen._inputs`), the time grid and the step windows of sampled inputs
(:mod:`codegen._grid`), the validity-domain check (:mod:`codegen._domain`) and
the collection of integrator outputs on the grid (:mod:`codegen._output`).
"""

from __future__ import annotations

import threading as _threading
import time as _time
from collections import OrderedDict

import casadi as ca
import numpy as np
import sympy as sp

from codegen._domain import DomainCheck, fmt_state, gated
from codegen._grid import step_windows, time_grid
from codegen._inputs import initial_state, input_signals, run_sampled, segment_inputs
from codegen._interpolants import _digest, _interpolant, interpolation
from codegen._layout import ParamLayout
from codegen._output import call_into_numpy, energy_accounts, energy_columns
from codegen._plan import plan_for
from codegen._solver_errors import describe
from codegen.discrete_gradient import discrete_gradient_simulate
from codegen.functions import _model_hash, generate
from codegen.results import SimulationResult
from codegen.translate import Translator
from phs.errors import InputDataError, SimulationError
from phs.params import TIME

__all__ = ["simulate", "simulator", "Simulator", "step_windows"]

_CALLS_KEPT = 8
"""Plans whose integrator calls a simulator keeps (:meth:`Simulator._calls`)."""


def simulate(system, t, u=None, x0=None, params=None, rtol: float = 1e-8, atol: float | None = None,
             method: str = "cvodes", compile: bool = False, progress=None) -> SimulationResult:
    """Simulate ``system`` on the time grid ``t``; see :class:`Simulator` (``progress``: see :meth:`Simulator.run`).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> res = simulate(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0})
    >>> round(float(res["v_C"][-1]), 6)   # 1 - exp(-5) of a 1 ms time constant
    0.993262
    """
    if method == "discrete_gradient":
        return discrete_gradient_simulate(system, t, u=u, x0=x0, params=params)
    if method != "cvodes":
        raise InputDataError(f"unknown simulation method {method!r}; use 'cvodes' or 'discrete_gradient'")
    return simulator(system, rtol=rtol, atol=atol, compile=compile).run(t, u=u, x0=x0, params=params, progress=progress)


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


NEGLIGIBLE = 1e-100
"""A run whose integration fails is tried once more with the state's components below this share of their
typical magnitude set to zero: CVODES restarted from a state holding such values (charges of 1e-170 C on
the curling HASEL decaying at 0 V) can fail with repeated right-hand-side errors where it passes from 0."""


MIN_STEP = 1e-14
"""CVODES's smallest step, in output intervals (the integrators' time unit).  Where the domain's gate
(:func:`codegen._domain.gated`) makes the right-hand side NaN, CVODES cuts its step and creeps toward the
boundary; with no smallest step it crept until its steps vanished against the time's roundoff and then
spent its whole step budget there (``CV_TOO_MUCH_WORK``): 0.18 s per failed call of a 0.18 s MSD HASEL run
that takes 1 ms, three such calls per domain exit.  With this bound it gives up at once
(``CV_REPTD_RHSFUNC_ERR``) and the exit is named at the same time and state.  1e-14 of an output interval
is below the time's roundoff beyond the first 1 % of an interval (steps there could not move ``t``), so no
step a solution needs is refused."""

SHARED_INTEGRATORS = 256
"""Integrators kept for every simulator of a thread (:meth:`Simulator._shared_key`; the oldest dropped
first).  A diagnosis builds a simulator per trial of a hypothesis (parameter values differ, the structure
and the recording's windows do not): on the EMPS stage (24.8 s at 1 kHz, 61 integrator calls per run)
rebuilding them was a quarter of each simulation's time."""
_SHARED: OrderedDict = OrderedDict()
_SHARED_LOCK = _threading.Lock()

REACH_SHARES = tuple(sorted({2.0 ** -k for k in range(1, 25)} | {1.0 - 2.0 ** -k for k in range(1, 25)}
                            | {j / 16 for j in range(1, 16)}))
"""Output times, as shares of a failed output interval, of the one integrator call that finds how far into
it the integration gets (:meth:`Simulator._reach`): factors of 2 near its start, halvings of the rest near
its end (a blow-up just before the end), sixteenths in between."""


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
        self._domain = DomainCheck(system, self.f)
        self._plan_calls: dict = {}

    # -- integrator construction ------------------------------------------------------------
    def _integrator(self, n: int, slots, sampled, max_step: float = 1.0, gate: bool = True):
        """CVODES integrator over ``n`` output steps for the given input templates and sampled inputs.

        With ``gate`` the right-hand side is NaN outside the validity domain (:func:`codegen._domain.gated`),
        so the integration stops where the domain is left; without it (only to locate where that was) it
        goes on.

        ``sampled[j]`` is ``(times, values)`` for an input given by samples (baked into a linear
        interpolant: evaluation costs O(log n), not O(n)), else None.  With a sampled input the step
        is bounded by ``max_step`` output intervals (see :func:`step_windows`).
        """
        digests = [(g[2] if len(g) > 2 else _digest(g)) if g is not None else None for g in sampled]
        key = (n, float(max_step), tuple(tuple(k for k, _, _ in sl) for sl in slots), tuple(digests), gate)
        hit = self._integrators.get(key)
        if hit is not None:
            return hit
        shared = self._shared_key(key)
        if shared is not None:
            with _SHARED_LOCK:
                hit = _SHARED.get(shared)
                if hit is not None:
                    _SHARED.move_to_end(shared)
            if hit is not None:
                self._integrators[key] = hit
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
        kinds = []  # how each sampled input is interpolated: part of what a compiled library holds
        for j in range(nu):
            if sampled[j] is not None:
                grid, values = sampled[j][:2]
                # in a smooth window a cubic spline through the same samples: without a kink at every
                # sample CVODES steps across samples (5-15 times fewer steps on sines sampled at 1 kHz);
                # a run's own samples name their kind (codegen._inputs.run_sampled: a local spline)
                kind = sampled[j][3] if len(sampled[j]) > 3 else interpolation(len(grid), max_step)
                kinds.append(kind)
                interp = _interpolant(grid, values, kind, digests[j])
                uexpr.append(interp(tt))
                layout.append(("sampled", ()))
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
            layout.append(("slots", tuple(lay)))
        uu = ca.vertcat(*uexpr) if nu else ca.SX(0, 1)
        x = z * self.scale
        subs_in = [sx["x"], sx["u"], sx["p"]]
        # gated: CVODES stops outside the domain; gated once per model in its own states (the scaled states'
        # Jacobian has the same sparsity), then substituted like the rest: the same expression, built once
        rhs = self._gated_rhs() if gate else sx["xdot"]
        xdot, supplied, dissipated, dparts = ca.substitute(
            [rhs, sx["supplied"], sx["dissipated"], sx["dissipators"]], subs_in, [x, uu, pp]
        )
        ode = h * xdot / self.scale
        # dense: a lossless model's dissipated power is a structural zero, which CVODES refuses as a sparse output
        quad = ca.densify(h * ca.vertcat(supplied, dissipated, dparts)) if self.energy else ca.SX(0, 1)
        P = ca.vertcat(pp, a, h, *extra)
        empty = ca.SX(0, 1)
        dae = ca.Function(f"{self.f.rhs.name()}_dae", [tau, z, empty, P, empty], [ode, empty, quad, empty],
                          ca.dyn_in(), ca.dyn_out())
        if self.compile:
            from codegen.compile import compiled

            # the key names the interpolants' kinds: a spline window and a linear one of the same samples are two libraries
            dae = (self.compiler or compiled)(dae, f"{_model_hash(self.system)}|{key[2:]}|{self.scale.tolist()}|gated"
                                              + (f"|{kinds}" if kinds else ""))
        opts = {"abstol": self.atol, "reltol": self.rtol, "max_num_steps": self.max_steps, "quad_err_con": False,
                "min_step_size": MIN_STEP,  # failures are reported as PHS errors instead:
                "disable_internal_warnings": True, "show_eval_warnings": False}
        if any(g is not None for g in sampled):
            # a sampled input may change after a long constant stretch: never step over a feature of it
            opts["max_step_size"] = float(max_step)
        opts.update(self.integrator_options)
        F = ca.integrator(f"{self.f.rhs.name()}_cvodes{n}", "cvodes", dae, 0.0, np.arange(1.0, n + 1.0), opts)
        layout = ParamLayout(npar, tuple(layout))
        if F.nnz_in(2) != layout.size * (1 + int(self.integrator_options.get("nfwd", 0))):
            raise SimulationError(f"simulation of {self.system.name!r}: integrator built with {F.nnz_in(2)} parameters "
                                  f"where its layout declares {layout.size}")
        self._integrators[key] = (F, layout)
        if shared is not None:
            with _SHARED_LOCK:
                _SHARED[shared] = (F, layout)
                while len(_SHARED) > SHARED_INTEGRATORS:
                    _SHARED.popitem(last=False)
        return F, layout

    def _gated_rhs(self):
        """The model's right-hand side in its own states, NaN outside its validity domain (:func:`gated`)."""
        hit = self.__dict__.get("_gated")
        if hit is None:
            sx = self.f.sx
            hit = self._gated = gated(sx["xdot"], sx["conditions"], sx["x"])
        return hit

    def _shared_key(self, key) -> tuple | None:
        """The key of integrator ``key`` among those every simulator of this thread shares (None for compiled
        ones, whose libraries are cached on disk): what it is built from is the model's structure (not its
        parameter values, which are arguments), the scaling, the tolerances and options, and ``key``."""
        if self.compile or self.compiler is not None:
            return None
        return (_model_hash(self.system), _threading.get_ident(), tuple(self.scale.tolist()), self.rtol, self.atol,
                self.max_steps, self.energy, repr(sorted(self.integrator_options.items())), key)

    # -- running ------------------------------------------------------------------------------
    def run(self, t, u=None, x0=None, params=None, *, signs: bool = True, progress=None) -> SimulationResult:
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
            Parameter overrides by name, checked like every value from outside
            (:meth:`phs.PHSystem.param_vector`: a value of the wrong sign is refused).
        signs : bool, optional
            ``False`` lets an override of the wrong sign through, for analyses that report what
            it does (the passivity certificate's what-if along a trajectory); never for a plain run.
        progress : callable, optional
            Called after each integrator call with the share of the time span done so far (0 to 1):
            a progress bar's hook.

        Raises
        ------
        DomainError
            When the state leaves the model's validity domain (time, state and condition named).
        SimulationError
            When the integrator fails or the solution becomes non-finite.
        """
        s = self.system
        wall = _time.perf_counter()
        t = time_grid(t)
        p = s.param_vector(params, signs=signs)
        x = self.initial_state(x0)
        self._check_domain(x[None, :], t[:1], p, np.zeros((1, len(s.inputs))))
        plan = plan_for(t, input_signals(s, u, t))
        if len(x) == 0:  # a static network: nothing to integrate, outputs follow the inputs
            return self._static_result(t, plan.sigs, plan.segs, plan.slots, p, wall, plan.origin)
        nq = len(energy_columns(s)) if self.energy else 0
        X = np.empty((len(t), len(x)))
        Q = np.zeros((len(t), nq))
        X[0] = x
        U = plan.U.copy()
        z = x / self.scale
        qacc = np.zeros(nq)
        done = []  # (states, times, inputs) of every run so far: the domain is checked over all of them at once
        for r, (F, tail) in zip(plan.runs, self._calls(plan), strict=True):
            P = np.concatenate((p, tail))
            try:
                zs, qs = call_into_numpy(F, z, P, len(x), r.n, nq)
            except RuntimeError as exc:
                self._check_done(done, p, plan.origin)  # a state that left the domain earlier is what went wrong
                try:  # once more from the state with its vanishing components set to zero
                    zs, qs = call_into_numpy(F, np.where(np.abs(z) < NEGLIGIBLE, 0.0, z), P, len(x), r.n, nq)
                except RuntimeError:
                    self._localize_failure(F, z, p, r.start, r.step, r.n, plan.slots, run_sampled(plan.sampled, r.choice, r),
                                           self._calls_layout(plan, r), r.choice, exc, plan.sigs, plan.origin)
            xs = zs * self.scale
            if not np.all(np.isfinite(xs)):
                self._check_done(done, p, plan.origin)
                k = int(np.argmin(np.all(np.isfinite(xs), axis=1)))
                raise SimulationError(f"simulation of {s.name!r}: non-finite state at t={r.times[k] + plan.origin:.6g}: "
                                      + fmt_state(s, xs[k]))
            done.append((xs, r))
            if progress is not None:
                progress(float(r.times[-1]) / max(float(t[-1] - t[0]), 1e-300))
            r.store(X, xs)
            r.store(Q, qacc + qs)
            qacc = qacc + qs[-1]
            z = zs[-1]
        self._check_done(done, p, plan.origin)
        nrun = len(plan.runs)
        res = SimulationResult(s, t, X, U, p, stats={"runs": nrun, "seconds": _time.perf_counter() - wall,
                                                     "method": "cvodes", "rtol": self.rtol, "atol": self.atol})
        if self.energy:
            res.quadratures = energy_accounts(s, Q)
        return res

    def _static_result(self, t, sigs, segs, slots, p, wall, origin: float = 0.0) -> SimulationResult:
        U = np.zeros((len(t), len(sigs)))
        tr = t - origin  # the segments and signals count time from the grid's start (codegen._plan.Plan.origin)
        for a, b, choice in segs:
            sel = (tr >= a) & ((tr < b) | (b >= tr[-1]))
            U[sel] = self._eval_inputs(sigs, slots, choice, tr[sel])
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
        return initial_state(self.system, x0)

    def _pvec(self, p, a, h, layout, choice):
        parts = [p, [a, h]]
        for j, lay in enumerate(layout.inputs):
            if lay[0] == "sampled":  # baked into the integrator
                continue
            active, vals = choice[j]
            for k, nc in enumerate(lay[1]):
                parts.append([1.0 if k == active else 0.0])
                parts.append(vals if k == active else [0.0] * nc)
        P = np.concatenate([np.asarray(v, dtype=float).reshape(-1) for v in parts])
        if len(p):
            layout.check(P, f"simulation of {self.system.name!r}")
        elif len(P) != layout.tail_size:
            layout.check(np.concatenate([np.zeros(layout.n_model), P]), f"simulation of {self.system.name!r}")
        return P

    def _eval_inputs(self, sigs, slots, choice, times, max_step: float = 1.0) -> np.ndarray:
        """Inputs at ``times`` inside one segment, from the segment's templates and constants (a sampled
        input through the interpolant a run of step bound ``max_step`` integrates it with)."""
        return segment_inputs(sigs, slots, choice, times, self._templates, max_step)

    def _check_domain(self, xs, times, p, uu) -> None:
        self._domain(xs, times, p, uu)

    def _calls(self, plan) -> list:
        """``(integrator, parameter tail)`` of each of ``plan``'s runs for this simulator: the run's
        integrator and the part of its parameter vector after the model's parameters (computed once per
        plan; :data:`_CALLS_KEPT` plans kept)."""
        hit = self._plan_calls.get(id(plan))
        if hit is not None and hit[0] is plan:
            return hit[1]
        calls = []
        for r in plan.runs:
            F, layout = self._integrator(r.n, plan.slots, run_sampled(plan.sampled, r.choice, r), r.max_step)
            calls.append((F, self._pvec(np.zeros(0), r.start, r.step, layout, r.choice)))
        while len(self._plan_calls) >= _CALLS_KEPT:
            self._plan_calls.pop(next(iter(self._plan_calls)))
        self._plan_calls[id(plan)] = (plan, calls)
        return calls

    def _calls_layout(self, plan, r):
        return self._integrator(r.n, plan.slots, run_sampled(plan.sampled, r.choice, r), r.max_step)[1]

    def _check_done(self, done, p, origin: float = 0.0) -> None:
        """The validity domain over the output steps of the runs ``done`` (``(states, run)`` pairs) in one call."""
        if done and self.system.conditions:
            self._check_domain(np.vstack([xs for xs, _ in done]), np.concatenate([r.times for _, r in done]) + origin, p,
                               np.vstack([r.u for _, r in done]))

    def _localize_failure(self, F, z, p, a, h, n, slots, sampled, layout, choice, exc, sigs, origin: float = 0.0):
        """Re-run the failed run one output step at a time to name the failing interval, find how far one
        call gets into it (:meth:`_reach`) and say in words what failed there, which state and what to try
        (:func:`codegen._solver_errors.describe`)."""
        s = self.system
        F1, _ = self._integrator(1, slots, sampled)
        zc = z
        for k in range(n):
            P = self._pvec(p, a + k * h, h, layout, choice)
            try:
                zc = np.asarray(F1(x0=zc, p=P)["xf"]).reshape(-1)
            except RuntimeError as step_exc:
                xs = zc * self.scale
                tk = a + k * h
                uk = self._eval_inputs(sigs, slots, choice, np.array([tk]))
                self._check_domain(xs[None, :], np.array([tk + origin]), p, uk)
                self._exit_within(zc, p, tk, h, layout, choice, slots, sampled, sigs, origin)
                self._domain.predicted(xs, tk + origin, h, p, uk)
                covered, step, zr = self._reach(F1, zc, p, tk, h, layout, choice, sampled)
                if covered >= 1.0:  # shorter output steps pass through: the state where the interval starts
                    covered, zr = 0.0, zc
                tr, xr = tk + covered * h, zr * self.scale
                ur = self._eval_inputs(sigs, slots, choice, np.array([tr])) if covered > 0 else uk
                if covered > 0:  # the state the integrator got to: left the domain on the way there?
                    self._check_domain(xr[None, :], np.array([tr + origin]), p, ur)
                across = tk + h * np.array((0.0, *REACH_SHARES, 1.0))
                with np.errstate(all="ignore"):
                    u_across = self._eval_inputs(sigs, slots, choice, across)
                raise SimulationError(describe(step_exc, s, t0=tk + origin, t1=tk + h + origin, t=tr + origin, x=xr, u=ur[0], p=p,
                                               functions=self.f, max_steps=self.max_steps, dt=step * h,
                                               inputs=(across + origin, u_across))) from None
            if not np.all(np.isfinite(zc)):
                break
        uk = self._eval_inputs(sigs, slots, choice, np.array([a]))
        raise SimulationError(describe(exc, s, t0=a + origin, t1=a + n * h + origin, x=z * self.scale, u=uk[0], p=p, functions=self.f,
                                       max_steps=self.max_steps)) from None

    def _reach(self, F1, z, p, tk, h, layout, choice, sampled):
        """``(covered, step, state)``: how far into the failed output interval ``[tk, tk + h]`` the integrator
        gets from the scaled state ``z`` with an output at each of :data:`REACH_SHARES`: the last share it
        reaches (0 when none; 1 when every one, the interval as a whole having failed), the longest of the
        shorter output intervals it passed (as a share, 0 when none), and the scaled state it reached."""
        zs = self._at_shares(F1, z, p, tk, h, layout, choice, sampled)
        ok = np.all(np.isfinite(zs), axis=1)
        k = len(ok) if ok.all() else int(np.argmin(ok))  # outputs are written in order: the first not reached
        if k == 0:
            return 0.0, 0.0, z
        covered = 1.0 if k == len(ok) else REACH_SHARES[k - 1]
        return covered, float(np.max(np.diff((0.0,) + REACH_SHARES[:k]))), zs[k - 1]

    def _at_shares(self, F1, z, p, tk, h, layout, choice, sampled) -> np.ndarray:
        """Scaled states at :data:`REACH_SHARES` of ``[tk, tk + h]`` from ``z``, NaN from the first not reached:
        one call of an integrator of ``F1``'s equations and options, whose outputs land in numpy as they
        are reached (a failure keeps the ones before it)."""
        opts = {"abstol": self.atol, "reltol": self.rtol, "max_num_steps": self.max_steps, "quad_err_con": False,
                "min_step_size": MIN_STEP, "disable_internal_warnings": True, "show_eval_warnings": False}
        if any(g is not None for g in sampled):
            opts["max_step_size"] = 1.0
        opts.update(self.integrator_options)
        zs = np.full((len(REACH_SHARES), len(z)), np.nan)
        try:
            G = ca.integrator(f"{F1.name()}_reach", "cvodes", F1.get_function("dae"), 0.0, list(REACH_SHARES), opts)
            buf, trigger = G.buffer()
            z = np.ascontiguousarray(z, dtype=float)
            P = np.ascontiguousarray(self._pvec(p, tk, h, layout, choice), dtype=float)
            buf.set_arg(0, memoryview(z))
            buf.set_arg(2, memoryview(P))
            buf.set_res(0, memoryview(zs))
            trigger()
        except RuntimeError:
            pass
        ok = np.all(np.isfinite(zs), axis=1)
        if not ok.all():
            zs[int(np.argmin(ok)):] = np.nan
        return zs

    def _exit_within(self, z, p, tk, h, layout, choice, slots, sampled, sigs, origin: float = 0.0) -> None:
        """The integration of ``[tk, tk + h]`` from the scaled state ``z`` (inside the domain) failed: integrate
        it again without the domain's gate, with outputs at :data:`REACH_SHARES`, and raise the
        :class:`~phs.errors.DomainError` of the first output outside the validity domain, if any (the
        gate, :func:`codegen._domain.gated`, stopped the integration there)."""
        if not self.system.conditions:
            return
        F1, _ = self._integrator(1, slots, sampled, gate=False)
        zs = self._at_shares(F1, z, p, tk, h, layout, choice, sampled)
        k = int(np.sum(np.all(np.isfinite(zs), axis=1)))
        if k:
            times = tk + h * np.asarray(REACH_SHARES[:k])
            with np.errstate(all="ignore"):
                uu = self._eval_inputs(sigs, slots, choice, times)
            self._check_domain(zs[:k] * self.scale, times + origin, p, uu)
