"""Validation samples that depend on when, between two samples, a recorded input changed abruptly.

A recorded input that changes abruptly (a held edge, a staircase's step, a PRBS bit: :func:`phs.kinks.abrupt_runs`)
changes somewhere between two of its samples; the samples say only between which, and a simulation replays the
change as the straight line through them.  Where the response follows the input fast (the current into a
capacitive load), the output samples right after such a change depend on when in the sample period it took
place, which no model of the recording can know.  A handful of such samples can outweigh the rest of a
validation residual: on the electrostatic actuator's lab recording at 2 kHz (``examples/lab_protocols.py``,
``esa:none@2kHz``, whose held edges straddle samples) the truth itself, replayed from the samples, misses 12
current samples by up to 350 times the noise, its validation residual is 26 times what the noise leaves, and any
concealed effect then explains a small share of "what the nominal model misses" (a leakage 0.012).

:func:`timing_mask` finds those samples with the fitted nominal model: it replays every abrupt change in the first
half of its sample interval and in the second (:func:`halved_course`: both through the same samples), and leaves
out of the validation scores the samples where the two replays differ by more than ``√12 σ`` in any channel (a
change time spread evenly between the two then varies the sample more than the channel's noise ``σ`` does), at
most :data:`TIMING_SHARE` of them (the largest); but only the samples of a change that the model replayed no better
than its timing allows (:data:`TIMING_EVIDENCE`): where the straight lines are the input's course (a simulation's
own output, a command that is truly a ramp between samples), the samples are evidence like any other.
On that recording: 12 of 34 001 samples (the six edges that straddle a sample), after which the truth's residual
there is 0.3 % of the noise's.
An input declared held (``zoh``: it changes at a sample) or given by its law changes where the recording says,
and is not replayed shifted.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from phs.kinks import abrupt_runs

TIMING_EVIDENCE = 0.05
"""An abrupt change's samples are left out only when the model's residual there is at least this share of the spread
its timing gives them (``Σ r² ≥ TIMING_EVIDENCE · Σ d²/12`` over them, in noise units): when the change took place
at a uniformly random time within its interval, the ratio is ``12 (U − ½)²`` with ``U`` uniform (mean 1, below 0.05
with probability 6.5 %, then the lines replay it nearly right anyway); when the straight lines are the input's
course (a simulation's own output) it is the model's error over the timing's spread.  Measured per change: the lab
recording ``esa:none@2kHz``'s six edges that straddle a sample 0.41-4.8, its 65 edges on the sample grid at most
0.0011; on the 3 s concealed recordings of ``examples/concealed_effects.py`` (a series resistance at full strength,
a hysteresis at 0.35) at most 0.0043."""

TIMING_SHARE = 0.05
"""Largest share of the validation samples :func:`timing_mask` leaves out (those whose replays differ most,
against their channel's noise).  A recording of steps every few samples (a fast PRBS into a fast response)
would otherwise lose most of its samples; the lab recordings' held edges take 0.04 % (2 kHz) to 0.14 % (500 Hz)."""


def halved_course(t, values, runs, early: bool):
    """``(times, values)``: the samples' straight lines with every interval of the abrupt runs ``(s, e)``
    (:func:`phs.kinks.abrupt_runs`) changed in its first half (``early``) or its second half instead, then flat:
    two courses through the same samples whose changes take place half a sample period apart, between which
    the straight line through the samples lies.

    Examples
    --------
    >>> t = np.arange(5.0); u = np.array([0.0, 0.0, 1.0, 1.0, 1.0])
    >>> times, values = halved_course(t, u, [(1, 2)], early=True)
    >>> times.tolist(), values.tolist()
    ([0.0, 1.0, 1.5, 2.0, 3.0, 4.0], [0.0, 0.0, 1.0, 1.0, 1.0, 1.0])
    >>> halved_course(t, u, [(1, 2)], early=False)[1].tolist()
    [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
    """
    t, v = np.asarray(t, float), np.asarray(values, float)
    k = np.array([i for s, e in runs for i in range(s, e)], dtype=int)
    times = np.concatenate([t, 0.5 * (t[k] + t[k + 1])])
    vals = np.concatenate([v, v[k + 1] if early else v[k]])
    order = np.argsort(times, kind="stable")
    return times[order], vals[order]


def timing_mask(model, data) -> np.ndarray:
    """``data.val_mask`` without the validation samples that depend on when, within a sample period, an input
    read as continuous changed abruptly (the module's rule, with ``model``'s fitted system and initial state).
    The mask itself when no input changes abruptly or a replay fails.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> from codegen import simulate
    >>> from phs.signals import Sampled
    >>> sys_ = rc_circuit()                                    # a time constant of 1 ms: faster than a sample
    >>> t = np.arange(400) * 0.01
    >>> course = Sampled((0.0, 1.003, 1.0031, 2.497, 2.4971, 4.0), (0.0, 0.0, 1.0, 1.0, 0.0, 0.0))  # steps between samples
    >>> u = np.array([course(x) for x in t])                  # the command as recorded
    >>> noise = 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    >>> def data_of(y):
    ...     rec = Recording.from_arrays(t, {"U": u, "v_C": y + noise})
    ...     return Data(rec, rec, np.ones(t.size, bool), None, ["v_C"], [], {}, [], None)
    >>> model = NS(system=sys_, x0=np.zeros(1))
    >>> np.flatnonzero(~timing_mask(model, data_of(simulate(sys_, t, u={"U": course})["v_C"]))).tolist()
    [101, 250]
    >>> bool(timing_mask(model, data_of(simulate(sys_, t, u={"U": u})["v_C"])).all())   # the lines are the course
    True
    """
    from phs.workflows.diagnose.element_search import _simulate
    from phs.workflows.diagnose.mismatch import noise_level
    from phs.workflows.identify.coordinates import CHANNEL_FLOOR

    val, mask = data.validation, np.asarray(data.val_mask, bool)
    line = (getattr(model, "simulated", None) or {}).get("validation")
    inputs = [u for u in model.system.input_names
              if u in val.signals and val.holds.get(u, "linear") == "linear" and u not in val.between]
    runs = {u: abrupt_runs(val[u]) for u in inputs}
    runs = {u: r for u, r in runs.items() if r}
    if not runs or len(val) < 3:
        return mask
    try:
        early, late = (_simulate(model.system, replace(val, between={**val.between, **{u: halved_course(val.t, val[u], r, side)
                                                                                          for u, r in runs.items()}}), model.x0)
                       for side in (True, False))
        line = line if line is not None else _simulate(model.system, val, model.x0)
        excess, missed, spread = np.zeros(len(val)), np.zeros(len(val)), np.zeros(len(val))
        for ch in data.outputs:
            y = np.asarray(val[ch], float)
            sigma = max(noise_level(y[mask]), CHANNEL_FLOOR * float(np.std(y[mask])), 1e-300)
            d = (np.asarray(early[ch], float) - np.asarray(late[ch], float)) / sigma
            excess = np.maximum(excess, np.abs(d) / math.sqrt(12.0))
            missed += ((y - np.asarray(line[ch], float)) / sigma) ** 2
            spread += d**2 / 12.0
    except Exception:  # noqa: BLE001 - a replay that fails leaves the scores as they were
        return mask
    if not (np.all(np.isfinite(excess)) and np.all(np.isfinite(missed))):
        return mask
    # each sample the timing moves belongs to the last abrupt change before it; a change whose samples the straight
    # lines replay far better than its timing would allow (a simulation's own output) keeps them
    starts = np.array(sorted({s for r in runs.values() for s, _ in r}))
    owner = np.searchsorted(starts, np.arange(len(val)), side="left") - 1
    moved = mask & (excess > 1.0)
    for k in np.unique(owner[moved]):
        group = moved & (owner == k)
        if missed[group].sum() < TIMING_EVIDENCE * spread[group].sum():
            excess[group] = 0.0
    out = excess <= 1.0
    drop = np.flatnonzero(mask & ~out)
    cap = int(TIMING_SHARE * int(mask.sum()))
    if len(drop) > cap:  # the largest only
        keep = drop[np.argsort(-excess[drop])[cap:]]
        out[keep] = True
    return mask & out


def without_timing_samples(nominal, data):
    """``(nominal, data)`` with :func:`timing_mask` applied: the validation mask without the samples an abrupt
    input change's timing decides, and the nominal model's validation scores recomputed on what is left
    (from its validation course, without simulating again); both unchanged when no sample is left out.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> from phs.workflows.recording import Recording
    >>> t = np.linspace(0, 1, 11)
    >>> rec = Recording.from_arrays(t, {"U": np.zeros(11), "y": np.sin(t)})
    >>> data = Data(rec, rec, np.ones(11, bool), None, ["y"], [], {}, [], None)
    >>> h = NS(system=NS(input_names=["U"]), x0=np.zeros(1))
    >>> without_timing_samples(h, data) == (h, data)          # a constant input: nothing changes abruptly
    True
    """
    from phs.workflows.diagnose.scoring import _channel_rss
    from phs.workflows.identify import nrmse_fit

    mask = timing_mask(nominal, data)
    vsims = (getattr(nominal, "simulated", None) or {}).get("validation")
    if int(mask.sum()) == int(np.asarray(data.val_mask, bool).sum()) or not vsims:
        return nominal, data
    data = replace(data, val_mask=mask)
    val = data.validation
    w = data.weights if isinstance(data.weights, dict) else None
    vrss, _ = _channel_rss(val, vsims, data.outputs, mask, weights=w)
    vfits = {ch: nrmse_fit(np.asarray(val[ch])[mask], np.asarray(vsims[ch])[mask]) for ch in data.outputs}
    return replace(nominal, validation_rss=vrss, validation_fit_percent=vfits), data
