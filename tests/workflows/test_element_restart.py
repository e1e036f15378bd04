"""An input element's joint fit starts again from the model's own values when the nominal fit pressed a free
parameter against a bound of its range (``hypotheses._pressed``): a loop's delay absorbed by the damping
at its lower end leaves the alternating fit in that corner, where neither the element's search with the
model held nor the model's refit alone lowers the cost.  The first search on the cost left after the
model's first-order re-adjustment (``element_search.nominal_profile``) leaves that corner too."""

from __future__ import annotations

import numpy as np
import pytest

import phs.workflows.diagnose.hypotheses as hyp
from components.candidates import LIBRARY, Scales
from examples.concealed_loops import LOOP_DELAY, NOMINAL_FREE, generate, nominal
from phs.workflows.diagnose.hypotheses import Data, _pressed, fit_augmented, train_result
from phs.workflows.diagnose.nominal import fit_nominal
from phs.workflows.recording import Recording

DECLARED_DAMPING = 2.5
"""The damping the nominal model is built with: a rough guess, not the truth (1.0 N·s/m)."""


def _data(free=("b", "k"), bounds=None, given=None):
    rec = Recording.from_arrays(np.linspace(0, 1, 11), {"y": np.zeros(11)})
    return Data(rec, rec, np.ones(11, bool), None, ["y"], list(free), bounds or {}, [], None, given=given)


@pytest.mark.parametrize("values, expected", [
    ({"b": 0.1, "k": 40.0}, ["b"]),            # on the lower end of a linear range
    ({"b": 10.0, "k": 40.0}, ["b"]),           # on the upper end
    ({"b": 0.1 + 1e-7, "k": 40.0}, ["b"]),     # within 1e-6 of the range's width (9.9e-6) of it
    ({"b": 0.1 + 1e-4, "k": 40.0}, []),        # beyond
    ({"b": 1.0, "k": 1000.0}, ["k"]),          # the end of a range spanning decades (log width)
    ({"b": 2.0, "k": 400.0}, []),              # inside both
])
def test_pressed_names_the_parameters_on_a_bound(values, expected):
    d = _data(bounds={"b": (0.1, 10.0), "k": (1.0, 1000.0)}, given={"b": 1.0, "k": 40.0})
    assert _pressed(values, d, None) == expected


def test_pressed_needs_a_given_value_inside_the_range():
    bounds = {"b": (0.1, 10.0)}
    assert _pressed({"b": 0.1}, _data(free=["b"], bounds=bounds, given={"b": 0.1}), None) == []  # built on the bound itself
    assert _pressed({"b": 0.1}, _data(free=["b"], bounds=bounds, given=None), None) == []         # no values to start from
    # without bounds of the fit, the parameter's declared range
    m = nominal()
    lo = m.param("b.b").range[0]
    assert _pressed({"b.b": lo}, _data(free=["b.b"], given={"b.b": 1.0}), m) == ["b.b"]


def _pressed_case(seconds):
    train, _ = generate("loop_delay", seconds=seconds, seed=1)
    val, _ = generate("loop_delay", seconds=seconds, seed=2, validation=True)
    model = nominal().with_params({"b.b": DECLARED_DAMPING})
    data = Data(train, val, np.ones(len(val), bool), None, ["u_c", "position"], list(NOMINAL_FREE), {}, [], None)
    nom, data = fit_nominal(model, data)
    res = train_result(nom, data)
    U = np.column_stack([np.asarray(res[n]) for n in nom.system.input_names])
    scales = Scales.of(nom.system.with_params(nom.values), res.t, np.asarray(res.x), U, {ch: train[ch] for ch in data.outputs})
    aug = next(c for c in LIBRARY if c.effect == "time_delay").augment(nom.system.with_params(nom.values), "u_c", scales)
    return nom, data, aug


def _compare(nom, data, aug, monkeypatch, restart_alone=True):
    """The joint fit as it runs (its first search on the cost left after the model's first-order
    re-adjustment, :func:`~phs.workflows.diagnose.element_search.nominal_profile`), with the restart alone
    (no profile; ``None`` unless ``restart_alone``), and with neither."""
    profiled = fit_augmented(nom, aug, data, joint=True)
    monkeypatch.setattr(hyp, "nominal_profile", lambda *a: None)
    with_restart = fit_augmented(nom, aug, data, joint=True) if restart_alone else None
    monkeypatch.setattr(hyp, "_pressed", lambda *a: [])
    neither = fit_augmented(nom, aug, data, joint=True)
    return profiled, with_restart, neither


def test_a_fit_pressed_into_a_corner_reaches_the_delay(monkeypatch):
    # 4 s loop delay with three alternating rounds (eight by default): from the corner the nominal fit left
    # (damping on its lower bound) the rounds creep towards the delay and stop short; from the damping the
    # model was built with (2.5, not the truth 1.0) the fit reaches it, and so does a first search that lets
    # the model re-adjust (to first order) to each trial delay
    monkeypatch.setattr(hyp, "ELEMENT_ROUNDS", 3)
    nom, data, aug = _pressed_case(4.0)
    assert _pressed(nom.values, data, nom.system) == ["b.b"]  # the precondition: the damping absorbed the delay
    hp, _, h0 = _compare(nom, data, aug, monkeypatch, restart_alone=False)  # the restart alone: the 20 s test below
    tau0 = h0.element_values["time_delay.tau_d"]
    # measured: 3.96 ms and damping 0.96 as it runs (the profile and the restart); 4.37 ms and 1.21 with the
    # restart alone; 3.32 ms and 0.70 with neither (training residual 4 % higher)
    assert abs(hp.element_values["time_delay.tau_d"] / LOOP_DELAY - 1) < 0.15 and abs(hp.values["b.b"] - 1.0) < 0.3
    assert hp.rss < h0.rss
    assert abs(tau0 / LOOP_DELAY - 1) > 0.15  # the check can fail: with neither the fit stops short


@pytest.mark.slow
def test_a_long_recording_finds_the_loop_delay_the_damping_absorbed(monkeypatch):
    # 20 s, eight rounds: with neither the profile nor the restart the delay is found at 2.1 ms (the
    # alternating fit stops after one round at the corner); with either, at the delay
    nom, data, aug = _pressed_case(20.0)
    hp, h, h0 = _compare(nom, data, aug, monkeypatch)
    for fit in (hp, h):
        assert abs(fit.element_values["time_delay.tau_d"] / LOOP_DELAY - 1) < 0.1 and abs(fit.values["b.b"] - 1.0) < 0.2
        assert fit.rss < 0.8 * h0.rss
    assert h0.element_values["time_delay.tau_d"] < 0.7 * LOOP_DELAY
