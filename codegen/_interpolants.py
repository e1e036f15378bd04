"""Interpolants of sampled inputs, built once per process.

A sampled input enters the integrator through a CasADi interpolant of its samples: linear, or a cubic
B-spline where it is smooth enough for long steps (:func:`codegen._grid.step_windows`).  The inputs a
result reports at its output times are evaluated through the same interpolant
(:func:`codegen._inputs.segment_inputs`): an output that feeds the input through (a source's current
``(U − v_C) / R`` across a small resistance) reads the input the states were integrated with, also
between samples.
"""

from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np


def digest(arrays) -> str:
    """A digest of float arrays (the key of what is computed from their values).

    Examples
    --------
    >>> digest([np.zeros(3)]) == digest([np.zeros(3)]) != digest([np.ones(3)])
    True
    """
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()


def sampled_digest(sg) -> str:
    """The digest of a sampled signal's times and values, computed once and kept on the signal.

    Examples
    --------
    >>> from phs.signals import Sampled
    >>> sg = Sampled((0.0, 1.0), (0.0, 2.0))
    >>> sampled_digest(sg) == digest(sg.arrays)
    True
    """
    d = sg.__dict__.get("_digest")
    if d is None:
        d = digest(sg.arrays)
        object.__setattr__(sg, "_digest", d)
    return d


def interpolation(n_samples: int, max_step: float) -> str:
    """How a run of step bound ``max_step`` (in output intervals) interpolates a sampled input of
    ``n_samples`` samples that enters it through its interpolant: a cubic B-spline where the step may span
    several intervals (:func:`codegen._grid.step_windows`) and there are samples enough, else linearly.

    Examples
    --------
    >>> interpolation(10, 4.0), interpolation(10, 1.0), interpolation(5, 4.0)
    ('bspline', 'linear', 'linear')
    """
    return "bspline" if max_step > 1 and n_samples >= 8 else "linear"


def _digest(g) -> str:
    """A digest of sampled times and values ``g`` (the key of the integrators that interpolate them)."""
    return digest(g[:2])


_INTERPOLANTS: dict = {}
"""Interpolants of sampled inputs by (samples' digest, kind), shared by every simulator of the process: a
diagnosis simulates the same recording through many models (a B-spline through 20 000 samples takes
~15 ms to build).  Bounded by :data:`_INTERPOLANTS_KEPT` (the oldest dropped first)."""
_INTERPOLANTS_KEPT = 64


def _interpolant(grid, values, kind: str, digest: str):
    """The CasADi interpolant of ``kind`` through the samples ``(grid, values)`` with digest ``digest``,
    built once per process (:data:`_INTERPOLANTS`), holding the first and last samples' values before and
    after them, as the samples themselves do (:meth:`phs.signals.Sampled.__call__`, the inputs a result
    reports): CasADi's own interpolants extrapolate (linearly, or to zero for a B-spline), so an input
    recorded by a converter that started late or stopped early drove the integration by a course it never
    had (an RLC circuit fed a multisine whose samples end 10 % before the grid was off by 11 % of its flux's
    range at the end).

    Examples
    --------
    >>> g = np.arange(4.0); v = np.array([0.0, 1.0, 0.0, 2.0])
    >>> f = _interpolant(g, v, "linear", _digest((g, v)))
    >>> float(f(2.5)), _interpolant(g, v, "linear", _digest((g, v))) is f
    (1.0, True)
    >>> float(f(-1.0)), float(f(5.0))          # held beyond the samples, not extrapolated
    (0.0, 2.0)
    """
    key = (digest, kind)
    hit = _INTERPOLANTS.get(key)
    if hit is None:
        grid = np.asarray(grid, dtype=float)
        raw = ca.interpolant(f"u_{kind}_{digest[:16]}", kind, [grid], np.asarray(values, dtype=float))
        tt = ca.SX.sym("t")
        hit = ca.Function(f"u_{kind}_{digest[:16]}_held", [tt], [raw(ca.fmin(ca.fmax(tt, grid[0]), grid[-1]))])
        if len(_INTERPOLANTS) >= _INTERPOLANTS_KEPT:
            _INTERPOLANTS.pop(next(iter(_INTERPOLANTS)))
        _INTERPOLANTS[key] = hit
    return hit
