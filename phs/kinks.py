"""Kinks of sampled values: where their linear interpolant changes slope, and the straight stretches between.

A recorded input enters a simulation or a fit as straight lines between its kinks where they are few
(:data:`KINK_SHARE`) or far apart (:data:`LINE_RUN`), and through an interpolant elsewhere
(:meth:`phs.signals.Sampled.kinks`, :meth:`phs.signals.Sampled.lines`, :func:`codegen._inputs.plan_segments`).
"""

from __future__ import annotations

import numpy as np


def linear_kinks(values, times=None) -> list[int]:
    """Sample indices where sampled values change slope: the kinks of their linear interpolant (a change
    of slope times the shorter neighbouring interval above 1e-12 of the largest magnitude, i.e. rounding).

    ``values`` is (n,) or (n, k) (a kink of any column counts); ``times`` (n,) the sample times
    (default: uniformly spaced).

    Examples
    --------
    >>> linear_kinks([0.0, 0.0, 1.0, 2.0, 2.0])
    [1, 3]
    >>> linear_kinks([0.0, 1.0, 2.0], times=[0.0, 1.0, 3.0])   # the slope halves at the middle sample
    [1]
    """
    U = np.asarray(values, dtype=float)
    U = U.reshape(len(U), -1)
    if U.size == 0 or len(U) < 3:
        return []
    tol = 1e-12 * max(float(np.max(np.abs(U))), 1e-300)
    if times is None:
        d2 = np.abs(U[2:] - 2 * U[1:-1] + U[:-2])
    else:
        h = np.diff(np.asarray(times, dtype=float))[:, None]
        slope = np.diff(U, axis=0) / h
        d2 = np.abs(np.diff(slope, axis=0)) * np.minimum(h[1:], h[:-1])
    return sorted({int(k) + 1 for k in np.nonzero(np.any(d2 > tol, axis=1))[0]})


KINK_SHARE = 0.1
"""A sampled input counts as piecewise linear when its kinks are at most this share of its intervals (or 20):
the simulator and identification then restart at each kink.  The concealed cases' drive delayed by a
fraction of a sample has kinks at 7 % of its samples; through the step windows instead, the electrostatic
actuator's current at rtol 1e-7 is off by 61 % of its spread at a step (4.5 % with the restarts; the two
rules agree to 0.06 % at rtol 1e-11), in 0.40 s per 20 s run against 0.50 s."""

LINE_RUN = 20
"""Samples with many kinks (a chirp between holds and ramps) still enter as straight lines over every stretch of
at least this many intervals without a kink (:meth:`phs.signals.Sampled.lines`): a step per sample costs about one step per
interval, a restart a few, so a stretch this long is cheaper as a line, and exact."""


CURVED_RUN = 8
"""Fewest samples of a curved stretch (:func:`curved_stretches`): a run of samples each of which is a kink, smooth to
third order.  Eight samples give the cubic spline of a stretch's own samples (``codegen._grid.bounded_runs``) four
more than the four it is made of.  Not chosen on a measurement."""


def smooth_to_third_order(w, tol) -> bool:
    """Whether every column of the points ``w`` (points, columns) is smooth to third order: at least
    :data:`CURVED_RUN` points, whose second differences vary slowly (a sampled sine or chirp, a raised-cosine
    edge), not in spikes (the kinks of a piecewise-linear waveform table, a step, noise): no third difference
    above half the largest second difference (``tol``, per column, an absolute floor of ``1e-12 tol``).

    Examples
    --------
    >>> k = np.arange(40.0)
    >>> smooth_to_third_order(np.cos(np.pi * k / 39)[:, None], [0.02]), smooth_to_third_order(np.abs(k - 20)[:, None], [0.4])
    (True, False)
    """
    w = np.asarray(w, dtype=float).reshape(len(w), -1)
    if len(w) < CURVED_RUN:
        return False
    d2, d3 = np.abs(np.diff(w, 2, axis=0)), np.abs(np.diff(w, 3, axis=0))
    return bool(np.all(d3.max(axis=0, initial=0.0) <= 0.5 * d2.max(axis=0, initial=0.0) + 1e-12 * np.asarray(tol, dtype=float)))


def curved_stretches(values, kinks) -> list[tuple[int, int]]:
    """``(i0, i1)`` sample ranges (inclusive) of the stretches of at least :data:`CURVED_RUN` samples whose inner
    samples are kinks (``kinks``: :func:`linear_kinks`; but for single samples between two kinks, where the slope
    happened not to change: an inflection) and which are smooth to third order
    (:func:`smooth_to_third_order`, at 1 % of the stretch's range): a raised-cosine edge between two holds, a sine
    burst.  Samples whose kinks are few may still hold such a stretch: they are then not piecewise linear.

    Examples
    --------
    >>> v = np.concatenate([np.zeros(10), 0.5 - 0.5 * np.cos(np.pi * np.arange(1, 20) / 20), np.ones(10)])
    >>> curved_stretches(v, linear_kinks(v))   # the edge and a sample of each hold (its inflection is no kink)
    [(8, 30)]
    >>> curved_stretches([0.0, 0.0, 1.0, 1.0, 2.0, 2.0], linear_kinks([0.0, 0.0, 1.0, 1.0, 2.0, 2.0]))
    []
    """
    v = np.asarray(values, dtype=float)
    k = np.asarray(sorted(kinks), dtype=int)
    out: list[tuple[int, int]] = []
    if len(k) < CURVED_RUN - 2:
        return out
    breaks = np.nonzero(np.diff(k) > 2)[0]
    for a, b in zip(np.concatenate([[0], breaks + 1]), np.concatenate([breaks, [len(k) - 1]]), strict=True):
        i0, i1 = int(k[a]) - 1, int(k[b]) + 1  # the run of consecutive kinks and the samples either side
        w = v[i0:i1 + 1].reshape(i1 + 1 - i0, -1)
        if i1 + 1 - i0 >= CURVED_RUN and smooth_to_third_order(w, 0.01 * np.maximum(np.ptp(w, axis=0), 1e-300)):
            out.append((i0, i1))
    return out


def straight_stretches(kinks, n: int) -> list[tuple[int, int]]:
    """Sample index pairs ``(a, b)``, consecutive among the ``kinks`` and the ends ``0``, ``n - 1``, at least
    :data:`LINE_RUN` intervals apart: the stretches over which ``n`` sampled values are one straight line.

    Examples
    --------
    >>> straight_stretches([30, 31, 35], 100)
    [(0, 30), (35, 99)]
    """
    k = [0] + [int(i) for i in kinks] + [n - 1]
    return [(a, b) for a, b in zip(k[:-1], k[1:]) if b - a >= LINE_RUN]


HELD_SHARE = 0.9
"""Sampled values read as held between samples (:func:`held_between_samples`) when at least this share of their
changes are isolated jumps between flat stretches.  A DAQ's command (steps, staircases, square waves, PRBS) changes at
isolated samples only (share 1); a sensor's samples of a continuous signal change at consecutive samples wherever it
moves (a sine, a ramp, a smooth edge: share near 0).  The margin below 1 keeps a held command whose value was updated
at two consecutive samples here and there."""

HELD_PLATEAU = 4
"""Held values whose flat stretches are shorter than this many intervals (median) may as well be a continuous signal
sampled coarsely or quantized by the converter: the reading is then said to be ambiguous."""


def held_between_samples(values) -> tuple[bool, bool]:
    """Whether sampled values look held between samples (a zero-order hold), and whether that reading is ambiguous.

    Held: the values change (beyond rounding: 1e-12 of their largest magnitude) in isolated jumps between flat
    stretches, at least :data:`HELD_SHARE` of the changing intervals having no changing neighbour.  Such samples
    are a command held by a DAC: a continuous signal recorded by a sensor has no flat stretches where it moves.
    Ambiguous: held, but with some changes at consecutive samples or with flat stretches shorter than
    :data:`HELD_PLATEAU` intervals (median): a slow signal quantized by the converter looks the same.  Constant values
    are not held (either reading gives the same signal).

    Examples
    --------
    >>> held_between_samples([0.0] * 10 + [1.0] * 10 + [0.0] * 10)      # a pulse as a DAQ holds it
    (True, False)
    >>> held_between_samples(np.sin(np.arange(50) * 0.1))                              # a sampled sine
    (False, False)
    >>> held_between_samples(np.round(10 * np.sin(np.arange(200) * 0.05)))            # a quantized sine
    (True, True)
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    if len(v) < 3:
        return False, False
    tol = 1e-12 * max(float(np.max(np.abs(v))), 1e-300)
    ch = np.abs(np.diff(v)) > tol
    n = int(ch.sum())
    if n == 0:
        return False, False
    neighbour = np.zeros_like(ch)
    neighbour[1:] |= ch[:-1]
    neighbour[:-1] |= ch[1:]
    isolated = int(np.sum(ch & ~neighbour))
    if isolated < HELD_SHARE * n:
        return False, False
    edges = np.flatnonzero(ch)
    flats = np.diff(np.concatenate([[-1], edges, [len(ch)]])) - 1  # flat intervals between consecutive changes
    flats = flats[flats > 0]
    ambiguous = isolated < n or (len(flats) > 0 and float(np.median(flats)) < HELD_PLATEAU)
    return True, bool(ambiguous)


ABRUPT_RATIO = 4.0
"""A sample interval over which sampled values change abruptly (:func:`abrupt_runs`) changes by more than this many
times the median change of the intervals around it (:data:`ABRUPT_WINDOW` on each side).  A sampled smooth signal
changes by at most about 1.6 times its median there (a sine's slope over a window of a third of its period: the
median of ``|cos|``), a raised-cosine edge a few samples long by at most 3 (at its first interval); a step, a held
edge or a PRBS bit changes by far more than the flat stretches beside it (their median is 0)."""

ABRUPT_WINDOW = 5
"""Intervals on each side of an interval whose median change it is compared with (:data:`ABRUPT_RATIO`): a change
spread over up to five consecutive intervals (a held edge that straddles a sample: two) still has flat neighbours
for most of the window."""

ABRUPT_SIZE = 0.01
"""Smallest abrupt change, as a share of the values' range (:func:`abrupt_runs`): below it, a converter's steps, not
a change of the command."""

ABRUPT_NOISE = 5.0
"""Smallest abrupt change, in standard deviations of the change noise makes (``√2 σ``, ``σ`` the values' noise
from the median of their second differences): a measured input's noise alone crosses it once in two million
intervals."""


def abrupt_runs(values) -> list[tuple[int, int]]:
    """Sample index pairs ``(s, e)``: maximal runs of consecutive intervals ``s..e-1`` over which sampled values
    change abruptly, by more than :data:`ABRUPT_RATIO` times the median change of the
    :data:`ABRUPT_WINDOW` intervals on each side and by more than :data:`ABRUPT_SIZE` of their range: steps, held
    edges and PRBS bits, not a sampled smooth signal.  Where, inside such a run, the signal changed is not in
    the samples.

    Examples
    --------
    >>> abrupt_runs([0.0] * 8 + [1.0] * 8)                          # a step between samples 7 and 8
    [(7, 8)]
    >>> abrupt_runs([0.0] * 8 + [0.4, 1.0] + [1.0] * 8)             # a held edge that straddles sample 8
    [(7, 9)]
    >>> abrupt_runs(list(np.sin(np.arange(60) * 0.3)))              # a sampled sine
    []
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    if len(v) < 3:
        return []
    a = np.abs(np.diff(v))
    span = float(np.max(v) - np.min(v))
    if span <= 0:
        return []
    w = ABRUPT_WINDOW
    windows = np.lib.stride_tricks.sliding_window_view(np.pad(a, w, mode="reflect" if len(a) > w else "edge"), 2 * w + 1)
    # the noise: the median of |second differences| (steps do not move it) over that of Gaussian noise's, 0.6745 √6
    sigma = float(np.median(np.abs(np.diff(v, 2)))) / (0.6745 * np.sqrt(6.0))
    floor = max(ABRUPT_SIZE * span, ABRUPT_NOISE * np.sqrt(2.0) * sigma)
    jump = (a > ABRUPT_RATIO * np.median(windows, axis=1)) & (a > floor)
    runs, k = [], 0
    idx = np.flatnonzero(jump)
    while k < len(idx):
        j = k
        while j + 1 < len(idx) and idx[j + 1] == idx[j] + 1:
            j += 1
        runs.append((int(idx[k]), int(idx[j]) + 1))
        k = j + 1
    return runs
