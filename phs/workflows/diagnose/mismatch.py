"""What the residuals of a fitted model show: the measurement noise of a channel, the model signals along the
recording, the located mismatch (:mod:`phs.workflows.diagnose.locate`) and whether structure is left."""

from __future__ import annotations

import math

import numpy as np


def noise_level(y) -> float:
    """Standard deviation of white measurement noise estimated from second differences: the smaller of
    ``std(Δ²y)/√6`` and ``1.4826 MAD(Δ²y)/√6`` (their median absolute deviation; smooth signal content
    sampled fast contributes little to either).  Sparse fast transients (a capacitor's current at every step
    of its voltage, an impact) inflate the standard deviation, not the median: on the electrostatic
    actuator's current under a square-wave program the first alone reads 33 times the noise added, the
    second within 2 % of it.  A quantised or held channel, whose second differences are mostly exactly
    equal (a median absolute deviation of zero), keeps the first.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.linspace(0, 1, 5001)
    >>> round(noise_level(np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(t.size)), 3)
    0.01
    >>> spikes = np.where(np.arange(t.size) % 500 == 0, 5.0, 0.0)   # a current's spike at every step
    >>> round(noise_level(spikes + 0.01 * rng.standard_normal(t.size)), 3)
    0.01
    >>> noise_level(np.round(np.sin(2 * np.pi * t), 2)) > 0      # quantised: the standard deviation's estimate
    True
    """
    y = np.asarray(y, float)
    if y.size <= 3:
        return 0.0
    by_std = float(np.std(np.diff(y, 2))) / math.sqrt(6.0)
    by_median = median_noise(y)
    return min(by_std, by_median) if by_median > 0 else by_std


def median_noise(y) -> float:
    """White-noise std from the median absolute deviation of second differences (``1.4826 MAD / √6``): zero for
    a quantised or held channel (most second differences exactly equal).

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> round(median_noise(0.01 * rng.standard_normal(20000)), 3), median_noise(np.repeat([0.0, 1.0], 50))
    (0.01, 0.0)
    """
    d = np.diff(np.asarray(y, float), 2)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(6.0)) if d.size else 0.0


def _features(scored, system, data) -> tuple[dict, dict]:
    """Model signals along the training recording for locating: states, velocities (``v:`` + momentum
    state), inputs; and the inputs separately.  Where the model cannot be integrated along the recording at
    either tolerance (:func:`~phs.workflows.diagnose.hypotheses.train_result`), no model signal and the
    recorded inputs, with a warning: the mismatch is then located against the inputs alone (when, at which
    input's steps, at which frequencies, whether it is white), and the diagnosis goes on."""
    import warnings

    from components.candidates import momentum_states
    from phs.errors import PHSError
    from phs.workflows.diagnose.hypotheses import train_result

    try:
        res = train_result(scored, data)
    except PHSError as err:
        warnings.warn(f"diagnose: {scored.label} cannot be integrated along the training recording ({err}); its mismatch "
                      "is located against the recorded inputs alone", RuntimeWarning, stacklevel=3)
        return {}, {n: np.asarray(data.recording[n], float) for n in system.input_names if n in data.recording.signals}
    feats = {name: np.asarray(res[name]) for name in system.state_names}
    inputs = {name: np.asarray(res[name]) for name in system.input_names}
    if momentum_states(system):
        grad = system.with_params(scored.values).lambdify(system.grad_H, with_u=False)
        X = np.asarray(res.x)
        G = np.array([np.asarray(grad(x), float).reshape(-1) for x in X])
        for p in momentum_states(system):
            feats[f"v:{p}"] = G[:, system.state_names.index(p)]
    return feats, inputs


def _locate(scored, system, data, noise):
    from phs.workflows.diagnose.locate import locate

    feats, inputs = _features(scored, system, data)
    return locate(data.recording.t, scored.residuals, feats, inputs, noise_std=noise)


STRUCTURED = 1.5
"""A residual whose RMS exceeds this many times the channel's noise level (:func:`noise_level`) is
structure left, whatever its colour: one of the two tests (with the whiteness test of the located
mismatch) that open a later round of the diagnosis, send it to discovery and keep a partial verdict's
confidence scaled (``verdict.residual_above_noise``).  At 1.5 a residual holds at least 1.25 noise
variances of unexplained signal; on 20 000 samples a second effect can leave less (a residual of 1.0-1.3
times the noise), which the whiteness test catches instead."""


def _structured(h, noise, outs) -> bool:
    """Residual RMS above :data:`STRUCTURED` times the noise in some channel."""
    for ch in outs:
        r = h.residuals.get(ch)
        if r is not None and noise.get(ch, 0) > 0 and float(np.sqrt(np.mean(r**2))) > STRUCTURED * noise[ch]:
            return True
    return False
