"""Straight lines between knots: a signal whose knots are its breakpoints, and the kinks of sampled values.

A sampled step, staircase, square wave or ramp table is piecewise linear with a few kinks.  Given as
:class:`PiecewiseLinear` (for instance by :func:`from_samples`), a simulation restarts at the kinks and
steps freely in between, where the sampled interpolant holds it to about one step per sample.

Examples
--------
>>> s = PiecewiseLinear((0.0, 1.0, 3.0), (0.0, 2.0, 0.0))
>>> s.breakpoints(0.0, 3.0).tolist()
[1.0]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from phs.errors import InputDataError
from phs.kinks import linear_kinks  # noqa: F401 - linear_kinks is used and re-exported here
from phs.params import TIME
from phs.signals import Sampled, Signal


@dataclass(frozen=True)
class PiecewiseLinear(Signal):
    """Straight lines between knots ``(times[k], values[k])``; held at the end values outside.

    Its knots are its breakpoints, so a simulation restarts there and steps freely in between.

    Examples
    --------
    >>> s = PiecewiseLinear((0.0, 1.0, 3.0), (0.0, 2.0, 0.0))
    >>> float(s(0.5)), float(s(2.0)), s.breakpoints(0.0, 3.0).tolist()
    (1.0, 1.0, [1.0])
    >>> s.expr_on(1.0, 3.0)
    3.0 - 1.0*t
    """

    times: tuple
    values: tuple

    def __post_init__(self):
        tt = np.asarray(self.times, dtype=float)
        vv = np.asarray(self.values, dtype=float)
        if tt.ndim != 1 or tt.shape != vv.shape or len(tt) < 2:
            raise InputDataError("piecewise-linear signal: times and values must be 1-D of equal length >= 2")
        if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(vv))):
            raise InputDataError("piecewise-linear signal: a knot is not finite")
        if np.any(np.diff(tt) <= 0):
            raise InputDataError("piecewise-linear signal: knot times must be strictly increasing")
        object.__setattr__(self, "_t", tt)
        object.__setattr__(self, "_v", vv)

    def breakpoints(self, t0, t1) -> np.ndarray:
        return self._t[(self._t > t0) & (self._t < t1)]

    def expr_on(self, a, b) -> sp.Expr:
        ts, vs = self._t, self._v
        k = int(np.clip(np.searchsorted(ts, (a + b) / 2, side="right") - 1, 0, len(ts) - 2))
        if (a + b) / 2 < ts[0] or (a + b) / 2 > ts[-1]:
            return sp.Float(float(vs[0] if (a + b) / 2 < ts[0] else vs[-1]))
        slope = float((vs[k + 1] - vs[k]) / (ts[k + 1] - ts[k]))
        if slope == 0.0:
            return sp.Float(float(vs[k]))
        return sp.Float(float(vs[k] - slope * ts[k])) + sp.Float(slope) * TIME

    def __call__(self, tt):
        tt = np.asarray(tt, dtype=float)
        out = np.interp(tt, self._t, self._v)
        return out if out.shape else float(out)


def from_samples(sampled: Sampled, max_share: float = 0.05, at_least: int = 20) -> PiecewiseLinear | None:
    """The linear interpolant of ``sampled`` as a :class:`PiecewiseLinear` signal with knots at its kinks
    only, when it has few (at most ``max(at_least, max_share * intervals)``); else None (also for held samples).

    Examples
    --------
    >>> tt = np.arange(6) * 0.1
    >>> s = from_samples(Sampled(tuple(tt), (0.0, 0.0, 1.0, 1.0, 1.0, 1.0)))
    >>> [round(x, 9) for x in s.times]
    [0.0, 0.1, 0.2, 0.5]
    >>> round(float(s(0.15)), 12)
    0.5
    """
    if sampled.hold != "linear":
        return None
    t, v = sampled.arrays
    k = linear_kinks(v, t)
    if len(k) > max(at_least, max_share * (len(v) - 1)):
        return None
    idx = [0] + k + [len(v) - 1]
    return PiecewiseLinear(tuple(t[idx].tolist()), tuple(v[idx].tolist()))
