"""A verdict that explains a small share of the mismatch says so, and its confidence falls with the share.

``phs.workflows.diagnose.ranking.partial``: below ``PARTIAL_BELOW`` (a half) of what the nominal model
misses above the noise floor, with a residual left above the noise, the confidence is multiplied by
``share / PARTIAL_BELOW``.  Checked on
the rule itself and on a diagnosis whose library cannot hold the truth: a drive clipping a PD loop's
force, diagnosed with the loop places removed (the controller's output not marked a command), where the
library's best imitates a little of the clip.
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from components.candidates.base import _rebuild
from examples.concealed_loops import NOMINAL_FREE, generate, nominal
from phs.workflows.diagnose import diagnose
from phs.workflows.diagnose.ranking import CALIBRATION, PARTIAL_BELOW, partial

V = {"effect": "cubic_stiffness", "effects": ["cubic_stiffness"], "confidence": 0.9, "explanation": "Missing physics: a spring.",
     "failed": [], "residual_above_noise": True}


@pytest.mark.parametrize("share, expected", [(0.0, 0.0), (0.05, 0.09), (0.25, 0.45), (0.49, 0.882)])
def test_the_confidence_falls_with_the_share_below_a_half(share, expected):
    out = partial({**V, "explained_share": share})
    assert out["confidence"] == pytest.approx(expected, abs=1e-3)
    assert f"explains only {100 * share:.0f} %" in out["explanation"] and out["explanation"].startswith(V["explanation"])
    assert out["effect"] == V["effect"] and out["effects"] == V["effects"]


def test_a_verdict_explaining_half_or_more_or_down_to_the_noise_and_none_are_untouched():
    for v in ({**V, "explained_share": PARTIAL_BELOW}, {**V, "explained_share": 0.97},
              {**V, "explained_share": 0.2, "residual_above_noise": False},
              {**V, "effect": "none", "effects": [], "explained_share": 0.0}):
        assert partial(v) == v


def test_a_library_effect_imitating_physics_the_library_lacks_is_not_named_with_confidence():
    train, _ = generate("drive_saturation", seconds=3.0, seed=1)
    val, _ = generate("drive_saturation", seconds=3.0, seed=2, validation=True)
    unmarked = nominal()
    unmarked = _rebuild(unmarked, measured=[replace(m, command=False) for m in unmarked.measured])
    d = diagnose(unmarked, train, validation=val, free=list(NOMINAL_FREE))
    v = d.verdict
    # the library's best (a quadratic drag, 33 %) explains a small part of the clip, and the confidence says so
    assert v["effect"] != "none" and v["explained_share"] < PARTIAL_BELOW, d.summary()
    assert v["residual_above_noise"] and "explains only" in v["explanation"], d.summary()
    # at most the highest calibrated level scaled by the share: 0.938 x 0.35 / 0.5 = 0.66 here, against 0.938 unscaled
    top = max(level for knots in CALIBRATION.values() for _, level in knots)
    assert v["confidence"] <= top * v["explained_share"] / PARTIAL_BELOW + 1e-3, d.summary()
    # (marked, the clip is found at the command and explains nearly all: tests/workflows/test_loop_elements.py)
