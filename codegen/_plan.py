"""The integrator calls of a simulation, planned once per time grid and inputs.

A simulation walks its input segments (:func:`codegen._inputs.plan_segments`) and the equally spaced
runs of output steps inside them (:func:`codegen._output.output_runs`), evaluating the inputs at every
output step.  None of that depends on the model or its parameters: a diagnosis or an identification
simulates the same recording through hundreds of models and parameter values, and on a recording whose
input steps every few tens of milliseconds that walk costs as much as the integration itself.
:func:`plan_for` does it once per time grid and inputs and keeps the result (:data:`_PLANS`, shared by
every simulator of the process); a run then only calls the integrators.

Examples
--------
>>> import numpy as np
>>> from phs.signals import step
>>> t = np.linspace(0.0, 1.0, 5)
>>> plan = plan_for(t, [step(1.0, at=0.5)])
>>> [(r.start, r.n) for r in plan.runs], plan_for(t, [step(1.0, at=0.5)]) is plan
([(0.0, 2), (0.5, 2)], True)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from codegen._inputs import baked, plan_segments, segment_inputs, shifted
from codegen._interpolants import digest, sampled_digest
from codegen._output import output_runs
from phs.signals import Sampled

_PLANS: dict = {}
"""Plans by (time grid, inputs), oldest dropped first beyond :data:`_PLANS_KEPT`."""
_PLANS_KEPT = 8
_TEMPLATES: dict = {}
"""The input templates' numpy functions by key (:func:`codegen._inputs.segment_inputs`)."""


@dataclasses.dataclass
class Plan:
    """The segments of a simulation and its integrator calls (:class:`codegen._output.OutputRun`), with
    the inputs on the grid (``U``, ``(len(t), n_inputs)``: copy it, it is shared) and, per input, its
    samples baked into an interpolant with their digest (:func:`codegen._inputs.baked`) or None."""

    sigs: list
    segs: list
    slots: list
    sampled: list
    runs: list
    U: np.ndarray
    origin: float = 0.0
    """The grid's first time: the segments, the runs and the signals ``sigs`` count time from it
    (:func:`codegen._inputs.shifted`); add it to a run's times to name them."""


def _key(t, sigs):
    """The cache key of a plan: the grid's digest and each input's (a sampled input by its samples, any
    other signal by itself); None when a signal cannot be a key."""
    parts = [digest([t])]
    for sg in sigs:
        if isinstance(sg, Sampled):
            d = sampled_digest(sg)
            # with how it enters (its kinks as breakpoints, its interpolant, its straight stretches)
            parts.append(("sampled", sg.hold, d, sg.kinks() is None, sg.lines().shape))
            continue
        try:
            hash(sg)
        except TypeError:
            return None
        parts.append(sg)
    return tuple(parts)


def plan_for(t, sigs, cuts=()) -> Plan:
    """The :class:`Plan` of a simulation on the grid ``t`` with the input signals ``sigs`` (one per input),
    computed once per grid and inputs; ``cuts``: further times at which a run must end
    (:func:`codegen._inputs.plan_segments`)."""
    key = _key(t, sigs)
    key = key + (tuple(float(c) for c in cuts),) if key is not None else None
    hit = _PLANS.get(key) if key is not None else None
    if hit is not None:
        return hit
    origin = float(t[0])  # the runs count time from the grid's start: absolute times lose the step's digits
    t = t - origin
    sigs = [shifted(sg, origin) for sg in sigs]
    cuts = tuple(float(c) - origin for c in cuts)
    segs, slots = plan_segments(sigs, t, cuts)
    sampled = [(*baked(sg), digest(baked(sg))) if baked(sg) is not None else None for sg in sigs]
    U = np.zeros((len(t), len(sigs)))
    runs = list(output_runs(t, sigs, segs, lambda choice, times, ms: segment_inputs(sigs, slots, choice, times, _TEMPLATES, ms), U))
    plan = Plan(list(sigs), segs, slots, sampled, runs, U, origin)
    if key is not None:
        while len(_PLANS) >= _PLANS_KEPT:
            _PLANS.pop(next(iter(_PLANS)))
        _PLANS[key] = plan
    return plan
