"""Scoring a fitted model against a recording: the channels' weights, the weighted residual and the BIC."""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.identify.coordinates import CHANNEL_FLOOR
from phs.workflows.recording import Recording


def weight_squared(weights, ch: str, y) -> float:
    """The squared weight of channel ``ch`` in every residual sum: ``weights[ch]²`` for a dict of weights,
    else ``1 / var(y)`` of the measured channel ``y`` (1 for a constant channel)."""
    return weights[ch] ** 2 if isinstance(weights, dict) else 1.0 / (float(np.var(np.asarray(y, float))) or 1.0)


def _channel_rss(rec: Recording, sims: dict, outputs, mask=None, weights=None) -> tuple[float, dict]:
    """Weighted total residual (``Σ_ch w_ch² RSS_ch``; without a dict of weights ``w_ch = 1 / std`` of the
    channel) and the per-channel residual sums of squares."""
    tot, per = 0.0, {}
    for ch in outputs:
        y, yh = np.asarray(rec[ch]), np.asarray(sims[ch])
        if mask is not None:
            y, yh = y[mask], yh[mask]
        per[ch] = float(np.sum((y - yh) ** 2))
        tot += per[ch] * weight_squared(weights, ch, y)
    return tot, per


def bic(per_channel_rss: dict, n_samples: int, n_params: int, floors: dict | None = None) -> float:
    """BIC of Gaussian residuals with one variance per channel: ``Σ_ch N ln(max(RSS_ch/N, f_ch²)) + k ln(N·n_ch)``.

    ``floors``: the smallest residual standard deviation each channel is credited with
    (:data:`~phs.workflows.identify.coordinates.CHANNEL_FLOOR` of its standard deviation), so that a
    channel fitted to its quantisation level does not decide the criterion by changes far below
    anything physical.

    Examples
    --------
    >>> round(bic({"y": 1.0}, 100, 2), 3)
    -451.307
    >>> bic({"y": 1e-12}, 100, 2, floors={"y": 1e-3}) == bic({"y": 1e-10}, 100, 2, floors={"y": 1e-3})
    True
    """
    n_ch = max(len(per_channel_rss), 1)
    floors = floors or {}
    s = sum(n_samples * math.log(max(v / n_samples, floors.get(ch, 0.0) ** 2, 1e-300)) for ch, v in per_channel_rss.items())
    return float(s + n_params * math.log(n_samples * n_ch))


def _floors(rec: Recording, outputs) -> dict:
    return {ch: CHANNEL_FLOOR * float(np.std(np.asarray(rec[ch], float))) for ch in outputs}
