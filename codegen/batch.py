"""Batched simulation: many variants of one system on one time grid, in threads.

A batch is a list of runs that share the system's structure and the time grid
and differ in parameter values, inputs or initial states (sweeps, Monte Carlo,
multi-start).  Evaluation:

* For each input *shape* (breakpoints and expression templates of the inputs,
  see :class:`codegen.simulator.Simulator`) the CVODES integrators of the
  simulator, restarted at every breakpoint, are chained into one CasADi
  function of a run, ``(z0, p, c) -> (Z, Q, Z_off)``: scaled initial state,
  parameters, and the per-segment constants (segment start, step, input
  constants), so runs whose inputs differ only in amplitudes share it.
* ``Function.map(n, "thread", k)`` evaluates a chunk of ``n`` runs in ``k``
  threads; arguments and results are numpy arrays handed to CasADi through
  its buffer interface, so the trajectories land in numpy without a copy.
* Validity conditions, measured outputs and the power balance are evaluated
  for every point of the chunk in one threaded mapped call each.
* A run whose integration fails is isolated by bisecting its chunk; its error
  is the one :meth:`Simulator.run` reports for it (a :class:`~phs.errors.DomainError`
  naming the condition and time, or a :class:`~phs.errors.SimulationError`).
  Runs that leave the validity domain or become non-finite are failed the same
  way; a failed run never stops the batch.

The arithmetic is the simulator's: a run of a batch is bitwise the run of
:meth:`Simulator.run` with the same arguments, whatever the number of threads.

Pickling a :class:`BatchSimulator` (as Dask does to ship it to worker
processes) carries the system and its generated functions in CasADi's own
serialization (:func:`serialize_functions`); unpickling installs them, so a
worker never re-derives the model symbolically: it only rebuilds the
integrators from the deserialized expressions, or loads them compiled from the
disk cache (``compile=True``, :mod:`codegen.compile`).

The pieces: the run function of one input shape (:mod:`codegen._batch_plan`),
the result (:mod:`codegen._batch_result`), threaded maps and their console
(:mod:`codegen._mapped`), the functions' serialization
(:mod:`codegen._serialize`); their public names are importable from here.
"""

from __future__ import annotations

import threading
import time as _time
from collections import OrderedDict

import casadi as ca
import numpy as np

from codegen._batch_plan import Shape, plan_shape, run_function
from codegen._batch_result import SIGNALS, BatchResult
from codegen._domain import fmt_state
from codegen._grid import time_grid
from codegen._mapped import Mapped, default_threads, quiet, unsilence
from codegen._output import energy_columns
from codegen._serialize import deserialize_functions, serialize_functions
from codegen._solver_errors import describe
from codegen.functions import generate
from codegen.simulator import Simulator
from phs.errors import DomainError, InputDataError, PHSError, SimulationError

__all__ = ["BatchSimulator", "BatchResult", "LOCK", "SIGNALS", "default_threads", "serialize_functions",
           "deserialize_functions", "unsilence"]

#: Held while a batch runs.  CasADi releases Python's GIL during its calls, but building functions
#: (integrators, maps) is not thread-safe: concurrent batches in one process (threads of a Dask worker)
#: take turns; each batch still evaluates in its own CasADi threads.
LOCK = threading.RLock()


class BatchSimulator:
    """Simulate many variants of one system on one time grid with CasADi ``map`` in threads.

    Parameters
    ----------
    system : PHSystem
    t : array
        Strictly increasing output times shared by every run.
    rtol, atol, max_steps, compile, energy
        As for :class:`codegen.simulator.Simulator` (``energy`` integrates the energy accounts).
    threads : int, optional
        Threads of the mapped evaluation (default: :func:`default_threads`); 1 evaluates the runs
        one after the other through the same functions (bitwise the same results).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import mass_spring_damper
    >>> batch = BatchSimulator(mass_spring_damper(), np.linspace(0, 60, 601), energy=False)
    >>> res = batch.run([{"k.K": k} for k in (1.0, 4.0, 9.0)], u={"F": 1.0})
    >>> [round(float(res[i]["position"][-1]), 3) for i in range(3)]   # settled at F / K
    [1.0, 0.25, 0.111]
    """

    def __init__(self, system, t, rtol: float = 1e-8, atol: float | None = None, max_steps: int = 20000,
                 compile: bool = False, energy: bool = True, threads: int | None = None):
        t = time_grid(np.array(t, dtype=float))
        if threads is not None and (not isinstance(threads, (int, np.integer)) or threads < 1):
            raise InputDataError(f"threads must be a positive integer, got {threads!r}")
        t.setflags(write=False)
        self.system = system
        self.t = t
        self.threads = int(threads) if threads is not None else default_threads()
        self._opts = {"rtol": rtol, "atol": atol, "max_steps": max_steps, "compile": compile, "energy": energy}
        self.simulator = Simulator(system, rtol=rtol, atol=atol, max_steps=max_steps, compile=compile, energy=energy)
        self.functions = generate(system)
        self._runfuns: dict = {}
        self._mapped: dict = {}
        self._inner: dict = {}
        self._subsets: dict = {}

    # -- pickling: the model travels with its serialized generated functions ------------------------------
    def __getstate__(self) -> dict:
        return {"system": self.system, "t": np.array(self.t), "threads": self.threads, "opts": self._opts,
                "functions": serialize_functions(self.functions)}

    def __setstate__(self, state: dict) -> None:
        deserialize_functions(state["system"], state["functions"])
        self.__init__(state["system"], state["t"], threads=state["threads"], **state["opts"])

    # -- preparation ------------------------------------------------------------------------------------
    def _runfun(self, shape: Shape) -> ca.Function:
        f = self._runfuns.get(shape.key)
        if f is None:
            f = self._runfuns[shape.key] = run_function(self.simulator, shape, f"{self.functions.rhs.name()}_run")
        return f

    def _map(self, f: ca.Function, n: int, inner: int | None = None) -> Mapped:
        """``f`` mapped over ``n`` runs (threads), optionally over ``inner`` grid points per run first."""
        key = (id(f), n, inner, self.threads)
        hit = self._mapped.get(key)
        if hit is None:
            g = f
            if inner:  # over the grid points of one run (parameters shared): built once per function
                g = self._inner.get((id(f), inner))
                if g is None:
                    g = self._inner[(id(f), inner)] = f.map(f"{f.name()}_grid", "serial", inner, [2], [])
            hit = Mapped(g.map(n, "thread", min(self.threads, n)) if self.threads > 1 and n > 1 else g.map(n, "serial"))
            self._mapped[key] = hit
            if len(self._mapped) > 64:
                self._mapped.pop(next(iter(self._mapped)))
        return hit

    # -- running ----------------------------------------------------------------------------------------
    def run(self, params=None, u=None, x0=None, signals=(), n: int | None = None) -> BatchResult:
        """Simulate every run and return a :class:`BatchResult`.

        Parameters
        ----------
        params : sequence of dict, optional
            Parameter overrides of each run (its length is the number of runs).
        u : input specification, or list/tuple of them
            Inputs as for :meth:`Simulator.run` shared by all runs, or a list (or tuple) with one
            specification per run.
        x0 : dict or array, or list/tuple of them
            Initial state shared by all runs, or one per run in a list (or tuple).
        signals : sequence of str
            Derived signals evaluated for the whole batch at once, among :data:`SIGNALS`
            (``"measured"``, ``"output"``, ``"power"``, ``"hamiltonian"``) and names of single measured
            outputs (only those are evaluated); others are computed on demand per run.
        n : int, optional
            Number of runs when neither ``params``, ``u`` nor ``x0`` is a per-run list.

        A run whose parameters, inputs or initial state are invalid, whose integration fails or that
        leaves the validity domain is failed with that error in ``errors``; the others are unaffected.

        Raises
        ------
        InputDataError
            When the per-run lists disagree in length or ``signals`` names an unknown signal.
        """
        with LOCK:  # see LOCK: CasADi's symbolic construction is not thread-safe
            return self._run(params, u, x0, signals, n)

    def _run(self, params, u, x0, signals, n) -> BatchResult:
        wall = _time.perf_counter()
        bad = [s for s in signals if s not in SIGNALS and s not in self.system.measured_names]
        if bad:
            raise InputDataError(f"unknown batch signal {bad[0]!r}; choose among {', '.join(SIGNALS)} or a measured "
                                 f"output ({', '.join(self.system.measured_names) or 'none'})")
        sizes = {name: len(v) for name, v in (("params", params), ("u", u), ("x0", x0))
                 if v is not None and (name == "params" or isinstance(v, (list, tuple)))}
        if n is not None:
            sizes["n"] = int(n)
        if len(set(sizes.values())) > 1:
            raise InputDataError(f"batch: per-run lists of different lengths ({', '.join(f'{k} {v}' for k, v in sizes.items())})")
        N = next(iter(sizes.values()), 1)
        s = self.system
        sim = self.simulator
        nt, nx, nu, npar = len(self.t), len(s.states), len(s.inputs), len(s.params)
        nq = len(energy_columns(s)) if sim.energy else 0

        def each(v, k):
            return v[k] if isinstance(v, (list, tuple)) else v

        errors: list = [None] * N
        P = np.empty((N, npar))
        X0 = np.empty((N, nx))
        shapes: list = [None] * N
        seen: dict = {}  # input specifications of this call by identity (the caller keeps them alive)
        for k in range(N):
            try:
                P[k] = s.param_vector(params[k] if params is not None else None)
                X0[k] = sim.initial_state(each(x0, k))
                uk = each(u, k)
                if nx == 0:  # a static network: nothing to plan
                    continue
                if id(uk) not in seen:
                    seen[id(uk)] = plan_shape(sim, self.t, uk)
                shapes[k] = seen[id(uk)]
            except PHSError as exc:
                errors[k] = exc
            except Exception as exc:  # a user's input callable failing for this run
                errors[k] = SimulationError(f"run {k} of {s.name!r}: preparing its inputs failed: {type(exc).__name__}: {exc}")
        if nx == 0:  # a static network: nothing to integrate, the simulator evaluates it directly
            return self._static(params, u, x0, N, errors, P, wall)
        X = np.empty((N, nt, nx))  # every row is written by its run, or set to NaN when the run failed
        U = np.zeros((N, nt, nu))
        U_check = np.zeros((N, nt, nu))
        off_points: dict = {}
        Q = np.empty((N, nt, nq)) if nq else None
        groups: OrderedDict = OrderedDict()
        for k in range(N):
            if errors[k] is None:
                groups.setdefault(shapes[k].key, []).append(k)
        calls = 0
        for idx in groups.values():
            shape = shapes[idx[0]]
            calls = max(calls, len(shape.steps))
            fun = self._runfun(shape)
            idx = np.asarray(idx)
            contiguous = bool(np.all(np.diff(idx) == 1))
            sl = slice(idx[0], idx[-1] + 1)
            Xg = X[sl] if contiguous else np.empty((len(idx), nt, nx))
            Qg = (Q[sl] if contiguous else np.empty((len(idx), nt, nq))) if nq else None
            n_off = len(shape.t_off)
            Zoff = np.empty((len(idx), n_off, nx)) if n_off else None
            Z0 = X0[idx] / sim.scale
            C = np.ascontiguousarray(np.broadcast_to(shape.c, (len(idx), len(shape.c))))
            for k in idx:  # inputs of runs sharing a shape may differ in their constants
                if shapes[k] is not shape:
                    C[np.searchsorted(idx, k)] = shapes[k].c
            ok = self._evaluate(fun, np.ascontiguousarray(Z0), np.ascontiguousarray(P[idx]), C, Xg, Qg, Zoff)
            Xg[:, 1:, :] *= sim.scale
            Xg[:, 0, :] = X0[idx]
            if not contiguous:
                X[idx] = Xg
                if nq:
                    Q[idx] = Qg
            for pos, k in enumerate(idx):
                U[k] = shapes[k].U
                U_check[k] = shapes[k].U_check
                if not ok[pos]:
                    errors[k] = self._failure(k, each(u, k), X0[k], P[k])
                elif n_off:
                    off_points[k] = Zoff[pos] * sim.scale
        done = [k for k in range(N) if errors[k] is None]
        if done:
            bad = self._violations(X, U_check, P)
            for k in done:
                if bad[k] or k in off_points:
                    errors[k] = self._check(X[k], off_points.get(k), shapes[k], P[k])
        for k in range(N):
            if errors[k] is not None:
                X[k] = np.nan
                if nq:
                    Q[k] = np.nan
        derived = self._derived(signals, X, U, P) if signals else {}
        stats = {"seconds": _time.perf_counter() - wall, "rtol": sim.rtol, "atol": sim.atol, "threads": self.threads,
                 "integrator_calls": calls, "shapes": len(groups)}
        return BatchResult(s, self.t, X, U, P, Q, errors, derived, stats)

    def _static(self, params, u, x0, N, errors, P, wall) -> BatchResult:
        """Runs of a system without states, one :meth:`Simulator.run` each."""
        s, nt, nu = self.system, len(self.t), len(self.system.inputs)
        columns = energy_columns(s)
        nq = len(columns) if self.simulator.energy else 0
        U = np.zeros((N, nt, nu))
        Q = np.zeros((N, nt, nq)) if nq else None
        for k in range(N):
            if errors[k] is not None:
                continue
            try:
                res = self.simulator.run(self.t, u=u[k] if isinstance(u, (list, tuple)) else u,
                                         params=params[k] if params is not None else None)
            except PHSError as exc:
                errors[k] = exc
                continue
            U[k] = res.u
            for i, name in enumerate(columns[:nq]):
                Q[k, :, i] = res.quadratures[name]
        stats = {"seconds": _time.perf_counter() - wall, "rtol": self.simulator.rtol, "atol": self.simulator.atol,
                 "threads": self.threads, "integrator_calls": 0, "shapes": 0}
        return BatchResult(s, self.t, np.zeros((N, nt, 0)), U, P, Q, errors, {}, stats)

    def _evaluate(self, fun, Z0, P, C, X, Q, Zoff) -> np.ndarray:
        """Evaluate the runs of a chunk into ``X``/``Q``/``Zoff``; bisect to isolate failing runs."""
        m = len(Z0)
        buf, trigger = self._map(fun, m).buffer()
        buf.set_arg(0, memoryview(Z0))
        buf.set_arg(1, memoryview(P))
        buf.set_arg(2, memoryview(C))
        r = 0
        buf.set_res(r, memoryview(X))
        if Q is not None:
            r += 1
            buf.set_res(r, memoryview(Q))
        if Zoff is not None:
            r += 1
            buf.set_res(r, memoryview(Zoff))
        with quiet():
            try:
                trigger()
                failed = buf.ret() != 0
            except RuntimeError:
                failed = True
        if not failed:
            return np.ones(m, dtype=bool)
        if m == 1:
            return np.zeros(1, dtype=bool)
        h = m // 2
        parts = [slice(0, h), slice(h, m)]
        return np.concatenate([self._evaluate(fun, Z0[q], P[q], C[q], X[q], None if Q is None else Q[q],
                                              None if Zoff is None else Zoff[q]) for q in parts])

    def _failure(self, k, u, x0, p) -> PHSError:
        """The error :meth:`Simulator.run` reports for a run whose integration failed."""
        params = dict(zip(self.system.param_names, p.tolist()))
        with quiet():
            try:
                self.simulator.run(self.t, u=u, x0=x0, params=params)
            except PHSError as exc:
                return exc
            except RuntimeError as exc:
                return SimulationError(describe(exc, self.system, t0=float(self.t[0]), t1=float(self.t[-1]), x=x0, p=p,
                                                max_steps=self.simulator.max_steps))
        return SimulationError(f"simulation of {self.system.name!r}: the integrator failed in the batch evaluation "
                               "but not when run alone")

    def _violations(self, X, U_check, P) -> np.ndarray:
        """Per run: a non-finite state or a violated validity condition at some grid point (one threaded call)."""
        s = self.system

        def nonfinite_or_below(A, low):  # per run, without temporaries of A's size: NaN propagates through min/max
            lo = A.min(axis=(1, 2))
            return ~np.isfinite(lo) | ~(lo >= low) | ~np.isfinite(A.max(axis=(1, 2)))

        bad = nonfinite_or_below(X, -np.inf)
        if s.conditions:
            N, nt = X.shape[0], X.shape[1]
            buf, trigger = self._map(self.functions.conditions, N, inner=nt).buffer()
            G = np.empty((N, nt, len(s.conditions)))
            for i, a in enumerate((X, U_check, P)):
                buf.set_arg(i, memoryview(np.ascontiguousarray(a)))
            buf.set_res(0, memoryview(G))
            with np.errstate(all="ignore"), quiet():
                trigger()
            bad |= nonfinite_or_below(G, -1e-12)
        return bad

    def _check(self, x, xoff, shape: Shape, p) -> PHSError | None:
        """The error of a run with a non-finite state or a violated condition (first in time first),
        also looking at the integrator's outputs between grid points (``xoff``)."""
        s = self.system
        t_all, x_all, u_all = self.t, x, shape.U_check
        if xoff is not None and len(xoff):
            order = np.argsort(np.concatenate([self.t, shape.t_off]), kind="stable")
            t_all = np.concatenate([self.t, shape.t_off])[order]
            x_all = np.concatenate([x, xoff])[order]
            u_all = np.concatenate([shape.U_check, shape.U_off])[order]
        finite = np.all(np.isfinite(x_all), axis=1)
        first_bad = None if finite.all() else int(np.argmin(finite))
        stop = len(t_all) if first_bad is None else first_bad
        if s.conditions and stop > 0:
            try:
                self.simulator._check_domain(x_all[:stop], t_all[:stop], p, u_all[:stop])
            except DomainError as exc:
                return exc
        if first_bad is not None:
            return SimulationError(f"simulation of {s.name!r}: non-finite state at t={t_all[first_bad]:.6g}: "
                                   + fmt_state(s, x_all[first_bad]))
        return None

    def _derived(self, signals, X, U, P) -> dict:
        """Derived signals for every run and grid point in one threaded mapped call each."""
        f = self.functions
        N, nt = X.shape[0], X.shape[1]
        names = [n for n in dict.fromkeys(signals) if n not in SIGNALS]
        kinds = [n for n in dict.fromkeys(signals) if n in SIGNALS]
        funs = {k: {"measured": f.measured, "output": f.output, "power": f.power_balance,
                    "hamiltonian": f.hamiltonian}[k] for k in kinds}
        if names and "measured" not in kinds:
            funs["columns"] = self._measured_subset(tuple(names))
        out = {}
        for key, fun in funs.items():
            buf, trigger = self._map(fun, N, inner=nt).buffer()
            args = [np.ascontiguousarray(X), np.ascontiguousarray(U), np.ascontiguousarray(P)]
            for i, a in enumerate(args):
                buf.set_arg(i, memoryview(a))
            res = [np.empty((N, nt, fun.size1_out(i))) for i in range(fun.n_out())]
            for i, r in enumerate(res):
                buf.set_res(i, memoryview(r))
            with np.errstate(all="ignore"), quiet():
                trigger()
            if key == "power":
                out[key] = tuple(r[:, :, 0] for r in res)
            elif key == "columns":
                out.update({n: res[0][:, :, i] for i, n in enumerate(names)})
            else:
                out[key] = res[0]
        if names and "measured" in kinds:
            idx = self.system.measured_names
            out.update({n: out["measured"][:, :, idx.index(n)] for n in names})
        return out

    def _measured_subset(self, names: tuple) -> ca.Function:
        """The measured outputs ``names`` alone (the same expressions: bitwise the rows of the full function)."""
        hit = self._subsets.get(names)
        if hit is None:
            sx = self.functions.sx
            rows = [self.system.measured_names.index(n) for n in names]
            hit = self._subsets[names] = ca.Function(f"{self.functions.measured.name()}_{len(self._subsets)}",
                                                     [sx["x"], sx["u"], sx["p"]], [sx["measured"][rows]],
                                                     ["x", "u", "p"], ["measured"])
        return hit

    def __repr__(self) -> str:
        return f"BatchSimulator({self.system.name!r}, {len(self.t)} samples, threads={self.threads})"
