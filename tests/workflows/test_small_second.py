"""A second effect too small on the first it was fitted on, fitted on the first round's other firsts
(``phs.workflows.diagnose.pairs.first_for_small``).

A later effect is named only when it adds ``run.LATER_SHARE`` of what the nominal model misses beyond the
accepted ones.  A first effect that is a third law (a hysteresis loop where a viscoelastic creep and a cubic
stiffness act) takes up part of both: the second's share beyond it is small, and it would not be named.  The
second is then fitted on each other hypothesis of the first round that was fitted in full, passes the
acceptance rule and lowers no channel; a pair is named when the second adds its share beyond its first, the
pair passes the acceptance rule against the first alone lowering no channel (it is better than the best
single effect), and its first earns its place beside the second alone.

The rule is checked here on stand-ins (the pairs' fits replaced by given scores); the real case, the 20 s
concealed viscoelastic creep + cubic stiffness that was named ``hysteresis`` alone, is the slow test.
"""

from __future__ import annotations

import importlib
from types import SimpleNamespace as NS

import pytest

import phs.workflows.diagnose.pairs as pairs
from phs.workflows.diagnose.ranking import MIN_BIC_GAIN, MIN_VALIDATION_GAIN

ce = importlib.import_module("examples.concealed_effects")

BEFORE = NS(validation_rss=500.0, bic=0.0, label="nominal")


def _hyp(label, vrss, bic, n_params=4, rss=None, worsens=None, ok=True, stage="full", ref=BEFORE, share=None):
    effect, place = label.split("@")
    return NS(label=label, ok=ok, stage=stage, validation_rss=vrss, bic=bic, rss=vrss if rss is None else rss,
              n_params=n_params, worsens=worsens or {}, reference_rss=ref.validation_rss, reference_bic=ref.bic,
              augmentation=NS(effect=effect, attached_to=place, free=[f"{effect}.k"]), notes=[], simulated={},
              later_share=share)


FIRST = _hyp("hysteresis@m.p", 183.0, -49_000.0)
CREEP = _hyp("viscoelastic_creep@m.p", 216.0, -44_000.0)
OFFSET = _hyp("offset@position", 296.0, -28_000.0)
SECOND = _hyp("cubic_stiffness@x", 164.0, -61_000.0, n_params=5, ref=FIRST, share=0.049)
ALONE = _hyp("cubic_stiffness@x", 382.0, -3_500.0)
CANDS = [NS(effect="cubic_stiffness")]


def _run(monkeypatch, scores, first_round, alone=ALONE, adds=None):
    """``first_for_small`` with the pairs' fits replaced: ``scores[label]`` is the pair fitted on that first."""
    tried = []

    def fake(others, first, second, cand, data_before, data_r, progress=False, label=""):
        tried.extend(h.label for h in others)
        return [(h, scores[h.label], f"data of {h.label}") for h in others if h.label in scores]

    monkeypatch.setattr(pairs, "_on_firsts", fake)
    adds = adds or (lambda f, h: h.later_share >= 0.05)
    calls = []

    def fitted_alone():
        calls.append(1)
        return alone

    out = pairs.first_for_small(FIRST, SECOND, fitted_alone, BEFORE, first_round, CANDS, None, None, adds)
    assert len(calls) <= 1  # the second alone is fitted once at most
    return out, tried


def _pair(vrss, bic, share, n_params=6, on=CREEP):
    return _hyp("cubic_stiffness@x", vrss, bic, n_params=n_params, ref=on, share=share)


def test_the_pair_on_another_first_is_named_when_it_beats_the_first_alone(monkeypatch):
    pair = _pair(134.0, -63_000.0, 0.217)
    out, tried = _run(monkeypatch, {CREEP.label: pair}, [FIRST, CREEP])
    assert out == (CREEP, pair, "data of viscoelastic_creep@m.p")
    assert tried == [CREEP.label]
    assert "viscoelastic_creep@m.p was chosen as the first of the pair over hysteresis@m.p" in pair.notes[0]


def test_no_pair_when_the_second_adds_too_small_a_share_beyond_the_other_first(monkeypatch):
    pair = _pair(134.0, -63_000.0, 0.03)
    out, _ = _run(monkeypatch, {CREEP.label: pair}, [FIRST, CREEP])
    assert out is None and "adds too small a share" in SECOND.notes[-1]


def test_no_pair_that_is_not_better_than_the_first_alone(monkeypatch):
    # the pair's gain over its own first (the creep) is large, over the first alone too small: judged against
    # the first, whatever model the pair was fitted from
    worse = _pair(FIRST.validation_rss * (1 - MIN_VALIDATION_GAIN / 2), -63_000.0, 0.2)
    assert (CREEP.validation_rss - worse.validation_rss) / CREEP.validation_rss > 0.1
    out, _ = _run(monkeypatch, {CREEP.label: worse}, [FIRST, CREEP])
    assert out is None and "is no better than hysteresis@m.p alone" in SECOND.notes[-1]
    small_bic = _pair(134.0, FIRST.bic - MIN_BIC_GAIN / 2, 0.2)
    assert _run(monkeypatch, {CREEP.label: small_bic}, [FIRST, CREEP])[0] is None


def test_no_pair_whose_first_does_not_earn_its_place_beside_the_second_alone(monkeypatch):
    pair = _pair(134.0, -63_000.0, 0.217)
    alone = _hyp("cubic_stiffness@x", 135.0, -62_990.0)  # the second alone fits as well: the creep adds nothing
    out, _ = _run(monkeypatch, {CREEP.label: pair}, [FIRST, CREEP], alone=alone)
    assert out is None and "does not earn its place" in SECOND.notes[-1]


def test_only_accepted_firsts_that_lower_no_channel_are_tried(monkeypatch):
    trading = _hyp("offset@current", 200.0, -40_000.0, worsens={"current": (95.0, 90.0)})
    refused = _hyp("added_mass@m.p", 498.0, -10.0)  # neither the BIC nor the validation gain of the rule
    screened = _hyp("leakage@Q", 190.0, -40_000.0, stage="screening")
    same = _hyp("cubic_stiffness@x", 300.0, -20_000.0)  # the second's own effect
    failed = _hyp("time_delay@U", 100.0, -90_000.0, ok=False)
    elsewhere = _hyp("hysteresis@x", 250.0, -30_000.0)  # the first's effect at another place: a first too
    _, tried = _run(monkeypatch, {}, [FIRST, CREEP, trading, refused, screened, same, failed, OFFSET, elsewhere])
    assert tried == [CREEP.label, elsewhere.label, OFFSET.label]  # largest gain over the model before the first, first


def test_the_second_alone_is_fitted_only_for_a_pair_that_passes_the_other_tests(monkeypatch):
    calls = []
    monkeypatch.setattr(pairs, "_on_firsts", lambda others, *a, **k: [(CREEP, _pair(134.0, -63_000.0, 0.03), None)])
    out = pairs.first_for_small(FIRST, SECOND, lambda: calls.append(1), BEFORE, [FIRST, CREEP], CANDS, None, None,
                                lambda f, h: h.later_share >= 0.05)
    assert out is None and calls == []


def test_of_two_pairs_that_count_the_library_chooses_the_simpler_sufficient(monkeypatch):
    creep_pair = _pair(134.0, -63_000.0, 0.217, n_params=6)
    offset_pair = _pair(133.0, -63_100.0, 0.3, n_params=8, on=OFFSET)  # as good, two parameters more
    out, _ = _run(monkeypatch, {CREEP.label: creep_pair, OFFSET.label: offset_pair}, [FIRST, CREEP, OFFSET])
    assert out[0] is CREEP and out[1] is creep_pair
    assert any("With offset@position as its first instead the pair fits no better" in n for n in creep_pair.notes)


@pytest.mark.slow  # a 20 s diagnosis with two rounds: about 100 s
def test_a_creep_and_a_cubic_stiffness_are_named_over_a_hysteresis_alone():
    from phs.workflows.diagnose import diagnose
    from systems.electrostatic_actuator import electrostatic_actuator

    pair = "viscoelastic_creep+cubic_stiffness"
    train, _ = ce.generate(pair, seconds=20, seed=1)
    val, _ = ce.generate(pair, seconds=20, seed=2, validation=True)
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(ce.NOMINAL_FREE), n_jobs=2)
    assert set(d.verdict["effects"]) == {"viscoelastic_creep", "cubic_stiffness"}, d.summary()
    first, second = d.accepted
    assert first.label == "viscoelastic_creep@m.p"
    hysteresis = next(h for h in d.rounds[0] if h.label == "hysteresis@m.p")
    assert hysteresis.validation_rss < first.validation_rss  # alone the hysteresis fits better
    assert pairs._passes(hysteresis, second)  # the pair beats it by the acceptance rule
