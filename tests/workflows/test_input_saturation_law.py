"""The input saturation's law: gradual to hard, searched as the compression of the recorded peak.

``InputSaturation`` maps a command ``u`` to ``u / (1 + |u/U|^p)^(1/p)`` (``U = U_hi`` above zero, ``U_lo``
below), parametrised by the compression of the recorded peaks and the sharpness ``p``.  The structural
laws hold on every lab-shaped command (hypothesis, over ``lab_inputs.waveforms``): the neutral point passes
the command through bit for bit, the output keeps the command's sign and order and never exceeds it in
magnitude nor the limits, :meth:`limits` and :meth:`at_limits` invert each other, and the compression at
the peak is the parameter's.  Then the reason for the law, on numbers that could be wrong: a gradual
saturation (the concealed ``tanh`` of ``examples.concealed_effects``) is explained by this law and not by
the hard clip it replaced.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from lab_inputs import waveforms

from components.candidates import InputSaturation
from phs.workflows.diagnose.element_search import element_search, searched

SAT = InputSaturation()


@st.composite
def commands(draw):
    n = draw(st.integers(20, 400))
    amplitude = draw(st.floats(1e-3, 1e4))
    u, _ = draw(waveforms(n, 1e-3, amplitude))
    if draw(st.booleans()):  # a unipolar drive (the electrostatic actuator's, a pump's)
        u = np.abs(u)
    return np.arange(n) * 1e-3, u


@given(commands(), st.floats(0.0, 0.8), st.floats(0.0, 0.8), st.floats(1.5, 20.0))
def test_the_law_keeps_sign_order_and_bounds(cmd, c_hi, c_lo, p):
    t, u = cmd
    specs = SAT.parameters(t, u)
    assert [s[0] for s in specs] == ["c_hi", "c_lo", "p", "ref_hi", "ref_lo"]
    assert np.array_equal(SAT.transform(t, u, SAT.neutral(t, u)), u)  # the neutral point is no element at all
    theta = [min(c_hi, specs[0][3]), min(c_lo, specs[1][3]), p, specs[3][1], specs[4][1]]
    y = SAT.transform(t, u, theta)
    assert np.all(np.isfinite(y)) and np.all(np.sign(y) == np.sign(u))
    assert np.all(np.abs(y) <= np.abs(u) * (1 + 1e-12))
    U_hi, U_lo = SAT.limits(theta)
    assert np.all(y <= U_hi * (1 + 1e-12)) and np.all(y >= -U_lo * (1 + 1e-12))
    order = np.argsort(u, kind="stable")
    assert np.all(np.diff(y[order]) >= -1e-12 * (np.max(np.abs(u)) or 1.0))  # a saturation never reverses the order
    # the compression at the recorded peak is the parameter's (relative error of the power's round trip)
    if np.max(u) > 0:
        assert abs(1 - SAT.transform(t, np.array([np.max(u)]), theta)[0] / np.max(u) - theta[0]) < 1e-9
    # limits and at_limits invert each other
    back = SAT.at_limits(t, u, U_hi, U_lo, p)
    assert np.allclose(back[:3], theta[:3], rtol=1e-9, atol=1e-12)


def test_a_hard_clip_and_a_gradual_saturation_are_both_in_the_family():
    u = np.linspace(0.0, 20.0, 2001)
    hard = SAT.transform(None, u, SAT.at_limits(None, u, 10.0, p=20.0))
    # within 3.4 % of the limit at the corner and 0.1 % of it at 1.5 times the limit: a clip
    assert abs(hard[1000] - 10.0 * 2 ** -0.05) < 1e-9 and abs(hard[1500] - 10.0) < 0.01
    assert abs(hard[250] - u[250]) < 1e-9  # untouched at a quarter of the limit (1e-13 off)
    gradual = SAT.transform(None, u, SAT.at_limits(None, u, 10.0, p=2.0))
    scale = 10.0 * math.sqrt(2.0 / 3.0)  # the tanh with the same third-order compression, x - x^3 / 200
    tanh = scale * np.tanh(u / scale)
    assert np.max(np.abs(gradual - tanh)[:500]) < 0.02 * 10.0  # alike up to half the limit


def test_a_parameter_whose_range_is_a_point_is_held_and_not_counted():
    t = np.arange(200) * 1e-3
    u = np.abs(np.sin(2 * np.pi * 5 * t)) * 7.0  # never below zero: no lower side to search
    specs = SAT.parameters(t, u)
    assert searched(specs) == 2 and specs[1][2] == specs[1][3] == 0.0
    seen = []

    def cost(theta):
        seen.append(list(theta))
        return (theta[0] - 0.2) ** 2 + (theta[2] - 4.0) ** 2

    theta = element_search(cost, specs, SAT.neutral(t, u))
    assert abs(theta[0] - 0.2) < 0.01 and abs(theta[2] - 4.0) < 0.1
    assert all(th[1] == 0.0 and th[3] == 7.0 for th in seen)  # the held ones never move


@pytest.mark.parametrize("size", [1.0])
def test_a_gradual_saturation_is_explained_by_the_law_not_by_a_hard_clip(size):
    # the concealed truth saturates as U+ tanh(U/U+): gradually, 9 % at the recorded peak (seed 1, 3 s).
    # With the sharpness searched the saturation explains 88 % of what the nominal model misses; held at a
    # hard clip (p = 20) 38 % (the softplus clip this law replaced: 36 %).  The margins (0.75, 0.5) leave room for either fit to
    # end elsewhere on another machine's rounding, and fail if the two laws explained alike.
    from examples.concealed_effects import NOMINAL_FREE, generate
    from phs.workflows.diagnose import diagnose
    from systems.electrostatic_actuator import electrostatic_actuator

    class HardClip(InputSaturation):
        def parameters(self, t, u):
            return [s if s[0] != "p" else ("p", 20.0, 20.0, 20.0) for s in super().parameters(t, u)]

    train, _ = generate("input_saturation", seconds=3.0, seed=1, size=size)
    val, _ = generate("input_saturation", seconds=3.0, seed=2, validation=True, size=size)
    shares = {}
    for name, el in (("law", InputSaturation()), ("hard", HardClip())):
        d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=1, candidates=[el],
                     discover=False)
        assert d.effect == "input_saturation", (name, d.summary())
        shares[name] = d.verdict["explained_share"]
        if name == "law":
            assert d.accepted[0].element_values["input_saturation.p"] < 5.0, d.accepted[0].element_values  # found gradual
            # the report gives the limit it tends to beside the compression (the truth tanh: 39.5 V, 1.6 times the peak)
            limit = InputSaturation().derived(list(d.accepted[0].element_values.values()))["U_hi"]
            assert f"U_hi = {limit:.3g}" in d.verdict["explanation"] and 1.2 < limit / np.max(train["U"]) < 4, d.verdict
    assert shares["law"] > 0.75 and shares["hard"] < 0.5, shares
