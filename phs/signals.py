"""Input signals: piecewise-smooth functions of time with known breakpoints.

Every signal knows where it (or its derivative) jumps, so simulators restart
their integrator exactly there instead of stepping blindly over an edge.
Between breakpoints a signal is a sympy expression of time ``t``.

Examples
--------
>>> sq = square(5000.0, frequency=2.0)
>>> sq.breakpoints(0.0, 1.0).tolist()
[0.25, 0.5, 0.75]
>>> float(sq(0.3)), float(sq(0.1))
(-5000.0, 5000.0)
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from numbers import Real

import numpy as np
import sympy as sp

from phs.errors import InputDataError
from phs.kinks import KINK_SHARE, LINE_RUN, curved_stretches, held_between_samples, linear_kinks, straight_stretches  # noqa: F401 - re-exported
from phs.params import TIME
from phs.safe_parse import Arithmetic, Refusal, evaluate

t = TIME
_MAX_SWITCHES = 1_000_000  # switching times of one signal over one simulated interval


class Signal:
    """Base class: a piecewise-smooth scalar function of time."""

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Sorted times strictly inside (t0, t1) where the signal or its derivative jumps."""
        return np.empty(0)

    def expr_on(self, a: float, b: float) -> sp.Expr:
        """Sympy expression of ``t`` valid on the open interval (a, b) between breakpoints."""
        raise NotImplementedError

    def __call__(self, tt):
        tt = np.asarray(tt, dtype=float)
        out = np.empty_like(tt)
        flat = tt.reshape(-1)
        res = out.reshape(-1)
        lo, hi = float(flat.min()), float(flat.max())
        bps = np.concatenate([[-np.inf], self.breakpoints(lo - 1.0, hi + 1.0), [np.inf]])
        for a, b in zip(bps[:-1], bps[1:]):
            sel = (flat >= a) & (flat < b)
            if np.any(sel):
                aa = a if np.isfinite(a) else lo - 1.0
                bb = b if np.isfinite(b) else hi + 1.0
                f = sp.lambdify(TIME, self.expr_on(aa, bb), "numpy")
                res[sel] = np.broadcast_to(f(flat[sel]), flat[sel].shape)
        return out if out.shape else float(out)

    # arithmetic -------------------------------------------------------------------
    def __add__(self, other):
        return Combined((self, as_signal(other)), "+")

    __radd__ = __add__

    def __mul__(self, other):
        return Combined((self, as_signal(other)), "*")

    __rmul__ = __mul__

    def __neg__(self):
        return Combined((self, Constant(-1.0)), "*")

    def __sub__(self, other):
        return self + (-as_signal(other))


@dataclass(frozen=True)
class Constant(Signal):
    """A constant value.

    Examples
    --------
    >>> Constant(3.0).expr_on(0, 1)
    3.00000000000000
    """

    value: float

    def expr_on(self, a, b) -> sp.Expr:
        return sp.Float(self.value)


@dataclass(frozen=True)
class Expression(Signal):
    """A smooth sympy expression of ``t`` (e.g. ``5000*sin(2*pi*t)``); Heaviside and
    Piecewise inside it contribute their switching times as breakpoints.

    Examples
    --------
    >>> Expression(sp.Heaviside(t - 1) * 2).breakpoints(0, 5).tolist()
    [1.0]
    """

    expr: sp.Expr

    def __post_init__(self):
        extra = self.expr.free_symbols - {TIME}
        if extra:
            raise InputDataError(f"input expression {self.expr} uses unknown symbols {sorted(map(str, extra))}; only t is allowed")

    def breakpoints(self, t0, t1) -> np.ndarray:
        pts = set()
        for node in sp.preorder_traversal(self.expr):
            args = []
            if isinstance(node, (sp.Heaviside, sp.sign, sp.Abs)):
                args = [node.args[0]]
            elif isinstance(node, sp.Piecewise):
                for _, c in node.args:
                    if isinstance(c, sp.core.relational.Relational):
                        args.append(c.lhs - c.rhs)
            for a in args:
                pts.update(r for r in _zeros(a, t0, t1) if t0 < r < t1)
        return np.array(sorted(pts))

    def expr_on(self, a, b) -> sp.Expr:
        mid = (a + b) / 2
        e = self.expr
        repl = {}
        for node in sp.preorder_traversal(e):
            if isinstance(node, sp.Heaviside):
                repl[node] = sp.Float(1.0 if float(node.args[0].subs(TIME, mid)) > 0 else 0.0)
            elif isinstance(node, sp.sign):
                repl[node] = sp.Float(math.copysign(1.0, float(node.args[0].subs(TIME, mid))))
        e = e.xreplace(repl)
        if e.has(sp.Piecewise):
            e = e.replace(lambda n: isinstance(n, sp.Piecewise), lambda n: _pick(n, mid))
        return e


_SCAN_POINTS = 4001  # grid of the numeric search for switching times


def _zeros(a: sp.Expr, t0: float, t1: float) -> list[float]:
    """Zeros of ``a(t)`` in (t0, t1): exact for a polynomial of degree <= 4 in t, else where a sampled
    grid of the interval sees the sign change (refined by bisection), so the search is bounded in time."""
    if a.is_polynomial(TIME) and sp.degree(a, TIME) <= 4:
        return [float(r) for r in sp.solve(a, TIME) if r.is_real]
    from scipy.optimize import brentq

    f = sp.lambdify(TIME, a, "numpy")
    grid = np.linspace(t0, t1, _SCAN_POINTS)
    with np.errstate(all="ignore"):
        v = np.broadcast_to(np.asarray(f(grid), dtype=complex).real, grid.shape)
    out = [float(x) for x, y in zip(grid, v) if y == 0]
    for i in np.flatnonzero(np.isfinite(v[:-1]) & np.isfinite(v[1:]) & (np.sign(v[:-1]) * np.sign(v[1:]) < 0)):
        out.append(brentq(lambda x: float(np.real(f(x))), grid[i], grid[i + 1], xtol=1e-14))
    return out


def _pick(pw: sp.Piecewise, mid: float) -> sp.Expr:
    for val, cond in pw.args:
        if cond == sp.true or bool(cond.subs(TIME, mid)):
            return val
    return sp.nan


@dataclass(frozen=True)
class Piecewise(Signal):
    """Values held between switching times: ``levels[k]`` on ``[times[k], times[k+1])``.

    ``initial`` applies before ``times[0]`` (default ``levels[0]``).

    Examples
    --------
    >>> s = Piecewise((0.0, 2.0, 4.0), (0.0, -1000.0, -2000.0))
    >>> float(s(3.0))
    -1000.0
    """

    times: tuple
    levels: tuple
    initial: float | None = None

    def __post_init__(self):
        if len(self.times) != len(self.levels) or not self.times:
            raise InputDataError("piecewise signal: times and levels must be non-empty and of equal length")
        if any(b <= a for a, b in zip(self.times, self.times[1:])):
            raise InputDataError("piecewise signal: switching times must be strictly increasing")

    def _before(self) -> float:
        return self.levels[0] if self.initial is None else self.initial

    def breakpoints(self, t0, t1) -> np.ndarray:
        prev = [self._before()] + list(self.levels[:-1])
        return np.array([x for x, a, b in zip(self.times, prev, self.levels) if t0 < x < t1 and a != b], dtype=float)

    def expr_on(self, a, b) -> sp.Expr:
        k = int(np.searchsorted(np.asarray(self.times), (a + b) / 2, side="right")) - 1
        return sp.Float(self._before() if k < 0 else self.levels[k])


@dataclass(frozen=True)
class Periodic(Signal):
    """A periodic square/pulse wave: ``high`` for ``duty*period`` then ``low``, from ``start``.

    Examples
    --------
    >>> w = Periodic(high=1.0, low=0.0, period=1.0, duty=0.25)
    >>> w.breakpoints(0, 2).tolist()
    [0.25, 1.0, 1.25]
    """

    high: float
    low: float
    period: float
    duty: float = 0.5
    start: float = 0.0
    before: float | None = None

    def __post_init__(self):
        if not self.period > 0 or not 0 < self.duty < 1:
            raise InputDataError(f"periodic signal: period must be > 0 and 0 < duty < 1 (got {self.period}, {self.duty})")

    def breakpoints(self, t0, t1) -> np.ndarray:
        if t1 <= self.start:
            return np.empty(0)
        if (t1 - max(t0, self.start)) / self.period > _MAX_SWITCHES / 2:
            raise InputDataError(f"periodic signal: more than {_MAX_SWITCHES} switching times between t = {t0:g} and "
                                 f"{t1:g} (period {self.period:g})")
        k0 = max(0, math.floor((max(t0, self.start) - self.start) / self.period) - 1)
        pts = []
        k = k0
        while True:
            base = self.start + k * self.period
            if base >= t1:
                break
            for x in (base, base + self.duty * self.period):
                if t0 < x < t1 and (x > self.start or self.before is not None):
                    pts.append(x)
            k += 1
        return np.array(sorted(set(pts)))

    def expr_on(self, a, b) -> sp.Expr:
        mid = (a + b) / 2
        if mid < self.start:
            return sp.Float(self.before if self.before is not None else self.high)
        phase = ((mid - self.start) / self.period) % 1.0
        return sp.Float(self.high if phase < self.duty else self.low)


@dataclass(frozen=True)
class Combined(Signal):
    """Sum or product of signals (breakpoints are the union)."""

    parts: tuple
    op: str

    def breakpoints(self, t0, t1) -> np.ndarray:
        pts = np.concatenate([p.breakpoints(t0, t1) for p in self.parts])
        return np.unique(pts)

    def expr_on(self, a, b) -> sp.Expr:
        es = [p.expr_on(a, b) for p in self.parts]
        return sp.Add(*es) if self.op == "+" else sp.Mul(*es)


# -- constructors ---------------------------------------------------------------------
def step(amplitude: float, at: float = 0.0, before: float = 0.0) -> Signal:
    """Step from ``before`` to ``amplitude`` at time ``at``.

    Examples
    --------
    >>> float(step(5000.0, at=0.1)(0.2))
    5000.0
    """
    return Piecewise((float(at),), (float(amplitude),), float(before))


def square(amplitude: float, frequency: float, duty: float = 0.5, offset: float = 0.0, bipolar: bool = True,
           start: float = 0.0) -> Signal:
    """Square wave: ``offset +- amplitude`` (bipolar) or ``offset + {amplitude, 0}`` (unipolar).

    Examples
    --------
    >>> float(square(1.0, 1.0, bipolar=False)(0.75))
    0.0
    """
    if not frequency > 0:
        raise InputDataError(f"square wave: frequency must be positive, got {frequency}")
    high = offset + amplitude
    low = offset - amplitude if bipolar else offset
    return Periodic(high, low, 1.0 / frequency, duty, start, before=offset if start > 0 else None)


def staircase(step_height: float, every: float, n_steps: int, start: float = 0.0, initial: float = 0.0) -> Signal:
    """Staircase of ``n_steps`` equal steps every ``every`` seconds (a negative height goes down).

    Examples
    --------
    >>> s = staircase(-1000.0, every=2.0, n_steps=3, start=1.0)
    >>> [float(s(x)) for x in (0.5, 1.5, 3.5, 5.5, 9.0)]
    [0.0, -1000.0, -2000.0, -3000.0, -3000.0]
    """
    if not 0 <= n_steps <= _MAX_SWITCHES:
        raise InputDataError(f"staircase: the number of steps must be between 0 and {_MAX_SWITCHES}, got {n_steps}")
    times = tuple(start + k * every for k in range(n_steps))
    levels = tuple(initial + (k + 1) * step_height for k in range(n_steps))
    return Piecewise(times, levels, float(initial))


def sine(amplitude: float, frequency: float, phase: float = 0.0, offset: float = 0.0) -> Signal:
    """``offset + amplitude * sin(2 pi f t + phase)``.

    Examples
    --------
    >>> round(float(sine(2.0, 1.0)(0.25)), 12)
    2.0
    """
    return Expression(sp.Float(offset) + sp.Float(amplitude) * sp.sin(2 * sp.pi * sp.Float(frequency) * TIME + sp.Float(phase)))


def chirp(amplitude: float, f0: float, f1: float, duration: float, offset: float = 0.0) -> Signal:
    """Linear chirp from ``f0`` to ``f1`` Hz over ``duration`` seconds.

    Examples
    --------
    >>> abs(float(chirp(1.0, 1.0, 10.0, 5.0)(0.0))) < 1e-12
    True
    """
    k = (f1 - f0) / duration
    return Expression(sp.Float(offset) + sp.Float(amplitude) * sp.sin(2 * sp.pi * (sp.Float(f0) * TIME + sp.Float(k / 2) * TIME**2)))


def exponential_chirp(amplitude: float, f0: float, f1: float, duration: float, offset: float = 0.0) -> Signal:
    """Exponential (logarithmic) chirp from ``f0`` to ``f1`` Hz over ``duration`` seconds (Novak et al.).

    ``s(t) = offset + amplitude sin(2 pi f0 L (exp(t / L) - 1))`` with ``L = duration / ln(f1 / f0)``:
    the instantaneous frequency ``f0 exp(t / L)`` grows by the same factor in equal times and
    reaches ``f1`` at ``t = duration``; each octave gets the same time.

    Raises
    ------
    InputDataError
        Unless ``0 < f0``, ``0 < f1``, ``f0 != f1`` and ``duration > 0``.

    Examples
    --------
    >>> s = exponential_chirp(1.0, 0.01, 5.0, 1800.0)
    >>> L = 1800.0 / math.log(5.0 / 0.01)
    >>> float(s(0.0)) == 0.0, round(float(s(100.0)) - math.sin(2 * math.pi * 0.01 * L * math.expm1(100.0 / L)), 12)
    (True, 0.0)
    """
    if not (f0 > 0 and f1 > 0 and f0 != f1 and duration > 0):
        raise InputDataError(f"exponential chirp: need 0 < f0 != f1 and duration > 0, got f0={f0}, f1={f1}, "
                             f"duration={duration}")
    L = duration / math.log(f1 / f0)
    phase = 2 * sp.pi * sp.Float(f0 * L) * (sp.exp(TIME / sp.Float(L)) - 1)
    return Expression(sp.Float(offset) + sp.Float(amplitude) * sp.sin(phase))


HOLDS = ("linear", "zoh", "auto")
"""How a sampled signal behaves between its samples (:class:`Sampled`)."""


@dataclass(frozen=True)
class Sampled(Signal):
    """Samples on a time grid, linearly interpolated (``hold="linear"``) or held (``"zoh"``).

    ``hold`` says how the signal behaves between samples: ``"linear"``, a continuous signal sampled by a sensor
    (interpolated: straight lines between its kinks, a cubic spline over its smooth stretches, see
    :func:`codegen._grid.step_windows`); ``"zoh"``, a command held by a DAC (sample ``k``'s value from ``t[k]`` to
    ``t[k+1]``); ``"auto"``, held when the samples look held (:func:`phs.kinks.held_between_samples`: isolated
    jumps between flat stretches), else linear, resolved when the signal is made (``held_ambiguous`` then says
    whether that reading was ambiguous).  Recordings read an undeclared input as ``"linear"``
    (:meth:`phs.workflows.recording.Recording.input_signal`).

    Examples
    --------
    >>> s = Sampled((0.0, 1.0, 2.0), (0.0, 2.0, 0.0))
    >>> float(s(0.5))
    1.0
    >>> t = tuple(np.arange(30) * 0.1)
    >>> Sampled(t, tuple([0.0] * 10 + [1.0] * 20), hold="auto").hold
    'zoh'
    """

    times: tuple
    values: tuple
    hold: str = "linear"

    def __post_init__(self):
        tt = np.asarray(self.times, dtype=float)
        vv = np.asarray(self.values, dtype=float)
        if tt.ndim != 1 or tt.shape != vv.shape or len(tt) < 2:
            raise InputDataError("sampled signal: times and values must be 1-D arrays of equal length >= 2")
        if not np.all(np.isfinite(vv)):
            i = int(np.argmin(np.isfinite(vv)))
            raise InputDataError(f"sampled signal: value at index {i} (t={tt[i]}) is not finite")
        if np.any(np.diff(tt) <= 0):
            i = int(np.argmax(np.diff(tt) <= 0)) + 1
            raise InputDataError(f"sampled signal: time is not strictly increasing at index {i} (t={tt[i]})")
        if self.hold not in HOLDS:
            raise InputDataError(f"sampled signal: hold must be one of {', '.join(map(repr, HOLDS))}, not {self.hold!r}")
        ambiguous = False
        if self.hold == "auto":
            held, ambiguous = held_between_samples(vv)
            object.__setattr__(self, "hold", "zoh" if held else "linear")
        object.__setattr__(self, "held_ambiguous", ambiguous)

        # the samples as arrays, once (a recording's input is evaluated segment by segment)
        object.__setattr__(self, "_t", tt)
        object.__setattr__(self, "_v", vv)

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The sample times and values as float arrays (computed once)."""
        return self._t, self._v

    def kinks(self) -> np.ndarray | None:
        """The times of the linear interpolant's kinks (:func:`linear_kinks`) when it is piecewise linear
        with few of them (at most :data:`~phs.kinks.KINK_SHARE` of the intervals, or 20): a step, staircase, square
        wave or ramp table as sampled.  None for many kinks (a sine, noise), for held samples and for uniform
        samples that hold a curved stretch among few kinks (:func:`~phs.kinks.curved_stretches`: a raised-cosine
        edge between holds), which the simulator integrates through the spline of the stretch's own samples.
        Computed once.

        Examples
        --------
        >>> Sampled((0.0, 0.1, 0.2, 0.3), (0.0, 0.0, 1.0, 1.0)).kinks().tolist()
        [0.1, 0.2]
        >>> Sampled((0.0, 0.1, 0.2, 0.3), (0.0, 0.0, 1.0, 1.0), hold="zoh").kinks() is None
        True
        """
        if "_kinks" not in self.__dict__:
            k = linear_kinks(self._v, self._t) if self.hold == "linear" else None
            few = k is not None and len(k) <= max(20, KINK_SHARE * (len(self._v) - 1))
            # a curved stretch (a kink at every sample of a smooth edge) is not piecewise linear (codegen._grid.bounded_runs)
            h = np.diff(self._t)
            few = few and not (len(h) and np.ptp(h) <= 1e-6 * np.mean(h) and curved_stretches(self._v, k))
            object.__setattr__(self, "_kinks", self._t[k] if few else None)
        return self.__dict__["_kinks"]

    def lines(self) -> np.ndarray:
        """``(k, 2)`` start and end times of the stretches of at least :data:`~phs.kinks.LINE_RUN` intervals over which
        the linear interpolant of samples with many kinks (:meth:`kinks` is None) is one straight line: the
        holds and ramps of a recording that also holds a sine or a chirp.  Empty for samples with few kinks
        (they are lines between their kinks everywhere), for held samples and when no stretch is that long.
        Computed once.

        Examples
        --------
        >>> t = np.arange(200) * 1e-3
        >>> v = np.where(t < 0.1, 0.0, np.sin(300 * t))     # a hold, then a sine
        >>> Sampled(tuple(t), tuple(v)).lines().tolist()
        [[0.0, 0.099]]
        """
        if "_lines" not in self.__dict__:
            out = np.zeros((0, 2))
            if self.hold == "linear" and self.kinks() is None:
                ab = straight_stretches(linear_kinks(self._v, self._t), len(self._v))
                out = self._t[np.array(ab, dtype=int).reshape(-1, 2)]
            object.__setattr__(self, "_lines", out)
        return self.__dict__["_lines"]

    def __call__(self, tt):
        tt = np.asarray(tt, dtype=float)
        ts, vs = self._t, self._v
        if self.hold == "linear":
            return np.interp(tt, ts, vs)
        idx = np.clip(np.searchsorted(ts, tt, side="right") - 1, 0, len(ts) - 1)
        return vs[idx]


def as_signal(spec) -> Signal:
    """Turn a number, sympy expression, string or Signal into a Signal.

    Examples
    --------
    >>> as_signal("5000*sin(2*pi*t)").expr_on(0, 1)
    5000*sin(2*pi*t)
    """
    if isinstance(spec, Signal):
        return spec
    if isinstance(spec, Real) and not isinstance(spec, bool):
        if not math.isfinite(spec):
            raise InputDataError(f"input value {spec} is not finite")
        return Constant(float(spec))
    if isinstance(spec, str):
        return parse_expression(spec)
    if isinstance(spec, sp.Expr):
        return Expression(spec) if spec.free_symbols else Constant(float(spec))
    raise InputDataError(f"cannot use {type(spec).__name__} as an input signal")


_FUNCS = {"square": square, "step": step, "staircase": staircase, "sine": sine, "chirp": chirp,
          "exponential_chirp": exponential_chirp}
_MATH = {"sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt, "tanh": sp.tanh,
         "sinh": sp.sinh, "cosh": sp.cosh, "abs": sp.Abs, "Abs": sp.Abs, "sign": sp.sign, "Heaviside": sp.Heaviside,
         "atan": sp.atan, "asin": sp.asin, "acos": sp.acos}
_MAX_INPUT_LENGTH = 2000


class _InputArithmetic(Arithmetic):
    """Values of an input expression: sympy expressions of ``t``, or signals built by ``square(...)`` etc."""

    operators = frozenset({"+", "-", "*", "/", "**", "%"})

    def __init__(self):
        super().__init__({"t": TIME, "pi": sp.pi}, {**_MATH, **_FUNCS},
                         hint=f" (allowed: t, pi, {', '.join(sorted(_MATH))}, {', '.join(_FUNCS)})")

    def keywords(self, name):
        return frozenset(inspect.signature(_FUNCS[name]).parameters) if name in _FUNCS else frozenset()

    def call(self, name, args, kwargs):
        if name not in _FUNCS:
            if any(isinstance(a, Signal) for a in args):
                raise Refusal(f"{name}() takes numbers or expressions of t, not a signal")
            return super().call(name, args, kwargs)
        values = [_constant(a, name) for a in args]
        options = {k: v if isinstance(v, bool) else _constant(v, name) for k, v in kwargs.items()}
        try:
            return _FUNCS[name](*values, **options)
        except (InputDataError, TypeError, ValueError, ArithmeticError) as exc:
            raise Refusal(f"{name}(): {exc}") from None

    def binary(self, op, a, b):
        if not isinstance(a, Signal) and not isinstance(b, Signal):
            return super().binary(op, a, b)
        if op == "/" and not isinstance(b, Signal):
            divisor = _constant(b, "a signal's divisor")
            if divisor == 0:
                raise Refusal("division by zero")
            return as_signal(a) * (1.0 / divisor)
        if op not in ("+", "-", "*"):
            raise Refusal(f"signals can be added, subtracted, multiplied and divided by a number, not combined with {op}")
        a, b = as_signal(a), as_signal(b)
        return a + b if op == "+" else a - b if op == "-" else a * b


def _shown(value) -> str:
    text = str(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _constant(value, name: str) -> float | int:
    """A finite float (an int for an integer) from a value of the expression that must be a number."""
    if isinstance(value, Signal) or not isinstance(value, sp.Basic) or value.free_symbols:
        raise Refusal(f"{name}() takes numbers, not {'a signal' if isinstance(value, Signal) else _shown(value)}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise Refusal(f"{_shown(value)} is not a real number") from None
    if not math.isfinite(number):
        raise Refusal(f"{_shown(value)} is not a finite number")
    return int(value) if value.is_Integer else number


def parse_expression(text: str) -> Signal:
    """Parse an input expression of ``t``; ``square(...)``, ``step(...)``, ``staircase(...)``,
    ``sine(...)``, ``chirp(...)`` build signals with breakpoints and may be scaled or added.

    The text is read by :mod:`phs.safe_parse` (numbers, ``t``, ``pi``, ``+ - * / ** %``
    and calls of the functions above; nothing is evaluated as Python), numbers must be
    finite and exponents bounded.

    Raises
    ------
    InputDataError
        Naming the expression when it cannot be read, uses unknown names, divides
        by zero, or is not a finite real number.

    Examples
    --------
    >>> s = parse_expression("2500 + square(2500, 2)")
    >>> float(s(0.1)), float(s(0.3))
    (5000.0, 0.0)
    >>> try:
    ...     parse_expression("log(0)")
    ... except InputDataError as err:
    ...     print(err)
    input expression 'log(0)': log(0) is not finite
    """
    where = f"input expression {text!r}" if len(str(text)) <= 60 else "input expression"
    value = evaluate(text, where, _InputArithmetic(), max_length=_MAX_INPUT_LENGTH)
    if isinstance(value, Signal):
        return value
    if value.has(sp.I):
        raise InputDataError(f"{where}: {_shown(value)} is not real")
    if value.free_symbols:
        return Expression(value)
    try:
        return Constant(float(_constant(value, "an input")))
    except Refusal as exc:
        raise InputDataError(f"{where}: {exc}") from None
