"""What a screening on a window measures its hypotheses against (``screening._screen_and_refit``).

A screening fit moves the nominal free parameters with the candidate's on the leading window of the training
recording.  When the window holds only part of the program, every screening fit moves them the same way and
fits the validation worse than the nominal model at its values from the whole recording, the neutral
hypotheses too.  The screened hypotheses are therefore measured against the model they extend refitted
alone on the same window with the same budget (``screening.refit_alone``); a screening of the whole
recording keeps the model itself as its reference.

Checked here with the fits replaced by given scores (the slow test runs the lab case that showed it).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from types import SimpleNamespace as NS

import pytest

import phs.workflows.diagnose.hypotheses as hypotheses
import phs.workflows.diagnose.screening as screening


@dataclass
class _Hyp:
    effect: str
    validation_rss: float
    bic: float = -100.0
    ok: bool = True
    stage: str = "screening"
    reference_rss: float | None = None
    reference_bic: float | None = None
    seconds: float = 1.0
    deferred: object = None
    label: str = ""
    augmentation: object = None
    notes: list = field(default_factory=list)

    def __post_init__(self):
        self.label = f"{self.effect}@x"
        self.augmentation = NS(effect=self.effect, attached_to="x", element=None)


@dataclass
class _Data:
    """The training data's stand-in: its leading window (``head``) is ``short``, or itself when screened whole."""

    recording: list
    short: object = None
    window: int | None = None

    def head(self, m):
        return self if self.short is None else self.short


NOMINAL = NS(label="nominal", system=None, values={}, x0=[], n_params=5, augmentation=None, element_values={},
             validation_rss=100.0, bic=0.0)


def _screen(monkeypatch, screened, alone, window=True):
    """``_screen_and_refit`` on stand-ins: the screening returns ``screened`` (measured against the model on
    the window, as ``_run_all`` does), ``refit_alone`` returns ``alone``; what is refitted is returned."""
    refitted = []
    data = _Data([0.0] * 30, _Data([0.0] * 10) if window else None)

    def run_all(base, augs, d, n_jobs, progress, label, joint=True, ordered=False, ftols=None):
        if "screening" in label:
            for h in screened:
                h.reference_rss, h.reference_bic = base.validation_rss, base.bic
            return screened
        refitted.extend(a.effect for a in augs)
        return [_Hyp(a.effect, 50.0, stage="full") for a in augs]

    monkeypatch.setattr(screening, "_run_all", run_all)
    monkeypatch.setattr(screening, "refit_alone", lambda base, d, joint=True: alone)
    monkeypatch.setattr(screening, "screening_samples", lambda current, d, noise=None: 10)
    monkeypatch.setattr(screening, "_for_refit", lambda h: h.augmentation)
    monkeypatch.setattr(hypotheses, "score", lambda *a, **k: NOMINAL)  # the model scored on the window
    screening._screen_and_refit(NOMINAL, [h.augmentation for h in screened], data, 1, False, "round 1", 3)
    return refitted


def test_on_a_window_the_gains_are_against_the_model_refitted_alone_there(monkeypatch):
    # every screening fit is worse on the validation than the nominal model (the window moved the shared
    # parameters); the model refitted alone on the window is worse still: against it two hypotheses gain
    truth, other, neutral = _Hyp("coulomb_friction", 130.0), _Hyp("input_saturation", 133.0), _Hyp("added_mass", 136.0)
    alone = NS(validation_rss=136.0, bic=-50.0)
    refitted = _screen(monkeypatch, [neutral, other, truth, _Hyp("offset", 137.0)], alone)
    assert refitted[:2] == ["coulomb_friction", "input_saturation"] and "added_mass" not in refitted
    assert truth.reference_rss == 136.0 and truth.reference_bic == -50.0


def test_against_the_nominal_model_none_of_them_would_have_had_a_gain(monkeypatch):
    # the same scores without the window's refit (it failed): only the best screened is refitted, and no
    # hypothesis has a gain over the nominal model's validation residual
    truth, other, neutral = _Hyp("coulomb_friction", 130.0), _Hyp("input_saturation", 133.0), _Hyp("added_mass", 136.0)
    refitted = _screen(monkeypatch, [neutral, other, truth, _Hyp("offset", 137.0)], None)
    assert refitted == ["coulomb_friction"] and truth.reference_rss == NOMINAL.validation_rss


def test_a_screening_of_the_whole_recording_keeps_the_model_as_its_reference(monkeypatch):
    truth = _Hyp("coulomb_friction", 90.0)
    calls = []
    monkeypatch.setattr(screening, "refit_alone", lambda *a, **k: calls.append(1))
    others = [_Hyp("added_mass", 99.0), _Hyp("offset", 101.0), _Hyp("leakage", 102.0)]
    refitted = _screen(monkeypatch, [truth, *others], NS(validation_rss=80.0, bic=-500.0), window=False)
    assert truth.reference_rss == NOMINAL.validation_rss and refitted[0] == "coulomb_friction" and calls == []


@pytest.mark.slow  # two 17 s lab recordings integrated by scipy (about 2 min) and a diagnosis (about 1 min)
def test_the_lab_friction_behind_a_saturation_is_named():
    lp = importlib.import_module("examples.lab_protocols")
    from phs.workflows.diagnose import diagnose

    case = "esa:coulomb_friction+input_saturation@1kHz"
    train, info = lp.generate(case, seed=1)
    val, _ = lp.generate(case, seed=2, validation=True)
    act = lp.ACTUATORS["esa"]
    d = diagnose(act.nominal(), train, validation=val, free=info["free"], x0=info["x0"], outputs=list(act.channels), n_jobs=2)
    assert "coulomb_friction" in d.verdict["effects"], d.summary()
    assert d.final.validation_fit_percent["position"] > d.nominal.validation_fit_percent["position"] + 10
