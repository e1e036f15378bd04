"""Inputs and initial states of a simulation, as the user gives them.

A user's input specification (numbers, :mod:`phs.signals` signals, expressions of ``t``, arrays on
the grid, callables) becomes one piecewise-smooth :class:`~phs.signals.Signal` per system input
(:func:`input_signals`).  The time between the inputs' breakpoints is cut into segments, and on each
segment every input is a sympy template whose numbers are left as constants (:func:`plan_segments`),
so that one integrator serves every segment of the same shape; :func:`segment_inputs` evaluates the
inputs of a segment from its template and constants.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Real

import numpy as np
import sympy as sp

from codegen._grid import local_samples
from codegen._interpolants import digest, interpolation, sampled_digest, spline_values
from phs.errors import InputDataError, SimulationError
from phs.params import TIME
from phs.signals import Constant, Piecewise, Sampled, Signal, as_signal


def input_signals(system, u, t) -> list[Signal]:
    """One signal per input of ``system`` from a user's specification ``u`` on the grid ``t``.

    ``u`` is a dict by input name (a bare value when the system has one input); missing inputs are
    zero.  Arrays are samples on ``t``, read as a continuous signal (``Sampled(t, values, hold="zoh")`` says
    they were held); a callable of ``t`` is turned into an expression when sympy
    can evaluate it, else sampled on ``t``; samples held by zero-order hold become a piecewise
    constant signal (its jumps are breakpoints).

    Raises
    ------
    InputDataError
        Naming an unknown input, an array of the wrong shape or an input that is not a signal.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> sigs = input_signals(rc_circuit(), {"U": "2*t"}, np.linspace(0, 1, 3))
    >>> float(sigs[0](0.5))
    1.0
    """
    s = system
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
            spec = held_signal(spec)
        try:
            out.append(as_signal(spec))
        except InputDataError as exc:
            raise InputDataError(f"input {name!r}: {exc}") from None
    return out


def held_signal(sg: Sampled) -> Signal:
    """The piecewise-constant signal of held samples ``sg`` (``hold="zoh"``): sample ``k``'s value from ``t[k]`` to
    ``t[k+1]``, switching only where the value changes (those are the integrator's restarts).

    Examples
    --------
    >>> sig = held_signal(Sampled((0.0, 1.0, 2.0, 3.0), (0.0, 0.0, 1.0, 1.0), hold="zoh"))
    >>> sig.breakpoints(0.0, 3.0).tolist(), float(sig(1.5)), float(sig(2.0))
    ([2.0], 0.0, 1.0)
    """
    tt, vals = sg.arrays
    change = np.flatnonzero(np.diff(vals) != 0) + 1
    if not len(change):
        return Constant(float(vals[0]))
    return Piecewise(tuple(tt[change].tolist()), tuple(vals[change].tolist()), float(vals[0]))


@dataclass(frozen=True, eq=False)
class Shifted(Signal):
    """``inner`` read on a time axis whose zero is ``origin``: ``Shifted(inner, origin)(t) = inner(t + origin)``.

    A simulation runs on the time from its grid's start (:func:`shifted`), so that a recording stamped at
    t = 1.7e9 s (a logger's epoch time) keeps its resolution: in absolute time a straight line's constants
    cancel to a few digits and CVODES cannot resolve a millisecond step at 1e7 s.

    Examples
    --------
    >>> from phs.signals import step
    >>> sg = Shifted(step(1.0, at=1000.5), 1000.0)
    >>> sg.breakpoints(0.0, 1.0).tolist(), float(sg(0.25)), float(sg(0.75))
    ([0.5], 0.0, 1.0)
    """

    inner: Signal
    origin: float

    def breakpoints(self, t0, t1) -> np.ndarray:
        return np.asarray(self.inner.breakpoints(t0 + self.origin, t1 + self.origin), dtype=float) - self.origin

    def expr_on(self, a, b) -> sp.Expr:
        e = self.inner.expr_on(a + self.origin, b + self.origin)  # a sympy expression (a plain number for a constant)
        return sp.Float(e) if isinstance(e, (int, float)) else e.xreplace({TIME: TIME + self.origin})

    def __call__(self, tt):
        return self.inner(np.asarray(tt, dtype=float) + self.origin)


def shifted(sg: Signal, origin: float) -> Signal:
    """The signal ``sg`` on a time axis whose zero is ``origin`` (:class:`Shifted`): samples move with their times
    (their kinks, straight stretches and interpolants stay exact), constants stay.

    Examples
    --------
    >>> shifted(Sampled((10.0, 11.0, 12.0), (0.0, 1.0, 0.0)), 10.0).times
    (0.0, 1.0, 2.0)
    """
    if origin == 0.0 or isinstance(sg, Constant):
        return sg
    if isinstance(sg, Sampled):
        return Sampled(tuple((sg.arrays[0] - origin).tolist()), sg.values, hold=sg.hold)
    return Shifted(sg, float(origin))


def initial_state(system, x0) -> np.ndarray:
    """Initial state vector of ``system`` from a dict by name or an array (default: each state at rest, ``StateInfo.initial``).

    Raises
    ------
    InputDataError
        Naming an unknown state, a non-finite value or a wrong number of values.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> initial_state(mass_spring_damper(), {"k.l": 0.5})
    array([0. , 0.5])
    """
    s = system
    base = np.array([st.initial for st in s.states])
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


def inputs_at(sigs, times) -> np.ndarray:
    """The signals ``sigs`` at ``times``: an array (len(times), len(sigs)).

    Examples
    --------
    >>> inputs_at([as_signal(1.0), as_signal("t")], np.array([0.0, 2.0]))
    array([[1., 0.],
           [1., 2.]])
    """
    if not sigs:
        return np.zeros((len(times), 0))
    return np.column_stack([np.broadcast_to(np.asarray(sg(times), dtype=float), times.shape) for sg in sigs])


def input_template(expr: sp.Expr):
    """Replace the numbers of an input expression by placeholders ``_c0, _c1, ...``: (key, template, values).

    Examples
    --------
    >>> key, tmpl, vals = input_template(sp.sympify("2.5*sin(3.0*t)"))
    >>> tmpl, vals
    (_c0*sin(_c1*t), [2.5, 3.0])
    """
    floats = sorted(expr.atoms(sp.Float), key=lambda f: sp.default_sort_key(f))
    if expr.is_Float:
        floats = [expr]
    ph = [sp.Symbol(f"_c{k}", real=True) for k in range(len(floats))]
    tmpl = expr.xreplace(dict(zip(floats, ph))) if not expr.is_Float else ph[0]
    key = sp.srepr(tmpl)
    return key, tmpl, [float(f) for f in floats]


_LINE = sp.Symbol("_c0", real=True) + sp.Symbol("_c1", real=True) * TIME
LINEAR_SLOT = (sp.srepr(_LINE), _LINE, 2)
"""The input template of a straight line ``_c0 + _c1 t`` as a slot ``(key, template, n_constants)``: a
piecewise-linear sampled input between two kinks (here and in identification's forward runs)."""


def baked(sg):
    """How a sampled input enters the integrator: ``(times, values)`` baked into an interpolant, or None
    when it is piecewise linear with few kinks (:meth:`phs.signals.Sampled.kinks`), which enters as a
    straight line between consecutive kinks (its breakpoints), its two constants in the integrator's
    parameters: the integrators then serve any such input, and a step never crosses a kink.  None also
    for an input that is not sampled.  An input with many kinks is baked even where it is a line over a
    long stretch (:meth:`phs.signals.Sampled.lines`): the segments of :func:`plan_segments` say where the
    interpolant is used.

    Examples
    --------
    >>> t = np.arange(5) * 0.1
    >>> baked(Sampled(tuple(t), (0.0, 0.0, 1.0, 1.0, 1.0))) is None
    True
    >>> len(baked(Sampled(tuple(np.arange(100) * 0.1), tuple(np.sin(np.arange(100.0))))))
    2
    """
    if not isinstance(sg, Sampled) or sg.kinks() is not None:
        return None
    return sg.arrays


def plan_segments(sigs, t, cuts=()):
    """Segments between the inputs' breakpoints on ``[t[0], t[-1]]`` and the input templates they use.

    A sampled input that is piecewise linear with few kinks (:meth:`phs.signals.Sampled.kinks`: a step,
    staircase or square wave as recorded) has its kinks as breakpoints: the integrator restarts there
    instead of stepping across one (:func:`codegen._grid.bounded_runs` then leaves the step free).  One
    with many kinks enters through its interpolant, except over its long straight stretches
    (:meth:`phs.signals.Sampled.lines`: the holds and ramps between the sines of a recording), whose ends
    are breakpoints and over which it is the line again.

    The first and last samples of a sampled input are breakpoints too: before and after them it holds its
    first and last values, a kink where its samples start late or stop early within the grid.

    ``cuts``: further times at which a segment must end (the windows of a multiple-shooting fit).

    Returns ``(segs, slots)``: ``segs`` a list of ``(a, b, choice)`` with ``choice[j]`` the index of
    input ``j``'s template in ``slots[j]`` and its constants (None where a sampled input enters through
    its interpolant), ``slots[j]`` the templates of input ``j`` as ``(key, template, n_constants)``.

    Examples
    --------
    >>> from phs.signals import step
    >>> segs, slots = plan_segments([step(1.0, at=0.5)], np.linspace(0.0, 1.0, 5))
    >>> [(a, b, c) for a, b, c in segs]
    [(0.0, 0.5, [(0, [0.0])]), (0.5, 1.0, [(0, [1.0])])]
    """
    t0, t1 = float(t[0]), float(t[-1])
    bps = sorted({float(b) for s in sigs if not isinstance(s, Sampled) for b in s.breakpoints(t0, t1)}
                 | {float(b) for s in sigs if isinstance(s, Sampled) and baked(s) is None for b in s.kinks()}
                 | {float(b) for s in sigs if isinstance(s, Sampled) for b in s.lines().reshape(-1)}
                 | {float(b) for s in sigs if isinstance(s, Sampled) for b in s.arrays[0][[0, -1]]}
                 | {float(b) for b in cuts})
    edges = [t0] + [b for b in bps if t0 < b < t1] + [t1]
    slots: list[list] = [[] for _ in sigs]  # per input: list of (key, template, n_constants)
    for j, s in enumerate(sigs):
        if isinstance(s, Sampled) and (baked(s) is None or len(s.lines())):
            slots[j].append(LINEAR_SLOT)
    segs = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b <= a:
            continue
        choice = []
        for j, s in enumerate(sigs):
            if isinstance(s, Sampled):
                if baked(s) is None or _on_line(s.lines(), 0.5 * (a + b)):  # u(a) + slope (t - a), numerically
                    ua, ub = float(s(a)), float(s(b))
                    slope = (ub - ua) / (b - a)
                    choice.append((0, [ua - slope * a, slope]))
                else:
                    choice.append(None)
                continue
            key, tmpl, vals = input_template(sp.sympify(s.expr_on(a, b)))
            keys = [k for k, _, _ in slots[j]]
            if key not in keys:
                slots[j].append((key, tmpl, len(vals)))
                keys.append(key)
            choice.append((keys.index(key), vals))
        segs.append((a, b, choice))
    return segs, slots


def run_sampled(sampled, choice, run=None) -> list:
    """The baked samples ``sampled`` (one entry per input, :func:`baked`) that a segment's ``choice`` uses:
    None for an input that enters the segment as a template (a line over one of its straight stretches too).
    For a ``run`` (:class:`codegen._output.OutputRun`) that interpolates its sampled inputs locally, each is
    the samples on the run's points alone with their digest and the kind ``"bspline"``
    (:func:`codegen._grid.bounded_runs`): the integrator's interpolant is the cubic spline of those samples.

    Examples
    --------
    >>> run_sampled([("grid", "values"), ("grid", "values")], [None, (0, [1.0, 0.0])])
    [('grid', 'values'), None]
    """
    out = [g if c is None else None for g, c in zip(sampled, choice, strict=True)]
    if run is None or not getattr(run, "local", False):
        return out
    return [g if g is None else _local(g, run) for g in out]


def _local(g, run) -> tuple:
    """The samples ``g`` (``(times, values, ...)``) of ``run``'s local span (:func:`codegen._grid.local_samples`),
    their digest and the kind ``"bspline"``."""
    span = run.local if isinstance(run.local, tuple) else (run.start, run.step, run.n)
    got = local_samples(g[0], g[1], *span)
    if got is None:  # bounded_runs made it local only where they are
        raise SimulationError("a locally interpolated run's points are not its input's samples")
    return (*got, digest(got) + ":local", "bspline")  # never the key of the whole signal's own interpolant


def _on_line(lines: np.ndarray, tm: float) -> bool:
    """Whether the time ``tm`` lies on one of the straight stretches ``lines`` (``(k, 2)``, sorted)."""
    i = int(np.searchsorted(lines[:, 0], tm, side="right")) - 1
    return i >= 0 and tm <= lines[i, 1]


def segment_inputs(sigs, slots, choice, times, cache: dict, max_step: float = 1.0) -> np.ndarray:
    """Inputs at ``times`` inside one segment, from the segment's templates and constants.

    ``cache`` keeps the templates' numpy functions by key across calls.  A sampled input that enters a run
    through its interpolant is evaluated through the one the run integrates it with
    (:func:`codegen._interpolants.interpolation`): between its samples a spline is not the straight line.

    Examples
    --------
    >>> from phs.signals import step
    >>> sigs = [step(1.0, at=0.5)]
    >>> segs, slots = plan_segments(sigs, np.linspace(0.0, 1.0, 5))
    >>> segment_inputs(sigs, slots, segs[1][2], np.array([0.75, 1.0]), {})
    array([[1.],
           [1.]])
    """
    out = np.empty((len(times), len(sigs)))
    for j, sg in enumerate(sigs):
        if isinstance(sg, Sampled):  # the samples themselves (a piecewise-linear one too: the same values)
            spline = choice[j] is None and interpolation(len(sg.arrays[0]), max_step) == "bspline"
            out[:, j] = _spline_values(sg, times) if spline else sg(times)
            continue
        k, vals = choice[j]
        key, tmpl, nc = slots[j][k]
        f = cache.get(key)
        if f is None:
            f = sp.lambdify([TIME] + [sp.Symbol(f"_c{i}", real=True) for i in range(nc)], tmpl, "numpy")
            cache[key] = f
        out[:, j] = np.broadcast_to(np.asarray(f(times, *vals), dtype=float), times.shape)
    return out



def _spline_values(sg, times) -> np.ndarray:
    """The B-spline interpolant of the samples of ``sg`` at ``times`` (the integrator's own)."""
    times = np.asarray(times, float)
    out = np.asarray(sg(times), dtype=float).reshape(-1)
    grid = sg.arrays[0]
    inside = (times > grid[0]) & (times < grid[-1])  # CasADi's B-spline is 0 on its last knot; the ends are samples
    if inside.any():
        out[inside] = spline_values(*sg.arrays, sampled_digest(sg), times[inside])
    return out
