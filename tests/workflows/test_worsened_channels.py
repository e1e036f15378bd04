"""No accepted effect lowers another channel's validation fit beyond what that channel's noise allows
(``phs.workflows.diagnose.ranking.worsened`` and ``WORSE_Z``; ``_pick`` passes over such a hypothesis and the
verdict says so).

The threshold is checked against its own statistics: two simulated courses equally far from the truth on
either side (a rise of the residual that only the noise makes) are flagged at the normal tail's rate
``P(Z > WORSE_Z)``, a course moved away from the truth by half a noise level RMS is flagged every time, and
one moved by a systematic rise smaller than the residual sum's own spread across draws of the noise
(significant, not material) never."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np

from phs.workflows.diagnose.hypotheses import Scored
from phs.workflows.diagnose.ranking import WORSE_Z, _pick, worsened
from phs.workflows.diagnose.report import worsening_sentence

N = 2000
T = np.linspace(0.0, 2.0, N)
TRUTH = {"x": np.sin(2 * np.pi * T), "i": np.cos(3 * np.pi * T)}
SHAPE = np.sin(5 * np.pi * T) * np.exp(-T)  # how a hypothesis moves a channel's course


def _data(seed, sigma=0.05):
    rng = np.random.default_rng(seed)
    y = {ch: TRUTH[ch] + sigma * rng.standard_normal(N) for ch in TRUTH}
    return NS(outputs=["x", "i"], validation=y, val_mask=np.ones(N, bool))


def _course(x, i, fits=(90.0, 90.0)):
    return NS(simulated={"validation": {"x": x, "i": i}}, validation_fit_percent={"x": fits[0], "i": fits[1]})


def test_rises_that_only_the_noise_makes_are_flagged_at_the_normal_tail_rate():
    # before and after lie on either side of the truth, equally far: the rise's expectation is zero and its
    # spread is the noise's (2σ|δ|); |δ| is 40 noise levels in norm, so that this spread (80 σ²) is above the
    # residual sum's own spread σ²√(2N) = 63 σ² and the significance part of the rule is the one that decides
    delta = 40 * 0.05 * SHAPE / np.linalg.norm(SHAPE)
    before, after = _course(TRUTH["x"] - delta / 2, TRUTH["i"]), _course(TRUTH["x"] + delta / 2, TRUTH["i"])
    flagged = sum("x" in worsened(before, after, _data(seed)) for seed in range(2000))
    expected = 0.5 * math.erfc(WORSE_Z / math.sqrt(2))  # 2.3 %
    # the binomial spread on 2000 draws is 0.33 points; the noise level is estimated from each recording
    # (second differences), which widens the rate a little: ±1.1 points
    assert abs(flagged / 2000 - expected) < 0.011


def test_a_course_moved_away_from_the_truth_is_flagged_every_time():
    # after = the truth moved by 0.5 noise levels RMS: a rise of |δ|² = 0.25 σ² N = 500 σ², against the
    # thresholds 2·WORSE_Z σ|δ| = 89 σ² and WORSE_Z σ²√(2N) = 126 σ², and a noise part of standard deviation 45 σ²
    delta = 0.5 * 0.05 * math.sqrt(N) * SHAPE / np.linalg.norm(SHAPE)
    before, after = _course(TRUTH["x"], TRUTH["i"]), _course(TRUTH["x"] + delta, TRUTH["i"])
    assert all("x" in worsened(before, after, _data(seed)) for seed in range(50))
    # and never the channel it left alone
    assert not any("i" in worsened(before, after, _data(seed)) for seed in range(50))


def test_a_significant_rise_smaller_than_the_noise_spread_of_the_sum_is_not_flagged():
    # after = the truth moved by |δ|² = 50 σ²: the rise (50 σ², noise part of standard deviation 2σ|δ| = 14 σ²)
    # is above the significance threshold 2·WORSE_Z σ|δ| = 28 σ² in most draws, but far below the residual
    # sum's own spread across draws of the noise (WORSE_Z σ²√(2N) = 126 σ²): another recording would show the
    # two courses in either order, so the fit does not fall beyond what the noise allows
    sigma = 0.05
    delta = math.sqrt(50.0) * sigma * SHAPE / np.linalg.norm(SHAPE)
    before, after = _course(TRUTH["x"], TRUTH["i"]), _course(TRUTH["x"] + delta, TRUTH["i"])
    significant = 0
    for seed in range(50):
        data = _data(seed, sigma)
        y = data.validation["x"]
        rise = float(np.sum((y - after.simulated["validation"]["x"]) ** 2) - np.sum((y - before.simulated["validation"]["x"]) ** 2))
        significant += rise > WORSE_Z * 2 * sigma * float(np.linalg.norm(delta))
        assert worsened(before, after, data) == {}
    assert significant >= 40  # the significance part alone would flag most (expected 94 %)


def _scored(label, effect, vfits, x, i, rss, bic):
    return Scored(label, None, {}, np.zeros(1), 1, dict(vfits), dict(vfits), rss, rss, bic, {}, {"validation": {"x": x, "i": i}},
                  0.0, augmentation=NS(effect=effect, attached_to="V", element=None))


def test_the_choice_passes_over_an_effect_that_trades_one_channel_for_another():
    data = _data(7)
    off = 0.4 * SHAPE  # 0.4 against a noise of 0.05: far beyond it
    nominal = _scored("nominal", "", {"x": 80.0, "i": 95.0}, TRUTH["x"] + off, TRUTH["i"], 10.0, 0.0)
    # the better gain, but it moves the current's course away from the truth
    trade = _scored("slew_rate_limit@V", "slew_rate_limit", {"x": 99.0, "i": 80.0}, TRUTH["x"], TRUTH["i"] + off, 2.0, -500.0)
    honest = _scored("series_resistance@V", "series_resistance", {"x": 92.0, "i": 95.0}, TRUTH["x"] + off / 2, TRUTH["i"], 6.0, -100.0)
    assert _pick(nominal, [trade, honest], data) is honest
    assert list(trade.worsens) == ["i"] and trade.worsens["i"] == (95.0, 80.0) and not honest.worsens
    # without the data (no courses to compare) the rule cannot apply and the better gain wins
    assert _pick(nominal, [trade, honest]) is trade
    # the only improving hypothesis trades channels: nothing is named, and the explanation says why
    assert _pick(nominal, [trade], data) is None
    text = worsening_sentence([trade])
    assert "slew_rate_limit at V" in text and "i 95.00 → 80.00 %" in text


def test_the_rule_reads_the_channels_through_the_validation_mask():
    # a rise only outside the validation part does not count
    data = _data(3)
    data.val_mask = T >= 1.0
    off = np.where(T < 1.0, 0.5, 0.0)
    before, after = _course(TRUTH["x"], TRUTH["i"]), _course(TRUTH["x"] + off, TRUTH["i"])
    assert worsened(before, after, data) == {}
    data.val_mask = np.ones(N, bool)
    assert "x" in worsened(before, after, data)


def test_a_none_verdict_whose_best_trades_channels_says_so_in_its_first_sentence():
    # the best candidate passes the fit rule (validation residual -20 %, BIC -50) and was refused only because
    # it lowers another channel's validation fit: the verdict must not open with "no candidate improves the fit"
    from phs.workflows.diagnose.hypotheses import Scored
    from phs.workflows.diagnose.report import explanation

    aug = NS(effect="offset", attached_to="position", component="Offset", summary="", free=[], element=None)
    nominal = Scored("nominal", None, {}, np.zeros(2), 3, {}, {}, 1.0, 1.0, 100.0, {}, {}, 0.1)
    best = Scored("offset@position", None, {}, np.zeros(2), 4, {}, {}, 0.8, 0.8, 50.0, {}, {}, 0.1, aug)
    best.worsens = {"current": (94.7, 92.2)}
    text = explanation(nominal, [], [], best, ["position", "current"])
    assert text.startswith("No missing physics accepted: the best candidate, offset at position, improves the fit "
                           "(validation residual −20.0 % (fell), ΔBIC -50.0) only by lowering another channel's."), text
    assert "beyond what noise explains" not in text
    # a best candidate that trades channels but would not pass the fit rule anyway (validation residual -0.5 %)
    plain = Scored("offset@position", None, {}, np.zeros(2), 4, {}, {}, 0.995, 0.995, 99.0, {}, {}, 0.1, aug)
    plain.worsens = {"current": (94.7, 92.2)}
    assert explanation(nominal, [], [], plain, ["position"]).startswith("No missing physics found: no candidate improves")
