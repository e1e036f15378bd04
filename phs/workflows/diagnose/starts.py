"""Where a screening fit starts: the cost of a model at given starts, one simulation each, and the starts
a candidate whose strength spans decades is screened from again when its own start does not pay
(:data:`DECADE_STARTS`)."""

from __future__ import annotations

import math

from codegen import Simulator
from phs.errors import PHSError
from phs.workflows.diagnose.element_search import channel_weights, weighted_residual

DECADE_STARTS = 100.0
"""Factor either side of a candidate's start value from which its screening starts again when, from its
start, it does not pay for its parameters (BIC not lower than the model it extends): for a new parameter
fitted in its logarithm whose range spans at least this factor squared, when the candidate gives no starts
of its own (:func:`_decade_starts`), and the better of the two is already lower than where the fit from
its start ended (one simulation each: an effect that is absent costs no second fit).  A strength whose
plausible values span decades may lie far from the start its scale suggests: on the concealed series
resistance at 0.35 of its strength (``examples.concealed_effects``, 3 s, the tests' seed 1) the start, 0.02
of the input's level over its current, ended after five evaluations at the neutral point and the verdict
was ``none``; from the start 100 times weaker the screening lowers the validation residual 13.97 → 13.82
and the verdict is ``series_resistance``.  Only where the start does not pay: the more promising start by
its first simulation need not be the one a five-evaluation fit gets furthest from (a start too strong costs
more at first and may still get there).  The factor is not chosen on a measurement."""


def _decade_starts(system, aug) -> list[dict]:
    """Starts :data:`DECADE_STARTS` below and above the value ``system`` holds for each new parameter of ``aug``
    fitted in its logarithm whose range spans at least ``DECADE_STARTS²`` (within the range).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> m = NS(param=lambda k: NS(value=1.0))
    >>> _decade_starts(m, NS(free=["a", "b"], log_scale=["a", "b"], bounds={"a": (1e-5, 1e3), "b": (0.5, 2.0)}))
    [{'a': 0.01}, {'a': 100.0}]
    """
    out = []
    for k in aug.free:
        lo, hi = aug.bounds.get(k) or (0.0, 0.0)
        if k in aug.log_scale and lo > 0 and hi >= lo * DECADE_STARTS**2:
            v = float(system.param(k).value)
            out += [{k: s} for s in (min(max(v * f, lo * 1.01), hi * 0.99) for f in (1 / DECADE_STARTS, DECADE_STARTS)) if s != v]
    return out


def _start_costs(system, starts: list, x0: dict, data, rtol: float) -> list[float]:
    """The training cost (``Σ_ch w_ch² RSS_ch``, as ``Scored.rss``) of ``system`` at each start, one simulation
    each at ``rtol``; infinite where the simulation fails."""
    sim = Simulator(system, rtol=rtol, energy=False)
    w = channel_weights(data)
    xs = [x0.get(n, 0.0) for n in system.state_names]
    costs = []
    for st in starts:
        try:
            r = weighted_residual(system, data.recording, xs, w, params=st or None, sim=sim)
            c = float(r @ r)
        except (PHSError, RuntimeError):
            c = math.inf
        costs.append(c if math.isfinite(c) else math.inf)
    return costs
