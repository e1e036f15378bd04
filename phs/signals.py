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

import math
from dataclasses import dataclass
from numbers import Real

import numpy as np
import sympy as sp

from phs.errors import InputDataError
from phs.params import TIME

t = TIME


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

    def expr_on(self, a, b):
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

    def breakpoints(self, t0, t1):
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
                try:
                    for r in sp.solve(a, TIME):
                        if r.is_real and t0 < float(r) < t1:
                            pts.add(float(r))
                except NotImplementedError:
                    continue
        return np.array(sorted(pts))

    def expr_on(self, a, b):
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

    def breakpoints(self, t0, t1):
        prev = [self._before()] + list(self.levels[:-1])
        return np.array([x for x, a, b in zip(self.times, prev, self.levels) if t0 < x < t1 and a != b], dtype=float)

    def expr_on(self, a, b):
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

    def breakpoints(self, t0, t1):
        if t1 <= self.start:
            return np.empty(0)
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

    def expr_on(self, a, b):
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

    def breakpoints(self, t0, t1):
        pts = np.concatenate([p.breakpoints(t0, t1) for p in self.parts])
        return np.unique(pts)

    def expr_on(self, a, b):
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


@dataclass(frozen=True)
class Sampled(Signal):
    """Samples on a time grid, linearly interpolated (``hold="linear"``) or held (``"zoh"``).

    Examples
    --------
    >>> s = Sampled((0.0, 1.0, 2.0), (0.0, 2.0, 0.0))
    >>> float(s(0.5))
    1.0
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
        if self.hold not in ("linear", "zoh"):
            raise InputDataError(f"sampled signal: hold must be 'linear' or 'zoh', not {self.hold!r}")

    def __call__(self, tt):
        tt = np.asarray(tt, dtype=float)
        ts, vs = np.asarray(self.times), np.asarray(self.values)
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


def parse_expression(text: str) -> Signal:
    """Parse an input expression of ``t``; ``square(...)``, ``step(...)``, ``staircase(...)``,
    ``sine(...)``, ``chirp(...)`` build signals with breakpoints and may be scaled or added.

    Raises
    ------
    InputDataError
        Naming the expression when it cannot be read or uses unknown names.

    Examples
    --------
    >>> s = parse_expression("2500 + square(2500, 2)")
    >>> float(s(0.1)), float(s(0.3))
    (5000.0, 0.0)
    """
    import ast

    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise InputDataError(f"cannot read input expression {text!r}: {exc.msg}") from None
    allowed_nodes = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Call, ast.Name, ast.Load, ast.Constant, ast.keyword,
                     ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.USub, ast.UAdd, ast.Mod)
    names = set(_FUNCS) | set(_MATH) | {"t", "pi"}
    for n in ast.walk(tree):  # checked before anything is evaluated
        if isinstance(n, ast.Attribute):
            raise InputDataError(f"input expression {text!r}: attribute access is not allowed")
        if not isinstance(n, allowed_nodes):
            raise InputDataError(f"input expression {text!r}: {type(n).__name__} is not allowed")
        if isinstance(n, ast.Name) and n.id not in names:
            raise InputDataError(f"input expression {text!r}: unknown name {n.id!r} "
                                 f"(allowed: t, pi, {', '.join(sorted(_MATH))}, {', '.join(_FUNCS)})")
        if isinstance(n, ast.Constant) and not isinstance(n.value, (int, float)):
            raise InputDataError(f"input expression {text!r}: only numbers are allowed as constants")
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in _FUNCS]
    if not calls:
        try:
            e = sp.sympify(text, locals={"t": TIME, "pi": sp.pi, **_MATH})
        except (sp.SympifyError, SyntaxError, TypeError, ValueError) as exc:
            raise InputDataError(f"cannot read input expression {text!r}: {exc}") from None
        if e.free_symbols - {TIME}:
            raise InputDataError(f"input expression {text!r}: unknown symbols {sorted(map(str, e.free_symbols - {TIME}))}")
        if not e.free_symbols and not sp.Float(e).is_finite:
            raise InputDataError(f"input expression {text!r} is not a finite number")
        return as_signal(e)
    env = {k: v for k, v in _FUNCS.items()}
    env.update({"pi": math.pi, "__builtins__": {}})
    for n in ast.walk(tree):
        if isinstance(n, ast.Name) and n.id not in env:
            raise InputDataError(f"input expression {text!r}: {n.id!r} cannot be combined with "
                                 f"{', '.join(_FUNCS)} (use numbers and those functions)")
    try:
        val = eval(compile(tree, "<input>", "eval"), env)  # names restricted above
    except (TypeError, ValueError, ZeroDivisionError, InputDataError) as exc:
        raise InputDataError(f"cannot evaluate input expression {text!r}: {exc}") from None
    return as_signal(val)
