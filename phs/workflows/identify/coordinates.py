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


CHANNEL_FLOOR = 1e-3
"""Smallest residual standard deviation a channel is credited with, as a share of the channel's own
standard deviation (a fit of 99.9 %): below it quantisation, timing jitter and the integrator's
tolerance dominate, not physics, and a channel that close to perfect would otherwise drown the others
in a maximum-likelihood weighting."""


def _channel_weights(recording, outputs, weights) -> dict:
    """Weight per fitted channel: ``weights`` where given, else ``1 / std`` of the measured channel."""
    w = {ch: 1.0 / max(float(np.std(recording[ch])), 1e-300) for ch in outputs}
    w.update(dict(weights or {}))
    return w


def channel_sigma(residual, measured, floor: float = CHANNEL_FLOOR) -> float:
    """Maximum-likelihood standard deviation of one channel's residual, floored at ``floor`` times the
    measured channel's standard deviation (:data:`CHANNEL_FLOOR`).

    Examples
    --------
    >>> y = np.sin(np.linspace(0, 6, 601))
    >>> round(channel_sigma(0.02 * np.cos(np.arange(601)), y), 4)       # a residual of RMS 0.02 / sqrt(2)
    0.0142
    >>> bool(channel_sigma(np.zeros(601), y) == 1e-3 * np.std(y))        # a perfect channel is floored
    True
    """
    r = np.asarray(residual, dtype=float)
    sd = float(np.std(np.asarray(measured, dtype=float))) or 1.0
    return max(float(np.sqrt(np.mean(r**2))) if r.size else 0.0, floor * sd, 1e-300)


def ml_weights(residuals: dict, recording, outputs) -> dict:
    """Weights ``1 / sigma`` per channel, ``sigma`` from :func:`channel_sigma` of each channel's residual:
    the weighting under which least squares is maximum likelihood with one unknown variance per channel.

    Examples
    --------
    >>> t = np.linspace(0, 1, 101)
    >>> class Rec(dict):
    ...     pass
    >>> rec = Rec(a=np.sin(6 * t), b=100 * np.cos(6 * t))
    >>> w = ml_weights({"a": 0.01 * np.ones(101), "b": 2.0 * np.ones(101)}, rec, ["a", "b"])
    >>> round(w["a"]), round(w["b"], 2)
    (100, 0.5)
    """
    return {ch: 1.0 / channel_sigma(residuals[ch], recording[ch]) for ch in outputs}


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
