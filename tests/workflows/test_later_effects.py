"""A second effect behind the first (``phs.workflows.diagnose.run``): a next round runs when the accepted effect
leaves a residual above the noise or a coloured one (either alone), and names a later effect only when it adds at least
``LATER_SHARE`` of what the nominal model misses above the noise, every channel it misses counted alike (``_adds_share``,
``balanced_share``); one that would have been named
without that rule is listed in ``verdict.small_share`` and in the explanation.

On a concealed pair (charge retention in the dielectric and Coulomb friction on the plate, 4 s recordings of
``examples/concealed_effects.py``) the diagnosis names both; with the share raised between what the second adds
and what the first leaves, the second is fitted but not named and the verdict says why, with the share it adds;
raised above what the first leaves, no second round runs.  A leakage behind Coulomb friction, seen in the
current alone (whose spikes at every voltage step must not be read as noise), is named too.  A later effect
that reaches no more than the accepted model refitted by itself (``screening.refit_alone``) is not named.
"""

from __future__ import annotations

import importlib
from dataclasses import replace

import pytest

import phs.workflows.diagnose.run as run
from phs.workflows.diagnose import diagnose
from systems.electrostatic_actuator import electrostatic_actuator

ce = importlib.import_module("examples.concealed_effects")

PAIR = "charge_retention+coulomb_friction"


@pytest.fixture(scope="module")
def recordings():
    train, info = ce.generate(PAIR, seconds=4.0, seed=1)
    val, _ = ce.generate(PAIR, seconds=4.0, seed=2, validation=True)
    return train, val, info


def _diagnose(recordings):
    train, val, _ = recordings
    return diagnose(electrostatic_actuator(), train, validation=val, free=list(ce.NOMINAL_FREE), n_jobs=2)


@pytest.fixture(scope="module")
def named(recordings):
    return _diagnose(recordings)


def test_both_effects_of_a_concealed_pair_are_named(named, recordings):
    d = named
    assert sorted(d.verdict["effects"]) == sorted(recordings[2]["effects"])
    second = d.accepted[1]
    # what it adds beyond the first, recorded when it was chosen, is the difference of the two explained shares
    first_share = run.balanced_share(d.nominal, d.accepted[0], d.data, d.noise, run.RELEVANT)
    both_share = run.balanced_share(d.nominal, second, d.data, d.noise, run.RELEVANT)
    assert second.later_share == pytest.approx(both_share - first_share, abs=1e-9)
    assert second.later_share >= run.LATER_SHARE and "small_share" not in d.verdict


def test_a_later_effect_below_the_share_is_not_named_and_the_verdict_says_so(named, recordings, monkeypatch):
    # a share above what the second effect adds but below what the first leaves: the next round still runs
    # (something above the share is left), and the second effect is fitted but not named
    d = named
    left = 1.0 - run.balanced_share(d.nominal, d.accepted[0], d.data, d.noise, run.RELEVANT)
    adds = d.accepted[1].later_share
    assert left > adds + 0.01  # room for a share between the two (the first leaves more than the second explains)
    monkeypatch.setattr(run, "LATER_SHARE", 0.5 * (adds + left))
    d2 = _diagnose(recordings)
    assert d2.verdict["effects"] == [d.verdict["effects"][0]]
    listed = d2.verdict["small_share"]
    assert [x["hypothesis"] for x in listed] == [d.accepted[1].label]
    assert listed[0]["share"] == pytest.approx(adds, rel=1e-6)
    assert "Also fitted after the accepted effects but not named" in d2.verdict["explanation"]


def test_no_next_round_when_less_than_the_share_is_left(named, recordings, monkeypatch):
    # a share above what the first effect leaves: no later effect could add it, so no second round is fitted
    d = named
    left = 1.0 - run.balanced_share(d.nominal, d.accepted[0], d.data, d.noise, run.RELEVANT)
    monkeypatch.setattr(run, "LATER_SHARE", left + 0.01)
    d2 = _diagnose(recordings)
    assert d2.verdict["effects"] == [d.verdict["effects"][0]] and len(d2.rounds) == 1 and "small_share" not in d2.verdict


def test_a_second_effect_seen_in_the_current_alone_is_named():
    # leakage behind Coulomb friction: the friction is seen in the position, the leakage in the current only,
    # whose spikes at every voltage step once made its noise level read thirty times the noise added, so that
    # the friction's residual looked like noise and no second round ran; and the leakage's refit of the
    # nominal parameters shifts the position by 0.004 fit points, significant on 4 000 samples but far below
    # the spread of the position's residual sum across draws of the noise (ranking.WORSE_Z)
    pair = "leakage+coulomb_friction"
    train, info = ce.generate(pair, seconds=4.0, seed=1)
    val, _ = ce.generate(pair, seconds=4.0, seed=2, validation=True)
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(ce.NOMINAL_FREE), n_jobs=2)
    assert sorted(d.verdict["effects"]) == sorted(info["effects"]), d.summary()
    first, both = d.accepted[0].validation_fit_percent, d.final.validation_fit_percent
    assert both["current"] > first["current"] + 3.0  # measured 91.0 -> 96.7 %
    assert both["position"] > first["position"] - 0.05  # the position left where the first effect put it


def test_a_round_opens_on_a_coloured_residual_alone(named, recordings, monkeypatch):
    # the residual RMS test off (as when the first effect leaves less than 1.5 times the noise, on long
    # recordings where a few per cent above the noise is significant): the round opens on the residual's
    # colour, and the same second effect is named
    monkeypatch.setattr(run, "_structured", lambda *a: False)
    d2 = _diagnose(recordings)
    assert d2.verdict["effects"] == named.verdict["effects"] and len(d2.rounds) == 2
    assert d2.accepted[1].validation_rss == pytest.approx(named.accepted[1].validation_rss, rel=1e-6)


def test_a_later_effect_is_judged_against_the_accepted_model_refitted_alone(named, recordings, monkeypatch):
    # when the accepted model refitted by itself reaches what the second effect reaches, the second adds
    # nothing beyond a better fit of the first (a flat valley the later refits move along): not named
    second = named.accepted[1]
    calls = []

    def alone(current, data, joint=True):
        calls.append(joint)
        if not joint:
            return None  # the screening's reference unchanged
        # the accepted model with the second effect's scores, a training residual a little below the model's own
        return replace(current, rss=0.999 * current.rss, validation_rss=second.validation_rss, bic=second.bic,
                       validation_fit_percent=dict(second.validation_fit_percent),
                       simulated={**current.simulated, "validation": second.simulated["validation"]})

    monkeypatch.setattr(run, "refit_alone", alone)
    d2 = _diagnose(recordings)
    assert True in calls  # the judgement ran
    assert d2.verdict["effects"] == [named.verdict["effects"][0]]
