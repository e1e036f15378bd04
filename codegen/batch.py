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
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
import sys
import threading
import time as _time
from collections import OrderedDict

import casadi as ca
import numpy as np

from codegen import functions as _functions
from codegen._domain import fmt_state
from codegen._grid import time_grid
from codegen._inputs import input_signals, plan_segments
from codegen._output import check_covered, energy_accounts, energy_columns, output_runs
from codegen.functions import GeneratedFunctions, generate
from codegen.results import SimulationResult
from codegen.simulator import Simulator
from phs.errors import DomainError, InputDataError, PHSError, SimulationError
from phs.signals import Sampled

#: Held while a batch runs.  CasADi releases Python's GIL during its calls, but building functions
#: (integrators, maps) is not thread-safe: concurrent batches in one process (threads of a Dask worker)
#: take turns; each batch still evaluates in its own CasADi threads.
LOCK = threading.RLock()

#: Derived signals that :meth:`BatchSimulator.run` can evaluate for a whole chunk at once.
SIGNALS = ("measured", "output", "power", "hamiltonian")


def default_threads() -> int:
    """Number of threads used by default: the processors this process may run on.

    Examples
    --------
    >>> default_threads() >= 1
    True
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


# -- transport of generated functions -------------------------------------------------------------
def serialize_functions(functions: GeneratedFunctions) -> dict:
    """The generated functions of a system in CasADi's serialization (one stream, shared symbols kept).

    Returns a plain dict (strings and lists) that pickles cheaply; :func:`deserialize_functions`
    restores it without any symbolic work.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> blob = serialize_functions(generate(rc_circuit()))
    >>> sorted(blob)[:3], blob["casadi"] == ca.__version__
    (['casadi', 'data', 'fields'], True)
    """
    fields = [f.name for f in dataclasses.fields(GeneratedFunctions) if f.name not in ("system", "sx")]
    ser = ca.StringSerializer()
    for name in fields:
        ser.pack(getattr(functions, name))
    keys = list(functions.sx)
    for key in keys:
        ser.pack(functions.sx[key])
    return {"casadi": ca.__version__, "fields": fields, "sx_keys": keys, "data": ser.encode()}


def deserialize_functions(system, blob: dict, install: bool = True) -> GeneratedFunctions:
    """Rebuild :class:`GeneratedFunctions` of ``system`` from :func:`serialize_functions` output.

    With ``install`` (default) they become what :func:`codegen.generate` returns for ``system``
    (and for systems differing from it only in parameter values), so nothing is re-derived.

    Raises
    ------
    SimulationError
        When the blob was written by another CasADi version (its serialization is not portable
        across versions).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> rc = rc_circuit()
    >>> f = deserialize_functions(rc, serialize_functions(generate(rc)), install=False)
    >>> float(f.hamiltonian([1e-6], [0], [1e3, 1e-6]))
    5e-07
    """
    if blob.get("casadi") != ca.__version__:
        raise SimulationError(f"generated functions of {system.name!r} were serialized by CasADi {blob.get('casadi')} "
                              f"but this process runs CasADi {ca.__version__}; install the same version everywhere")
    des = ca.StringDeserializer(blob["data"])
    funs = {name: des.unpack() for name in blob["fields"]}
    sx = {key: des.unpack() for key in blob["sx_keys"]}
    out = GeneratedFunctions(system=system, sx=sx, **funs)
    if install:
        _functions._CACHE[system] = out
        _functions._BY_HASH[system.model_hash()] = out
    return out


class _Discard:
    """A text stream that drops what it is given."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


_QUIET_LOCK = threading.Lock()
_QUIET = {"depth": 0, "saved": None}


@contextlib.contextmanager
def _quiet():
    """Silence CasADi's diagnostics (failed runs are reported as PHS errors instead).

    CasADi prints through Python's ``sys.stdout``/``sys.stderr``; they are swapped once for all
    threads inside (a per-call ``redirect_stdout`` would, with several threads, restore another
    thread's sink and lose the console for good).
    """
    with _QUIET_LOCK:
        if _QUIET["depth"] == 0:
            _QUIET["saved"] = (sys.stdout, sys.stderr)
            sys.stdout = sys.stderr = _Discard()
        _QUIET["depth"] += 1
    try:
        yield
    finally:
        with _QUIET_LOCK:
            _QUIET["depth"] -= 1
            if _QUIET["depth"] == 0:
                sys.stdout, sys.stderr = _QUIET["saved"]


# -- the run function of one input shape -----------------------------------------------------------
@dataclasses.dataclass
class _Step:
    """One integrator call of a run: ``n`` output steps, which of them are grid points."""

    F: ca.Function
    n_c: int  # entries of the constant vector c used by this call
    on: np.ndarray  # bool (n,): output step lands on the grid
    j: np.ndarray  # grid indices of the steps on the grid


@dataclasses.dataclass
class _Shape:
    """An input specification evaluated on the grid: the integrator calls and the per-run constants."""

    key: str
    steps: list
    c: np.ndarray  # constants of every call, concatenated
    U: np.ndarray  # (nt, nu) inputs as stored in results (right-continuous at breakpoints)
    U_check: np.ndarray  # (nt, nu) inputs with which the simulator checks the validity domain
    t_off: np.ndarray  # output times of the integrator that are not grid points (segment ends)
    U_off: np.ndarray


def _shape(sim: Simulator, t: np.ndarray, u) -> _Shape:
    """Plan the integrator calls of :meth:`Simulator.run` for the input ``u`` on the grid ``t``."""
    sigs = input_signals(sim.system, u, t)
    segs, slots = plan_segments(sigs, t)
    sampled = [(np.asarray(sg.times), np.asarray(sg.values)) if isinstance(sg, Sampled) else None for sg in sigs]
    nt, nu = len(t), len(sigs)
    U = np.zeros((nt, nu))
    U_check = np.zeros((nt, nu))  # the initial state is checked with zero input, as the simulator does
    runs, steps, cs, t_off, u_off, key = [], [], [], [], [], []
    for r in output_runs(t, sigs, segs, lambda choice, times: sim._eval_inputs(sigs, slots, choice, times), U):
        F, layout = sim._integrator(r.n, slots, sampled, r.max_step)
        c = sim._pvec(np.zeros(0), r.start, r.step, layout, r.choice)
        r.store(U_check, r.u)
        t_off.extend(r.times[~r.on])
        u_off.extend(r.u[~r.on])
        runs.append(r)
        steps.append(_Step(F, len(c), r.on, r.j[r.on]))
        cs.append(c)
        key.append((id(F), len(c), r.on.tobytes(), r.j[r.on].tobytes()))
    check_covered(runs, nt, "batch evaluation")
    return _Shape(key=hashlib.sha1(repr(key).encode()).hexdigest(), steps=steps,
                  c=np.concatenate(cs) if cs else np.zeros(0), U=U, U_check=U_check,
                  t_off=np.asarray(t_off, dtype=float), U_off=np.asarray(u_off, dtype=float).reshape(-1, nu))


def _run_function(sim: Simulator, shape: _Shape, name: str) -> ca.Function:
    """Chain the integrator calls of ``shape`` into one function ``(z0, p, c) -> (Z, [Q], [Z_off])``."""
    nx, npar = len(sim.system.states), len(sim.system.params)
    nq = len(energy_columns(sim.system)) if sim.energy else 0
    z0 = ca.MX.sym("z0", nx)
    p = ca.MX.sym("p", npar)
    c = ca.MX.sym("c", len(shape.c))
    z = z0
    grid, qgrid, off = [z0], [ca.MX.zeros(nq, 1)], []
    qacc = ca.MX.zeros(nq, 1)
    k = 0
    for st in shape.steps:
        out = st.F(x0=z, p=ca.vertcat(p, c[k:k + st.n_c]))
        k += st.n_c
        xf = out["xf"]
        on = [int(i) for i in np.nonzero(st.on)[0]]
        offi = [int(i) for i in np.nonzero(~st.on)[0]]
        grid.append(xf if len(on) == len(st.on) else xf[:, on])
        if offi:
            off.append(xf[:, offi])
        if nq:
            qf = out["qf"]
            qgrid.append(ca.repmat(qacc, 1, len(on)) + (qf if len(on) == len(st.on) else qf[:, on]))
            qacc = qacc + qf[:, -1]
        z = xf[:, -1]
    outs, names = [ca.horzcat(*grid)], ["Z"]
    if nq:
        outs.append(ca.horzcat(*qgrid))
        names.append("Q")
    if off:
        outs.append(ca.horzcat(*off))
        names.append("Z_off")
    return ca.Function(name, [z0, p, c], outs, ["z0", "p", "c"], names)


# -- results -------------------------------------------------------------------------------------------
class _BatchRun(SimulationResult):
    """A run of a batch: a :class:`SimulationResult` whose derived signals were evaluated for the batch."""

    def __init__(self, system, t, x, u, p, stats, pre: dict):
        super().__init__(system, t, x, u, p, stats)
        self._pre = pre

    @property
    def measured(self) -> np.ndarray:
        """Measured outputs (nt, n_measured)."""
        m = self._pre.get("measured")
        return m if m is not None else super().measured

    @property
    def y(self) -> np.ndarray:
        """Power-conjugate outputs (nt, nu)."""
        y = self._pre.get("output")
        return y if y is not None else super().y

    @property
    def H(self) -> np.ndarray:
        """Hamiltonian along the trajectory."""
        h = self._pre.get("hamiltonian")
        return h if h is not None else super().H

    @property
    def _power(self):
        pw = self._pre.get("power")
        return pw if pw is not None else super()._power

    def __getitem__(self, name: str) -> np.ndarray:
        col = self._pre.get("columns", {}).get(name)
        return col if col is not None else super().__getitem__(name)


class BatchResult:
    """Trajectories of the runs of a batch, in arrays shared with CasADi's outputs.

    Attributes
    ----------
    t : array (nt,)
    x : array (n, nt, nx)
        States of every run (rows of failed runs are NaN).
    u : array (n, nt, nu)
        Inputs on the grid.
    p : array (n, n_params)
        Parameter values.
    quadratures : array (n, nt, 2 + n_dissipators) or None
        Cumulative supplied energy, dissipated energy and energy dissipated per element
        (with ``energy=True``).
    errors : list
        ``None`` for a run that succeeded, else its :class:`~phs.errors.PHSError`.
    signals : dict
        Derived signals evaluated for the whole batch (``"measured"``: (n, nt, n_measured), ...).
    seconds : float
        Wall time of the batch.

    ``result[k]`` is run ``k`` as a :class:`~codegen.results.SimulationResult` (raising its error
    if it failed); ``len(result)`` is the number of runs.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> batch = BatchSimulator(rc_circuit(), np.linspace(0, 1e-3, 11), threads=2)
    >>> res = batch.run([{"R.R": 1e3}, {"R.R": 2e3}], u={"U": 1.0})
    >>> len(res), bool(res.ok.all()), res.x.shape
    (2, True, (2, 11, 1))
    >>> round(float(res[0]["v_C"][-1]), 6)   # 1 - exp(-1)
    0.632121
    """

    def __init__(self, system, t, x, u, p, quadratures, errors, signals, stats):
        self.system = system
        self.t = t
        self.x = x
        self.u = u
        self.p = p
        self.quadratures = quadratures
        self.errors = errors
        self.signals = signals
        self.stats = stats
        self.seconds = float(stats.get("seconds", 0.0))

    def __len__(self) -> int:
        return len(self.errors)

    @property
    def ok(self) -> np.ndarray:
        """Boolean array: which runs succeeded."""
        return np.array([e is None for e in self.errors], dtype=bool)

    def __getitem__(self, k: int) -> SimulationResult:
        k = range(len(self))[k]
        if self.errors[k] is not None:
            raise self.errors[k]
        s = self.system
        pre = {}
        for name, arr in self.signals.items():
            if name == "power":
                pre[name] = tuple(a[k] for a in arr)
            elif name == "hamiltonian":
                pre[name] = arr[k][:, 0]
            elif name in SIGNALS:
                pre[name] = arr[k]
            else:  # one measured output
                pre.setdefault("columns", {})[name] = arr[k]
        stats = {"runs": self.stats.get("integrator_calls"), "seconds": self.seconds / max(len(self), 1),
                 "method": "cvodes", "rtol": self.stats.get("rtol"), "atol": self.stats.get("atol"), "batch": True}
        res = _BatchRun(s, self.t, self.x[k], self.u[k], self.p[k], stats, pre)
        if self.quadratures is not None:
            res.quadratures = energy_accounts(s, self.quadratures[k])
        return res

    def __repr__(self) -> str:
        return f"BatchResult({self.system.name!r}, {len(self)} runs, {int(self.ok.sum())} ok, {len(self.t)} samples)"


# -- the batch simulator ---------------------------------------------------------------------------------
class _Mapped:
    """A mapped function and its call buffers (one per thread: a buffer holds the evaluation's work memory,
    whose allocation costs as much as a short evaluation)."""

    def __init__(self, f: ca.Function):
        self.f = f
        self._local = threading.local()

    def buffer(self):
        hit = getattr(self._local, "buffer", None)
        if hit is None:
            hit = self._local.buffer = self.f.buffer()
        return hit


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
    def _runfun(self, shape: _Shape) -> ca.Function:
        f = self._runfuns.get(shape.key)
        if f is None:
            f = self._runfuns[shape.key] = _run_function(self.simulator, shape, f"{self.functions.rhs.name()}_run")
        return f

    def _map(self, f: ca.Function, n: int, inner: int | None = None) -> _Mapped:
        """``f`` mapped over ``n`` runs (threads), optionally over ``inner`` grid points per run first."""
        key = (id(f), n, inner, self.threads)
        hit = self._mapped.get(key)
        if hit is None:
            g = f
            if inner:  # over the grid points of one run (parameters shared): built once per function
                g = self._inner.get((id(f), inner))
                if g is None:
                    g = self._inner[(id(f), inner)] = f.map(f"{f.name()}_grid", "serial", inner, [2], [])
            hit = _Mapped(g.map(n, "thread", min(self.threads, n)) if self.threads > 1 and n > 1 else g.map(n, "serial"))
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
                    seen[id(uk)] = _shape(sim, self.t, uk)
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
        with _quiet():
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
        with _quiet():
            try:
                self.simulator.run(self.t, u=u, x0=x0, params=params)
            except PHSError as exc:
                return exc
            except RuntimeError as exc:
                return SimulationError(f"simulation of {self.system.name!r} failed: {str(exc).splitlines()[-1][:200]}")
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
            with np.errstate(all="ignore"), _quiet():
                trigger()
            bad |= nonfinite_or_below(G, -1e-12)
        return bad

    def _check(self, x, xoff, shape: _Shape, p) -> PHSError | None:
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
            with np.errstate(all="ignore"), _quiet():
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
