"""The choice among accepted hypotheses (``ranking._pick``): the simplest among those equally good on the
validation recording and on the training recording."""

from __future__ import annotations

from types import SimpleNamespace

from phs.workflows.diagnose.ranking import SUFFICIENT_MARGIN, _pick

NOMINAL = SimpleNamespace(validation_rss=50.0, bic=-207500.0, rss=52.0)


def _h(label, rss, vrss, bic, n):
    return SimpleNamespace(label=label, rss=rss, validation_rss=vrss, bic=bic, n_params=n, ok=True, stage="full",
                           reference_rss=None, reference_bic=None, augmentation=SimpleNamespace(effect=label, attached_to="U"))


def test_a_simpler_hypothesis_that_leaves_much_more_training_residual_is_not_sufficient():
    # the concealed tanh saturation of the input (3 s), as measured: the added mass comes within 2.8 % of the
    # soft clip's validation residual but leaves 66 % more of the training residual
    clip = _h("input_saturation", 24.76, 34.82, -212003.6, 5)
    mass = _h("added_mass", 41.03, 35.79, -208993.1, 4)
    assert mass.validation_rss <= clip.validation_rss * (1 + SUFFICIENT_MARGIN)  # equally good on validation alone
    assert _pick(NOMINAL, [mass, clip]) is clip


def test_equally_good_on_both_recordings_the_simplest_wins():
    a = _h("two_parameters", 30.0, 34.0, -210000.0, 5)
    b = _h("one_parameter", 30.5, 34.5, -209990.0, 4)  # within 3 % on both
    assert _pick(NOMINAL, [a, b]) is b


def test_the_training_margin_is_taken_among_the_validation_good():
    # the best training residual belongs to a hypothesis far worse on validation: it does not set the margin
    over = _h("overfit", 10.0, 45.0, -215000.0, 7)
    a = _h("two_parameters", 30.0, 34.0, -210000.0, 5)
    b = _h("one_parameter", 30.5, 34.5, -209990.0, 4)
    assert _pick(NOMINAL, [over, a, b]) is b
