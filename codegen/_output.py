"""Integrator outputs collected on the user's time grid.

Between two input breakpoints the integrator is called over runs of equally spaced output points
(:mod:`codegen._grid`); a segment end that is not a grid point is an output step of its own, and a
breakpoint within rounding of a grid point is that grid point (:func:`codegen._grid.snap_to_grid`),
so every grid point belongs to exactly one segment's output steps.
:func:`output_runs` walks these calls for a whole simulation and says, for every output step, which
grid point it lands on (if any), while it fills the inputs as a result stores them: right-continuous,
so a grid point on a breakpoint sees the new segment's input, except the final time, which has no next
segment.  The simulator and the batch both collect their outputs through it, so a run of a batch
lands on the grid exactly where :meth:`codegen.simulator.Simulator.run` puts it.

Outputs go straight into preallocated numpy arrays: :func:`call_into_numpy` hands them to CasADi's
call buffer, whose column-major ``(nx, n)`` result is the memory of a C-ordered ``(n, nx)`` array.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from codegen._grid import bounded_runs, equal_runs, local_samples, snap_to_grid
from phs.errors import SimulationError


@dataclasses.dataclass
class OutputRun:
    """One integrator call: ``n`` output steps of length ``step`` from ``start`` inside segment ``(a, b)``."""

    choice: list  # the segment's input templates and constants (see codegen._inputs.plan_segments)
    start: float
    step: float
    n: int
    max_step: float  # bound on the integration step, in output intervals (codegen._grid.bounded_runs)
    times: np.ndarray  # (n,) output times of the call
    j: np.ndarray  # (n,) index of the grid point each output time lands on (or the next one)
    on: np.ndarray  # bool (n,): the output time is a grid point
    u: np.ndarray  # (n, nu) inputs at the output times
    local: tuple | bool = False  # the span whose samples' spline its sampled inputs follow (codegen._grid.bounded_runs)

    def store(self, out: np.ndarray, values: np.ndarray) -> None:
        """Write the rows of ``values`` (one per output step) that fall on grid points into ``out``."""
        out[self.j[self.on]] = values[self.on]


def output_runs(t, sigs, segs, inputs, U):
    """The integrator calls covering the grid ``t`` segment by segment, as :class:`OutputRun` objects.

    ``segs`` are the segments of :func:`codegen._inputs.plan_segments`, ``inputs(choice, times, max_step)``
    evaluates a segment's inputs (``max_step``: the step bound of the run, which says how a sampled input
    is interpolated there), and ``U`` (len(t), nu), preallocated, receives the inputs on the grid
    as results store them (the first row before the first call).

    Examples
    --------
    >>> from codegen._inputs import plan_segments, segment_inputs
    >>> from phs.signals import step
    >>> t, sigs = np.linspace(0.0, 1.0, 3), [step(1.0, at=0.25)]
    >>> segs, slots = plan_segments(sigs, t)
    >>> U = np.zeros((3, 1))
    >>> runs = list(output_runs(t, sigs, segs, lambda c, tt, ms: segment_inputs(sigs, slots, c, tt, {}, ms), U))
    >>> [(r.start, r.n, r.on.tolist()) for r in runs]   # the edge at 0.25 is an output step off the grid
    [(0.0, 1, [False]), (0.25, 1, [True]), (0.5, 1, [True])]
    >>> U[:, 0]
    array([0., 1., 1.])
    """
    nt = len(t)
    h = float(np.min(np.diff(t)))
    for k, (a, b, choice) in enumerate(segs):
        if k == 0:
            U[0] = inputs(choice, t[:1], 1.0)[0]
        # a breakpoint within rounding of a grid point is that grid point, so that the segments on either
        # side agree on who owns it: the one ending there (its output), the one starting there (its input)
        a, ia = snap_to_grid(t, a, h)
        b, ib = snap_to_grid(t, b, h)
        if b <= a:  # an input feature shorter than the rounding of the grid: nothing to integrate
            continue
        if ia is not None:  # inputs are right-continuous: a grid point on a breakpoint sees the new segment's input
            U[ia] = inputs(choice, np.array([a]), 1.0)[0]
        lo = ia + 1 if ia is not None else int(np.searchsorted(t, a, side="right"))
        hi = ib if ib is not None else int(np.searchsorted(t, b, side="left"))
        # the output steps: grid points strictly inside (a, b), then b (a grid point or not)
        pts = [a] + t[lo:hi].tolist() + [b]
        idx = np.array(list(range(lo, hi)) + [ib if ib is not None else -1], dtype=int)
        pos = 0
        # the sampled inputs entering through their interpolant here, and whether a neighbouring segment
        # has one of them as a straight stretch (a kink at the edge: the window there keeps one interval)
        interp = [j for j, c in enumerate(choice) if c is None]
        edges = tuple(0 <= i < len(segs) and any(segs[i][2][j] is not None for j in interp) for i in (k - 1, k + 1))
        for ra, rh, rn, ms, local in bounded_runs(equal_runs(pts), [sigs[j] for j in interp], edges):
            times = ra + rh * np.arange(1, rn + 1)
            uu = inputs(choice, times, ms)
            if local:
                uu = _local_course(uu, [(j, sigs[j]) for j in interp], local, times)
            j = idx[pos:pos + rn]
            pos += rn
            on = j >= 0
            j = np.where(on, j, hi)  # an output step between grid points: the next grid point's index
            keep = on.copy()
            if pos == len(idx) and ib is not None and ib < nt - 1:
                keep[-1] = False  # b belongs to the next segment, except the final time, which has no next segment
            U[j[keep]] = uu[keep]
            # a local run's inputs follow the spline of the samples of its span (bounded_runs)
            yield OutputRun(choice, ra, rh, rn, ms, times, j, on, uu, local)


def _local_course(uu, sampled, span, times):
    """``uu`` (the inputs at a local run's output ``times``) with each sampled input ``(j, signal)`` whose samples
    lie off the run's points (:func:`codegen._grid.local_samples`: ``n + 2`` around a span of ``n`` intervals) at
    the value of the spline the integrator follows there, not the straight line between the samples: a
    channel that feeds the input through (a source's current) reports the course that drove the state.  On the
    points the samples are the spline's values and ``uu`` is kept as it is."""
    from scipy.interpolate import make_interp_spline

    out = None
    for j, sg in sampled:
        got = local_samples(*sg.arrays[:2], *span)
        if got is not None and len(got[0]) == span[2] + 2:
            out = np.array(uu, dtype=float) if out is None else out
            out[:, j] = make_interp_spline(got[0], got[1], k=3)(times)
    return uu if out is None else out


def check_covered(runs, nt: int, what: str) -> None:
    """Raise a :class:`SimulationError` unless the output steps of ``runs`` land on grid points 1..nt-1 once each, in order.

    Examples
    --------
    >>> run = OutputRun([], 0.0, 0.5, 2, 1.0, np.array([0.5, 1.0]), np.array([1, 2]), np.array([True, True]), None)
    >>> check_covered([run], 3, "example")
    >>> check_covered([run], 4, "example")
    Traceback (most recent call last):
    ...
    phs.errors.SimulationError: example: the integrator's output steps do not cover the time grid once each
    """
    filled = np.concatenate([r.j[r.on] for r in runs]) if runs else np.zeros(0, dtype=int)
    if not np.array_equal(filled, np.arange(1, nt)):
        raise SimulationError(f"{what}: the integrator's output steps do not cover the time grid once each")


def energy_columns(system) -> list[str]:
    """Names of the energy accounts integrated with the states, in the order of their columns.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> energy_columns(rc_circuit())
    ['E_supplied', 'E_dissipated', 'E_dissipated[R]']
    """
    return ["E_supplied", "E_dissipated"] + [f"E_dissipated[{label}]" for label, _ in system.dissipators]


def energy_accounts(system, Q) -> dict:
    """The energy accounts of ``system`` by name, as views of the columns of ``Q`` (nt, n_accounts)."""
    return {name: Q[:, k] for k, name in enumerate(energy_columns(system))}


def call_into_numpy(F, z0, P, nx: int, n: int, nq: int):
    """Call an integrator writing its outputs straight into numpy arrays (no DM -> numpy copy).

    CasADi stores the (nx, n) output column-major, which is the memory layout of a
    C-ordered (n, nx) array: the rows are the states at each output time.
    """
    buf, trigger = F.buffer()
    z0 = np.ascontiguousarray(z0, dtype=float)
    P = np.ascontiguousarray(P, dtype=float)
    zs = np.empty((n, nx))
    qs = np.empty((n, nq))
    buf.set_arg(0, memoryview(z0))
    buf.set_arg(2, memoryview(P))
    buf.set_res(0, memoryview(zs))
    buf.set_res(2, memoryview(qs))
    trigger()
    return zs, qs
