"""What the residuals of a fitted model show: the measurement noise of a channel, the model signals along the
recording, the located mismatch (:mod:`phs.workflows.diagnose.locate`) and whether structure is left."""

from __future__ import annotations

import math

import numpy as np


def noise_level(y) -> float:
    """Standard deviation of white measurement noise estimated from second differences
    (``std(Δ²y)/√6``; smooth signal content sampled fast contributes little).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.linspace(0, 1, 5001)
    >>> round(noise_level(np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(t.size)), 3)
    0.01
    """
    y = np.asarray(y, float)
    return float(np.std(np.diff(y, 2)) / math.sqrt(6.0)) if y.size > 3 else 0.0


def _features(scored, system, data) -> tuple[dict, dict]:
    """Model signals along the training recording for locating: states, velocities (``v:`` + momentum
    state), inputs; and the inputs separately."""
    from components.candidates import momentum_states
    from phs.workflows.diagnose.hypotheses import train_result

    res = train_result(scored, data)
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


def _structured(h, noise, outs) -> bool:
    """Residual RMS above 1.5 times the noise in some channel."""
    for ch in outs:
        r = h.residuals.get(ch)
        if r is not None and noise.get(ch, 0) > 0 and float(np.sqrt(np.mean(r**2))) > 1.5 * noise[ch]:
            return True
    return False
