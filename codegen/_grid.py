"""The user's time grid and how it is cut into integrator calls.

An integrator built for ``n`` output steps of one length serves every run of ``n`` equally spaced
output points (time is normalised per call), so the output points between two input breakpoints are
split into runs of equal spacing (:func:`equal_runs`).  A sampled input further cuts a run into
windows, each with the longest integration step its samples allow (:func:`step_windows`,
:func:`bounded_runs`).
"""

from __future__ import annotations

import numpy as np

from phs.errors import InputDataError
from phs.kinks import smooth_to_third_order

STEP_WINDOW = 200  # output intervals per window of a sampled input with its own step bound
JOINED_MAX = 64
"""Neighbouring windows with the same step bound are joined into one integrator call of up to this many
windows, cut into lengths of ``STEP_WINDOW`` times a power of two (:func:`_binary_lengths`: an integrator is
built per number of output steps, so few distinct ones serve a whole recording).  Each call restarts CVODES at
its first step; a 24.8 s run at 1 kHz (the EMPS stage through a delay element) took 163 calls in windows of
200 and 61 joined, integrating in 0.12 s of CPU time instead of 0.19 s (the same outputs to 6e-7 of their
size at rtol 1e-6)."""
_STEP_FACTORS = (64, 32, 16, 8, 4, 2)
_STEP_REL_TOL = 0.01  # of the input's range: a window's input must be this close to linear between step ends


def time_grid(t) -> np.ndarray:
    """``t`` as a float array, checked to be a strictly increasing 1-D grid of at least 2 finite points.

    Raises
    ------
    InputDataError
        Naming the index of the first non-finite or non-increasing value.

    Examples
    --------
    >>> time_grid([0, 1, 2])
    array([0., 1., 2.])
    >>> time_grid([0.0, 1.0, 1.0])
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: time grid is not strictly increasing at index 2 (t=1.0)
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise InputDataError("time grid must be a 1-D array with at least 2 points")
    if not np.all(np.isfinite(t)):
        raise InputDataError(f"time grid has a non-finite value at index {int(np.argmin(np.isfinite(t)))}")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0)) + 1
        raise InputDataError(f"time grid is not strictly increasing at index {i} (t={t[i]})")
    return t


#: An input breakpoint this close to a grid point is that grid point: a nanosecond (relative to the time
#: for late times), and never more than a thousandth of the grid's finest spacing.
_SNAP_REL, _SNAP_OF_STEP = 1e-9, 1e-3


def snap_to_grid(t: np.ndarray, x: float, step: float | None = None) -> tuple[float, int | None]:
    """``(t[i], i)`` when ``x`` lies within rounding of the grid point ``t[i]``, else ``(x, None)``.

    Rounding is ``1e-9 * max(1, |x|)`` seconds, at most a thousandth of the finest spacing of ``t``
    (``step`` when the caller knows it):
    a square wave's edge computed as ``k * period / 2`` lands on the grid point it was meant for,
    so the segments on either side agree on which of them owns that point.

    Examples
    --------
    >>> t = np.arange(0, 11) * 1e-3
    >>> snap_to_grid(t, 0.0075 * 0.8 + 1e-18)          # 6 ms, up to rounding: grid point 6
    (0.006, 6)
    >>> snap_to_grid(t, 0.0065)                         # between grid points 6 and 7
    (0.0065, None)
    """
    h = step if step is not None else float(np.min(np.diff(t)))
    tol = min(_SNAP_REL * max(1.0, abs(x)), _SNAP_OF_STEP * h)
    i = min(max(int(t.searchsorted(x)), 1), len(t) - 1)  # scalars: called twice per segment of every simulation
    lo, hi = float(t[i - 1]), float(t[i])
    if abs(lo - x) <= abs(hi - x):
        i, hi = i - 1, lo
    return (hi, i) if abs(hi - x) <= tol else (float(x), None)


def equal_runs(pts) -> list[tuple[float, float, int]]:
    """Split output points into runs of equal spacing: ``(start, step, n_steps)``.

    Examples
    --------
    >>> equal_runs([0.0, 1.0, 2.0, 3.0, 3.5, 4.0])
    [(0.0, 1.0, 3), (3.0, 0.5, 2)]
    """
    out = []
    p = np.asarray(pts, dtype=float)
    d = np.diff(p)
    i = 0
    m = len(p)
    while i < m - 1:
        h = d[i]
        # the first interval after i that differs from h (beyond rounding) ends the run
        off = np.abs(d[i + 1:] - h) > 1e-9 * max(h, 1e-300) + 1e-12 * np.abs(p[i + 1:m - 1])
        j = i + 1 + (int(np.argmax(off)) if off.any() else m - 2 - i)
        n = j - i
        out.append((float(p[i]), float((p[j] - p[i]) / n), n))
        i = j
    return out


FINE_WINDOW = 25
"""A window that is rough somewhere is examined again in windows of this many intervals, and a smooth window
next to a rough one gives up this many of its intervals: one kink or jump in a smooth input costs the few
intervals around it, not its window and both neighbours (600 intervals, at up to 50 CVODES steps each on a
chirp).  A cubic spline's ringing from a kink decays by about 0.27 per sample: below 1e-14 after 25."""


def _bound(w: np.ndarray, tol: np.ndarray) -> int:
    """The step bound of one window ``w`` (points, columns): 1 unless every column is smooth to third order
    (:func:`smooth_to_third_order`), else the largest factor whose linear interpolation reproduces every
    point to within ``tol``."""
    k = np.arange(len(w))
    # a channel that follows the input's derivative (a capacitor's current) must see the kinks where they are
    if not smooth_to_third_order(w, tol):
        return 1
    for m in _STEP_FACTORS:
        if m >= len(w):
            continue
        idx = np.unique(np.append(np.arange(0, len(w), m), len(w) - 1))
        err = max((np.max(np.abs(w[:, j] - np.interp(k, idx, w[idx, j]))) / tol[j] for j in range(w.shape[1])), default=0.0)
        if err <= 1.0:
            return m
    return 1


def step_windows(values, window: int = STEP_WINDOW, rough_ends=(False, False)) -> list[tuple[int, int, int]]:
    """Windows of a uniformly sampled input and the longest integration step each allows.

    ``values`` (n,) or (n, k): inputs at n equally spaced points.  Returns ``(i0, i1, m)``: points
    ``i0..i1`` (at most ``window`` intervals) and ``m``, the largest of 64, 32, ..., 2, 1 intervals such
    that every input, linearly interpolated through every m-th point of the window, reproduces all
    its points to within 1 % of its range over the record; ``m`` is 1 where an input is not smooth to
    third order (its third differences exceed half its largest second difference: kinks of a
    piecewise-linear table, steps, noise) and over the :data:`FINE_WINDOW` intervals next to such a place.
    A window that is rough somewhere is examined again in windows of :data:`FINE_WINDOW` intervals (a
    smooth input with one jump keeps long steps up to a few samples from it); neighbouring windows with the
    same bound are joined again, up to ``window`` intervals.
    A BDF step only evaluates the dynamics at its ends, so a step must not cross a feature of the
    input; steps of ``m`` intervals cross none (to 1 %).  In windows with ``m > 1`` the simulator
    interpolates the samples by a cubic spline instead of linearly: the linear interpolant's kink at
    every sample would otherwise hold CVODES to about a step per sample.  Smooth, finely sampled
    inputs (sines, chirps, slow ramps at 1 kHz) get long steps; an input that changes character at
    every sample (noise, multisines near the Nyquist frequency, a zero-order hold) keeps one interval
    and its linear interpolation.  ``rough_ends``: whether what lies before the first point and after
    the last is rough (a kink where the input's interpolant meets one of its straight stretches), so that
    the first or last intervals keep one interval too.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 1001)
    >>> step_windows(np.sin(2 * np.pi * 5 * t))   # 5 Hz at 1 kHz: steps of 8 samples, windows joined
    [(0, 800, 8), (800, 1000, 8)]
    >>> {w[2] for w in step_windows(np.random.default_rng(0).normal(size=1001))}
    {1}
    >>> u = np.sin(2 * np.pi * 2 * t)
    >>> u[500:] += 0.5                                               # a jump at point 500
    >>> [w for w in step_windows(u) if w[2] == 1]                    # one interval near it only
    [(450, 525, 1)]
    """
    V = np.asarray(values, dtype=float)
    V = V.reshape(len(V), -1)
    n = len(V)
    tol = _STEP_REL_TOL * np.maximum(np.ptp(V, axis=0), 1e-300) if n else np.zeros(V.shape[1])
    out = []
    for i0 in range(0, max(n - 1, 0), window):
        i1 = min(i0 + window, n - 1)
        m = _bound(V[i0: i1 + 1], tol)
        if m == 1 and i1 - i0 > FINE_WINDOW:  # rough somewhere: where exactly
            out += [(a, min(a + FINE_WINDOW, i1), _bound(V[a: min(a + FINE_WINDOW, i1) + 1], tol)) for a in range(i0, i1, FINE_WINDOW)]
        else:
            out.append((i0, i1, m))
    # a spline through a rough window rings into its neighbours for a few samples: a smooth window next
    # to a rough one keeps one interval (and the linear interpolant) over its FINE_WINDOW intervals there
    rough = [rough_ends[0]] + [m == 1 for _, _, m in out] + [rough_ends[1]]
    parts = []
    for k, (a, b, m) in enumerate(out):
        lo = a + FINE_WINDOW if m > 1 and rough[k] else a
        hi = b - FINE_WINDOW if m > 1 and rough[k + 2] else b
        if hi <= lo:
            parts.append((a, b, 1))
            continue
        parts += [(a, lo, 1)] if lo > a else []
        parts.append((lo, hi, m))
        parts += [(hi, b, 1)] if hi < b else []
    joined: list[tuple[int, int, int]] = []
    for a, b, m in parts:
        if joined and joined[-1][2] == m and b - joined[-1][0] <= window * JOINED_MAX:
            joined[-1] = (joined[-1][0], b, m)
        else:
            joined.append((a, b, m))
    return [(a + i, a + j, m) for a, b, m in joined for i, j in _binary_lengths(b - a, window)]


def _binary_lengths(n: int, window: int) -> list[tuple[int, int]]:
    """``[0, n)`` cut into consecutive pieces of ``window`` times a power of two, longest first, and what is
    left (shorter than ``window``) as one piece.

    Examples
    --------
    >>> _binary_lengths(1250, 200)
    [(0, 800), (800, 1200), (1200, 1250)]
    >>> _binary_lengths(150, 200)
    [(0, 150)]
    """
    out, i = [], 0
    while n - i >= window:
        k = window
        while 2 * k <= n - i:
            k *= 2
        out.append((i, i + k))
        i += k
    if i < n:
        out.append((i, n))
    return out


def bounded_runs(runs, interpolated, rough_ends=(False, False)):
    """Runs ``(start, step, n)`` cut into windows with their step bound and interpolation
    ``(start, step, n, max_step, local)``.

    ``interpolated``: the sampled inputs that enter the integrator through their interpolant on these runs.
    With such inputs, the windows of :func:`step_windows` (``rough_ends`` passed on); one window bounded by
    one interval when one of them is finer than the output grid; and unbounded runs (``max_step`` 1,
    unused) without them: inputs that are not sampled, or sampled inputs that enter as lines between
    their kinks, the segments' breakpoints (:meth:`phs.signals.Sampled.kinks`, :meth:`~phs.signals.Sampled.lines`),
    not through an interpolant whose features would bound the step.

    ``local``: a window bounded by one interval whose points are every input's own samples, smooth to third
    order (:func:`smooth_to_third_order`), is integrated through the cubic spline of those samples alone
    (:func:`local_samples`) instead of the straight lines between them.  Such a window is smooth but was
    kept to one interval by a rough neighbour (the global spline would ring into it) or by its curvature
    (a raised-cosine edge between two holds, a chirp at a dozen samples per period); the straight lines'
    kink at every sample would make a channel that follows the input's derivative (a capacitor's current)
    lag by half a sample there and cost the integrator a restart of its steps at every sample.  The spline
    of the window's own samples does not see the rough place beyond them.  ``local`` is False, or the span
    ``(start, step, n)`` whose samples (:func:`local_samples`) the spline goes through: the window's own, or for
    a partial step beside such a window (a breakpoint off the grid), the neighbour's.

    Examples
    --------
    >>> list(bounded_runs([(0.0, 0.5, 4)], []))
    [(0.0, 0.5, 4, 1.0, False)]
    """
    samp = list(interpolated)
    out = []
    for ra, rh, rn in runs:
        if not samp or any(float(np.min(np.diff(sg.arrays[0]))) < rh * (1 - 1e-9) for sg in samp):
            out.append((ra, rh, rn, 1.0, False))
            continue
        tt = ra + rh * np.arange(rn + 1)
        for i0, i1, m in step_windows(np.column_stack([np.asarray(sg(tt), dtype=float) for sg in samp]), rough_ends=rough_ends):
            if m > 1:
                out.append((ra + i0 * rh, rh, i1 - i0, float(m), False))
                continue
            out += [(ra + (i0 + j0) * rh, rh, j1 - j0, 1.0, local) for j0, j1, local in _local_pieces(samp, ra + i0 * rh, rh, i1 - i0)]
    yield from _partial_steps_joined(out, samp)


def _partial_steps_joined(windows: list, samp) -> list:
    """``windows`` with each single step shorter than an output interval (from a breakpoint off the grid to the
    next grid point, or back) that lies beside a local window and within the samples of its spline made local
    with that window's span: the same spline on both sides (a command delayed by a fraction of a sample has its
    kinks, where the segments end, between the grid points; read as a straight line there beside the spline,
    the course would jump where the two meet)."""
    out = list(windows)
    for i, (ra, rh, rn, ms, local) in enumerate(out):
        if local or rn != 1:
            continue
        for nb in (i - 1, i + 1):
            span = out[nb][4] if 0 <= nb < len(out) else False
            if not span or not rh < span[1] * (1 - 1e-9):
                continue
            inside = [local_samples(*sg.arrays[:2], *span) for sg in samp]
            if all(v is not None and v[0][0] - 1e-9 * rh <= ra and ra + rh <= v[0][-1] + 1e-9 * rh for v in inside):
                out[i] = (ra, rh, rn, ms, span)
                break
    return out


def local_samples(grid, values, start: float, step: float, n: int):
    """The samples ``(grid, values)`` of a run of ``n`` intervals ``step`` from ``start`` that its local spline
    goes through: the ``n + 1`` samples on its points (within a millionth of the step), or, for samples as
    evenly spaced but off the points by a constant phase (a command delayed by a fraction of a sample), the
    ``n + 2`` that cover it (the last at or before its start to the first at or after its end); None for
    samples spaced otherwise.

    Examples
    --------
    >>> g = np.arange(10) * 0.5
    >>> local_samples(g, g ** 2, 1.0, 0.5, 3)
    (array([1. , 1.5, 2. , 2.5]), array([1.  , 2.25, 4.  , 6.25]))
    >>> local_samples(g, g ** 2, 1.25, 0.5, 3)[0]
    array([1. , 1.5, 2. , 2.5, 3. ])
    >>> local_samples(g ** 1.5, g, 1.0, 0.5, 3) is None
    True
    """
    grid = np.asarray(grid, dtype=float)
    eps = 1e-6 * step
    end = start + n * step
    lo = int(np.searchsorted(grid, start + eps, side="right")) - 1  # the last sample at or before the start
    hi = int(np.searchsorted(grid, end - eps, side="left"))  # the first at or after the end
    if lo < 0 or hi >= len(grid):
        return None
    on = abs(grid[lo] - start) <= eps  # on the run's points: n + 1 of them; else n + 2 around them
    if hi - lo != (n if on else n + 1) or not np.allclose(np.diff(grid[lo:hi + 1]), step, rtol=0.0, atol=eps):
        return None
    return grid[lo:hi + 1], np.asarray(values, dtype=float)[lo:hi + 1]


LOCAL_SPLITS = 4
"""Most kinks a window bounded by one interval is split at in search of smooth pieces (:func:`_local_pieces`): a
smooth stretch that ends in a step (a chirp burst dropping to its rest level) keeps its spline up to the step.
Not chosen on a measurement."""


def _local_pieces(samp, start: float, step: float, n: int, splits: int = LOCAL_SPLITS) -> list:
    """A window of ``n`` intervals from ``start`` bounded by one interval, as ``(i0, i1, local)`` pieces: the
    whole window local when every input's samples on its points (or evenly spaced around them:
    :func:`local_samples`) are all of them and smooth to third order; else, while ``splits`` last, cut at its
    sharpest kink (the largest second difference of any input, scaled by its range) into two pieces examined
    the same way, the kink the end of both (a kink between two points: the interval that holds it taken by
    the straight lines); a piece of fewer than 8 points is not local.  A local piece's ``local`` is the span
    ``(start, step, n)`` whose samples its spline goes through (:func:`local_samples`)."""
    if n <= 0:
        return []
    vals = [local_samples(*sg.arrays[:2], start, step, n) for sg in samp]
    if n < 7 or any(v is None for v in vals) or len({len(v[1]) for v in vals}) > 1:
        return [(0, n, False)]
    V = np.column_stack([v[1] for v in vals])
    tol = _STEP_REL_TOL * np.maximum(np.ptp(V, axis=0), 1e-300)
    if smooth_to_third_order(V, tol):
        return [(0, n, (start, step, n))]
    if splits <= 0:
        return [(0, n, False)]
    k = 1 + int(np.argmax(np.max(np.abs(np.diff(V, 2, axis=0)) / tol, axis=1)))  # the sharpest kink's sample
    # samples on the points: the kink is point k, the end of both pieces; samples between them (n + 2): sample k
    # lies inside interval k - 1, which the straight lines take, the pieces either side ending at its ends
    a, b = (k, k) if len(V) == n + 1 else (k - 1, k)
    left = _local_pieces(samp, start, step, a, splits - 1)
    middle = [(a, b, False)] if b > a else []
    right = _local_pieces(samp, start + b * step, step, n - b, splits - 1)
    return _joined(left + middle + [(b + i, b + j, loc) for i, j, loc in right])


def _joined(pieces: list) -> list:
    """Neighbouring pieces that are both not local, as one."""
    out: list = []
    for a, b, loc in pieces:
        if out and not loc and not out[-1][2]:
            out[-1] = (out[-1][0], b, False)
        else:
            out.append((a, b, loc))
    return out
