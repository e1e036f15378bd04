"""What a model explains of what the reference misses, per channel and every channel counted alike
(``phs.workflows.diagnose.discover.naming.channel_shares``, ``balanced_share``): on one channel the same
share as the channels weighted together (``explained_share``, an independent computation from the weighted
residual sums rather than the fits); on two, a channel the reference misses far more does not hide what a
model explains of the other; a channel fitted to its noise has no room and is not counted."""

from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from phs.workflows.diagnose.discover.naming import balanced_share, channel_shares, explained_share
from phs.workflows.diagnose.mismatch import STRUCTURED, noise_level

T = np.linspace(0.0, 6.0, 1500)


def _data(signals: dict, mask=None):
    n = len(next(iter(signals.values())))
    return NS(validation=signals, val_mask=np.ones(n, bool) if mask is None else mask, outputs=list(signals))


def _model(data, fits: dict):
    """A stand-in for a scored model: its validation fits and the weighted residual sum they imply (the
    scores' default weights, one over the channel's variance over the scored samples)."""
    rss = 0.0
    for ch, f in fits.items():
        y = np.asarray(data.validation[ch], float)[data.val_mask]
        rss += (1.0 - f / 100.0) ** 2 * float(np.sum((y - y.mean()) ** 2)) / float(np.var(y))
    return NS(validation_fit_percent=dict(fits), validation_rss=rss)


@given(ref=st.floats(0.0, 99.0), better=st.floats(-50.0, 100.0), sigma=st.sampled_from([0.0, 0.003, 0.03]),
       drop=st.integers(0, 300))
def test_one_channel_shares_what_the_channels_weighted_together_share(ref, better, sigma, drop):
    # the reference's fit ``ref`` %, the model's anywhere from 50 points worse to perfect; white noise of std
    # ``sigma`` (none: no floor); the first ``drop`` samples left out of the scores (a timing mask)
    y = np.sin(2.0 * T) + sigma * np.random.default_rng(3).standard_normal(T.size)
    mask = np.arange(T.size) >= drop
    data = _data({"y": y}, mask)
    h_fit = min(100.0, ref + better * (100.0 - ref) / 100.0) if better >= 0 else ref + better
    reference, h = _model(data, {"y": ref}), _model(data, {"y": h_fit})
    noise = {"y": sigma}
    shares = channel_shares(reference, h, data, noise)
    floor = noise_level(y[mask]) if sigma else 0.0
    rms = (1.0 - ref / 100.0) * float(np.std(y[mask]))
    assert ("y" in shares) == (rms > STRUCTURED * floor)  # counted when the reference misses more than the noise
    if "y" in shares:
        # the weighted sums' share is the channel's, clipped to [0, 1] (the channel's may fall to −1)
        assert np.clip(shares["y"], 0.0, 1.0) == pytest.approx(explained_share(reference, h, data, noise), abs=1e-9)
        assert balanced_share(reference, h, data, noise) == shares["y"]
    else:
        assert balanced_share(reference, h, data, noise) == 0.0


def test_a_channel_missed_far_more_does_not_hide_the_other():
    # the reference misses the current far more (10 % fit) than the position (70 %); a model that raises only
    # the position's fit to 93 % explains 0.02 of the two weighted together and 0.86 of the position's mismatch
    rng = np.random.default_rng(0)
    data = _data({"position": np.sin(T) + 0.01 * rng.standard_normal(T.size),
                  "current": np.cos(9.0 * T) + 0.01 * rng.standard_normal(T.size)})
    noise = {"position": 0.01, "current": 0.01}
    reference = _model(data, {"position": 70.0, "current": 10.0})
    h = _model(data, {"position": 93.0, "current": 10.0})
    shares = channel_shares(reference, h, data, noise)
    assert shares["current"] == 0.0
    assert shares["position"] == pytest.approx(1.0 - (7.0 / 30.0) ** 2, abs=0.01)  # its noise floor aside
    assert explained_share(reference, h, data, noise) < 0.1
    assert balanced_share(reference, h, data, noise) == pytest.approx(shares["position"] / 2.0, abs=1e-12)
    # the channels' weights and units do not enter: the current in mA shares the same
    scaled = _data({"position": data.validation["position"], "current": 1e3 * data.validation["current"]})
    assert channel_shares(reference, h, scaled, {"position": 0.01, "current": 10.0}) == pytest.approx(shares, abs=1e-12)


def test_a_channel_fitted_to_its_noise_is_not_counted():
    # the reference already fits the current to its noise (a residual of the noise's RMS): only the position counts
    rng = np.random.default_rng(1)
    y = np.cos(9.0 * T)
    current = y + 0.05 * rng.standard_normal(T.size)
    at_noise = 100.0 * (1.0 - noise_level(current) / float(np.std(current)))
    data = _data({"position": np.sin(T) + 0.01 * rng.standard_normal(T.size), "current": current})
    noise = {"position": 0.01, "current": 0.05}
    reference = _model(data, {"position": 70.0, "current": at_noise})
    worse_current = _model(data, {"position": 90.0, "current": at_noise - 5.0})
    assert set(channel_shares(reference, worse_current, data, noise)) == {"position"}
    # without a noise floor (a noise-free channel) a channel whose residual is below ``relevant`` of its spread
    # is not counted either
    exact = _data({"position": np.sin(T), "current": y})
    ref = _model(exact, {"position": 70.0, "current": 99.995})
    assert set(channel_shares(ref, ref, exact, {}, relevant=0.01)) == {"position"}
    assert set(channel_shares(ref, ref, exact, {})) == {"position", "current"}
