"""A hysteresis whose screened loop closes in the pre-sliding regime waits for the choice of Coulomb friction
at the same place (``screening._friction_loops``, ``_refit_deferred``): not refitted when the friction is
chosen, refitted when it is not."""

import pytest

from examples.concealed_effects import NOMINAL_FREE, generate
from phs.workflows.diagnose import FRICTION_LIKE, diagnose, presliding_share
from phs.workflows.diagnose.screening import _refit_deferred
from systems.electrostatic_actuator import electrostatic_actuator


@pytest.fixture(scope="module")
def friction():
    train, _ = generate("coulomb_friction", seconds=3.0, seed=1)
    val, _ = generate("coulomb_friction", seconds=3.0, seed=2, validation=True)
    return diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=1)


def test_friction_chosen_loop_not_refitted(friction):
    d = friction
    assert d.effect == "coulomb_friction"
    loop = [h for h in d.rounds[0] if h.label == "hysteresis@m.p"][0]
    # screened only, and friction-like on its screening values (measured 0.021 of the stroke)
    assert loop.stage == "screening" and loop.deferred
    assert presliding_share(d.nominal, loop, d.data) < FRICTION_LIKE
    # the same physics as the chosen friction: not its rival, so the verdict is not capped by it
    assert loop.label in d.accepted[0].same_physics
    # the JSON says why it stayed screened
    doc = {h["effect"]: h for h in d.to_dict()["hypotheses"]}
    assert doc["hysteresis"]["criterion"]["stage"] == "screening" and "pre-sliding" in doc["hysteresis"]["deferred"]
    assert "deferred" not in doc["coulomb_friction"]
    # nothing waits when the choice is the friction at its place
    hyps = list(d.rounds[0])
    assert not _refit_deferred(d.nominal, hyps, d.accepted[0], d.data, False, "test")
    assert hyps == d.rounds[0]


def test_loop_refitted_when_friction_not_chosen(friction):
    d = friction
    hyps = list(d.rounds[0])
    before = [h for h in hyps if h.label == "hysteresis@m.p"][0]
    assert _refit_deferred(d.nominal, hyps, None, d.data, False, "test")
    after = [h for h in hyps if h.label == "hysteresis@m.p"][0]
    assert after is not before and after.stage == "full" and not after.deferred and after.ok
    # refitted on the whole recording to convergence: at least the screening's training fit (the
    # refit starts from it; 1e-9 relative for the solver's last step)
    assert after.rss <= before.rss * (1 + 1e-9)
