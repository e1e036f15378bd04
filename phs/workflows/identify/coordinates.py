"""The coordinates a fit works in: parameters in log scale, bounds, and the weight of each channel.

A free parameter ``p`` is fitted as ``p / p_start``, or as ``log(p / p_start)`` when its declared
range spans decades; an estimated initial state ``x`` as ``x / s`` with the simulator's scale ``s``
(see :class:`phs.workflows.identify.sensitivities._Problem`).
"""

from __future__ import annotations

import numpy as np

from phs.errors import ParameterError


def _log_scaled(system, free, log_scale) -> list:
    """The free parameters fitted in log scale: ``log_scale`` (those of them that are free), or by
    default those whose declared range spans at least 1.5 decades."""
    if log_scale is None:
        return [k for k in free if system.param(k).value > 0 and system.param(k).range[0] > 0
                and system.param(k).range[1] / system.param(k).range[0] >= 10**1.5]
    log_scaled = [k for k in log_scale if k in free]
    bad = [k for k in log_scaled if system.param(k).value <= 0]
    if bad:
        raise ParameterError(f"identify: log scale needs positive values; {bad} are not positive")
    return log_scaled


def _channel_weights(recording, outputs, weights) -> dict:
    """Weight per fitted channel: ``weights`` where given, else ``1 / std`` of the measured channel."""
    w = {ch: 1.0 / max(float(np.std(recording[ch])), 1e-300) for ch in outputs}
    w.update(dict(weights or {}))
    return w


def _bounds(system, free, log_scaled, nominal, bounds, estimate_x0, scale) -> tuple[list, list]:
    """Lower and upper bounds in fit coordinates of the free parameters (``bounds`` in their units,
    default each one's declared range; ``nominal`` their starting values) and of the estimated
    initial states (their declared ranges)."""
    lo, hi = [], []
    bounds = dict(bounds or {})
    for i, k in enumerate(free):
        b = bounds.get(k, system.param(k).range)
        if not (len(b) == 2 and b[0] < b[1]):
            raise ParameterError(f"identify: bounds of {k!r} must be (lo, hi) with lo < hi, got {b}")
        nom = nominal[i]
        if k in log_scaled:
            if b[0] <= 0:
                raise ParameterError(f"identify: {k!r} is fitted in log scale; its lower bound must be positive")
            lo.append(np.log(b[0] / nom))
            hi.append(np.log(b[1] / nom))
        else:
            a, c = sorted((b[0] / nom, b[1] / nom)) if nom != 0 else (b[0], b[1])
            lo.append(a)
            hi.append(c)
    for name in estimate_x0:
        i = system.state_names.index(name)
        st = system.states[i]
        lo.append(st.range[0] / scale[i])
        hi.append(st.range[1] / scale[i])
    return lo, hi
