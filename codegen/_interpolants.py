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


BSPLINE_BANDED_FROM = 2_000
"""From this many samples a cubic B-spline interpolant is built by :func:`banded_bspline` (linear time and
memory); below it by CasADi's ``interpolant``, whose solve for the coefficients grows quadratically (0.2 s
at 25 000 samples, 2.2 s at 100 000, 11 s at 200 000).  From 3 000 samples on the banded build is the faster
(CPU seconds, CasADi's against the banded: 0.007 / 0.002 at 3 000, 0.037 / 0.004 at 10 000, 0.19 / 0.011 at
24 800): an input element's search rebuilds the interpolant of a new command for every trial.  Both are the
same spline (cubic, not-a-knot): they differ by the rounding of their solves, at most 3e-13 of the samples' range at 100 000 samples."""


def banded_bspline(name: str, grid, values) -> ca.Function:
    """The cubic not-a-knot B-spline through the samples ``(grid, values)`` as a CasADi function of time, built
    in linear time and memory: the spline CasADi's ``interpolant(name, "bspline", [grid], values)`` is (the
    same knots: the samples' times without the second and the second-to-last, the ends fourfold), its
    coefficients from the banded collocation system (:func:`scipy.interpolate.make_interp_spline`) instead
    of CasADi's sparse least squares, which takes quadratic time.  It reproduces the samples to rounding.

    Examples
    --------
    >>> g = np.linspace(0.0, 1.0, 50); v = np.sin(3.0 * g)
    >>> f = banded_bspline("u", g, v)
    >>> ref = ca.interpolant("u", "bspline", [g], v)
    >>> x = np.linspace(0.0, 0.99, 7).reshape(1, -1)
    >>> bool(np.max(np.abs(np.asarray(f(x)) - np.asarray(ref(x)))) < 1e-13), bool(abs(float(f(g[7])) - v[7]) < 1e-15)
    (True, True)
    """
    return _banded(name, grid, values)[0]


def _banded(name: str, grid, values):
    """:func:`banded_bspline` and the same spline as a :class:`scipy.interpolate.BSpline`."""
    from scipy.interpolate import make_interp_spline

    spline = make_interp_spline(np.asarray(grid, dtype=float), np.asarray(values, dtype=float), k=3)
    return ca.Function.bspline(name, [spline.t], spline.c, [3], 1, {}), spline


def spline_values(grid, values, digest: str, times) -> np.ndarray:
    """The B-spline interpolant of the samples ``(grid, values)`` (digest ``digest``) at ``times``, inside the
    samples, as :func:`_interpolant` builds it for the integrator.  From :data:`BSPLINE_BANDED_FROM` samples on
    it is evaluated by scipy (5 µs per 200 times where CasADi takes 1 ms: a recording of 10⁶ samples reports its
    inputs in 5000 runs), which differs from CasADi's evaluation of the same spline by rounding (7e-16 of the
    samples' range measured).

    Examples
    --------
    >>> g = np.arange(30000) * 1e-3; v = np.sin(g)
    >>> x = np.array([0.0105, 12.3456])
    >>> bool(np.max(np.abs(spline_values(g, v, _digest((g, v)), x) - np.sin(x))) < 1e-9)
    True
    """
    f = _interpolant(grid, values, "bspline", digest)
    times = np.asarray(times, dtype=float).reshape(-1)
    spline = _SPLINES.get(digest)
    if spline is not None and len(times):
        # the pieces over ``times`` only: scipy looks for the first time's knot interval from the spline's start
        # (1 ms at 10⁶ samples, paid by each of its 5000 runs); the same numbers (a piece reads 4 coefficients)
        kt, c = spline.t, spline.c
        a = max(int(np.searchsorted(kt, times.min(), side="right")) - 4, 0)
        b = min(int(np.searchsorted(kt, times.max(), side="right")), len(c))
        return np.asarray(type(spline).construct_fast(kt[a:b + 4], c[a:b], 3)(times), dtype=float)
    return np.asarray(f(times.reshape(1, -1)), dtype=float).reshape(-1)


def _digest(g) -> str:
    """A digest of sampled times and values ``g`` (the key of the integrators that interpolate them)."""
    return digest(g[:2])


_INTERPOLANTS: dict = {}
"""Interpolants of sampled inputs by (samples' digest, kind), shared by every simulator of the process: a
diagnosis simulates the same recording through many models (a B-spline through 20 000 samples takes
~15 ms to build).  Bounded by :data:`_INTERPOLANTS_KEPT` (the oldest dropped first)."""
_INTERPOLANTS_KEPT = 64
_SPLINES: dict = {}
"""The splines of :func:`banded_bspline` by the samples' digest, as scipy evaluates them (:func:`spline_values`)."""


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
        values = np.asarray(values, dtype=float)
        name = f"u_{kind}_{digest[:16]}"
        tt = ca.SX.sym("t")
        held = ca.fmin(ca.fmax(tt, grid[0]), grid[-1])
        if kind == "bspline" and len(grid) >= BSPLINE_BANDED_FROM:
            raw, spline = _banded(name, grid, values)
            # called, not inlined: CasADi's B-spline has no SX form (its own interpolant is such a call too)
            at = raw.call([held], False, True)[0]
            if len(_SPLINES) >= _INTERPOLANTS_KEPT:
                _SPLINES.pop(next(iter(_SPLINES)))
            _SPLINES[digest] = spline
        else:
            at = ca.interpolant(name, kind, [grid], values)(held)
        hit = ca.Function(f"{name}_held", [tt], [at])
        if len(_INTERPOLANTS) >= _INTERPOLANTS_KEPT:
            _INTERPOLANTS.pop(next(iter(_INTERPOLANTS)))
        _INTERPOLANTS[key] = hit
    return hit
