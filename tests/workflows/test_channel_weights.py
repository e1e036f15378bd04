"""Maximum-likelihood channel weights (``identify(..., weights="ml")``) and the floored BIC.

With the right model the residual of each channel is its noise, so the maximum-likelihood weights
must come out as one over each channel's noise standard deviation.  The concealed-effect control
(``none``) has 1 % of the position's range and 3 % of the current's standard deviation as noise: two
channels whose noise differs by orders of magnitude in their units.  3000 samples estimate a standard
deviation to about 1.3 % (1/sqrt(2N)); the fit absorbs three degrees of freedom; 5 % is the tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest

from examples.concealed_effects import NOMINAL_FREE, generate
from phs import ParameterError
from phs.workflows.diagnose.hypotheses import bic
from phs.workflows.identify import identify
from phs.workflows.identify.coordinates import CHANNEL_FLOOR, channel_sigma
from systems.electrostatic_actuator import electrostatic_actuator


@pytest.fixture(scope="module")
def control():
    return generate("none", seconds=3.0, seed=5)


def test_ml_weights_are_one_over_each_channel_noise(control):
    rec, info = control
    fit = identify(electrostatic_actuator(), rec, list(NOMINAL_FREE), weights="ml", rtol=1e-7)
    for ch, sd in info["noise_std"].items():
        assert fit.weights[ch] * sd == pytest.approx(1.0, abs=0.05), (ch, fit.weights[ch], sd)
    # the default weights (1 / std of each channel) are not the noise's: the check above can fail
    plain = identify(electrostatic_actuator(), rec, list(NOMINAL_FREE), rtol=1e-7)
    assert any(abs(plain.weights[ch] * sd - 1.0) > 0.5 for ch, sd in info["noise_std"].items())
    # both fits reach the same parameters within their intervals (the model is right: weights only
    # change the efficiency)
    for k in NOMINAL_FREE:
        lo, hi = plain.intervals[k]
        assert lo <= fit.values[k] <= hi


def test_a_perfect_channel_is_floored_and_cannot_decide_the_criterion():
    y = np.sin(np.linspace(0, 20, 2001))
    assert channel_sigma(np.zeros_like(y), y) == pytest.approx(CHANNEL_FLOOR * np.std(y))
    floors = {"a": CHANNEL_FLOOR * np.std(y), "b": 0.0}
    # channel a improves from 1e-9 to 1e-12 of its variance (far below anything physical): no change;
    # channel b's identical change counts in full
    assert bic({"a": 1e-9, "b": 1.0}, 2001, 3, floors) == pytest.approx(bic({"a": 1e-12, "b": 1.0}, 2001, 3, floors))
    assert bic({"a": 1.0, "b": 1e-12}, 2001, 3, floors) < bic({"a": 1.0, "b": 1e-9}, 2001, 3, floors) - 1e4


def test_unknown_weighting_is_refused(control):
    rec, _ = control
    with pytest.raises(ParameterError, match="weights must be a dict of channel weights or 'ml', got 'max'"):
        identify(electrostatic_actuator(), rec, ["k"], weights="max")


def test_ml_fit_started_from_its_own_weights_needs_no_reweighting(control):
    rec, _ = control
    first = identify(electrostatic_actuator(), rec, list(NOMINAL_FREE), weights="ml", rtol=1e-7)
    again = identify(electrostatic_actuator().with_params(first.values), rec, list(NOMINAL_FREE), weights="ml",
                     ml_start=dict(first.weights), rtol=1e-7)
    one = identify(electrostatic_actuator().with_params(first.values), rec, list(NOMINAL_FREE),
                   weights=dict(first.weights), rtol=1e-7)
    # started at the weights it ends with, the maximum-likelihood fit is that one fit with those weights
    assert again.iterations == one.iterations
    assert again.weights == pytest.approx(first.weights, rel=0.1)
    # from the default weights it needs re-weighting passes: the comparison above can fail
    assert first.iterations > one.iterations
    with pytest.raises(ParameterError, match="ml_start .* needs weights='ml'"):
        identify(electrostatic_actuator(), rec, ["k"], ml_start=dict(first.weights))
