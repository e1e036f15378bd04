"""An input element's output between samples: a delay by a fraction of a sample moves the command's kinks
between the recording's samples, and a simulation must follow the delayed course, not the straight lines
through its values at the samples (``InputElement.course``, ``Recording.between``)."""

from __future__ import annotations

import numpy as np
import pytest

from components.candidates import InputSaturation, TimeDelay
from examples.concealed_effects import generate
from examples.concealed_truths import truth
from phs.workflows.diagnose.hypotheses import _simulate, _transformed
from phs.workflows.recording import Recording


def test_a_fractional_delay_follows_the_truth_between_samples():
    # the concealed 0.7 ms delay of the applied voltage (0.7 of a sample) on a command that steps: the truth's
    # own system driven through the element's course reproduces the noise-free recording; through the
    # straight lines between the delayed samples its current is off by most of the current's spread
    size = 0.35
    rec, info = generate("time_delay", seconds=3, seed=3, size=size)
    tr = truth("time_delay", size=size)
    tau = info["parameters"]["delay"]
    assert 0 < tau / rec.dt % 1  # a fraction of a sample
    r = _transformed(rec, TimeDelay(), "U", [tau])
    x0 = np.zeros(len(tr.system.states))
    exact = _simulate(tr.system, r, x0)
    on_grid = _simulate(tr.system, Recording(r.t, r.signals, r.source, r.units), x0)
    for ch in ("position", "current"):
        s = float(np.std(info["clean"][ch]))
        # the truth was simulated at rtol 1e-9, the hypothesis at 1e-8: 1e-4 of the spread holds both
        assert np.max(np.abs(np.asarray(exact[ch]) - info["clean"][ch])) < 1e-4 * s
    err = np.max(np.abs(np.asarray(on_grid["current"]) - info["clean"]["current"])) / np.std(info["clean"]["current"])
    assert err > 0.3  # measured 0.84: the check can fail


def test_a_whole_sample_delay_needs_no_course_and_zero_none():
    t, u = np.arange(5.0), np.array([0.0, 0.0, 1.0, 1.0, 1.0])
    assert TimeDelay().course(t, u, [0.0]) is None
    times, values = TimeDelay().course(t, u, [1.0])
    assert np.allclose(np.interp(t, times, values), TimeDelay().transform(t, u, [1.0]))  # the samples agree


def test_a_window_keeps_the_course_over_it():
    rec, _ = generate("time_delay", seconds=1, seed=3, size=0.35)
    r = _transformed(rec, TimeDelay(), "U", [0.4 * rec.dt])
    w = r.window(0.2, 0.6)
    tt = np.linspace(0.2, 0.6, 977)
    assert np.array_equal(w.input_signal("U")(tt), r.input_signal("U")(tt))
    assert w.between["U"][0][0] <= 0.2 and w.between["U"][0][-1] >= 0.6


def test_an_element_setting_an_input_again_transforms_its_course():
    # a second element at the same input (a later diagnosis round) transforms the course the first left: a
    # saturation after a delay by a fraction of a sample saturates the delayed course (along the line through
    # its new samples the delay's kinks between the samples were lost: on the concealed input saturation +
    # time delay pair, the saturation's every trial then cost three times the model without it)
    rec, _ = generate("time_delay", seconds=1, seed=3, size=0.35)
    r = _transformed(rec, TimeDelay(), "U", [0.4 * rec.dt])
    times, values = r.between["U"]
    sat = InputSaturation()
    theta = sat.at_limits(r.t, r["U"], 5.0, 5.0)
    s = _transformed(r, sat, "U", theta)
    assert np.array_equal(s.between["U"][0], times)
    assert np.array_equal(s.input_signal("U")(times), sat.transform(times, values, theta))
    assert np.max(s["U"]) < np.max(r["U"]) and np.max(s.between["U"][1]) < np.max(values)


@pytest.mark.parametrize("a, b", [(0.4, 0.3), (0.25, 1.5), (2.0, 0.0)])
def test_two_delays_at_one_input_make_their_sum(a, b):
    # the course of a delay after a delay is the course of the summed delay (independent computations:
    # composed through the recording, and at once), between the samples too
    rec, _ = generate("time_delay", seconds=0.5, seed=3, size=0.35)
    dt = rec.dt
    twice = _transformed(_transformed(rec, TimeDelay(), "U", [a * dt]), TimeDelay(), "U", [b * dt])
    once = _transformed(rec, TimeDelay(), "U", [(a + b) * dt])
    tt = np.linspace(rec.t[0], rec.t[-1], 7 * len(rec.t) + 3)
    assert np.allclose(twice.input_signal("U")(tt), once.input_signal("U")(tt), rtol=0, atol=1e-12 * np.ptp(rec["U"]))


def test_the_other_inputs_keep_their_holds_through_an_element():
    # a disturbance held by a DAC (zoh) beside a command an element transforms: a simulation of the transformed
    # recording must still hold the disturbance between samples (it was read as straight lines: a 0 -> 1 step at
    # t = 0.5 read 0.5 at t = 0.45); the transformed input keeps its declared "zoh" too, a declared law not
    t = np.arange(11) * 0.1
    rec = Recording.from_arrays(t, {"U": np.linspace(0.0, 2.0, 11), "D": np.where(t < 0.45, 0.0, 1.0),
                                    "W": np.where(t < 0.45, 0.0, 1.0)}, holds={"D": "zoh", "W": "step(1.0, 0.5)"})
    r = _transformed(rec, InputSaturation(), "U", InputSaturation().at_limits(rec.t, rec["U"], 1.5, 1.5))
    assert r.holds == {"D": "zoh", "W": rec.holds["W"]}
    assert float(r.input_signal("D")(0.45)) == 0.0 and float(rec.input_signal("D")(0.45)) == 0.0
    assert float(r.input_signal("W")(0.45)) == 0.0 and float(r.input_signal("W")(0.55)) == 1.0
    held = Recording.from_arrays(t, {"U": np.where(t < 0.45, 0.0, 2.0)}, holds={"U": "zoh"})
    assert _transformed(held, InputSaturation(), "U", InputSaturation().at_limits(t, held["U"], 1.5)).holds == {"U": "zoh"}
    law = Recording.from_arrays(t, {"U": np.where(t < 0.45, 0.0, 2.0)}, holds={"U": "step(2.0, 0.5)"})
    assert _transformed(law, InputSaturation(), "U", InputSaturation().at_limits(t, law["U"], 1.5)).holds == {}
