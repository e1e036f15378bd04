"""The hydrogel arm: eq. 7 (typos fixed) from the actuator element, the reported 1.56 s period, and a
bounded, energy-consistent response to a square heating pulse."""

import numpy as np
import pytest

from codegen import generate, simulate
from components.hydrogel import force_coefficients, step_force
from phs import ModelError
from phs.signals import Piecewise
from systems import hydrogel_arm
from systems.hydrogel_arm import PERIOD


def test_step_force_is_the_step_response_of_the_second_order_law():
    b0, b1, b2 = force_coefficients(1.08)
    t = np.linspace(0, 40, 4001)
    f = step_force(t, 1.08)
    assert f[0] == 0.0 and f[-1] == pytest.approx(0.04795, abs=1e-5)
    fdd = np.gradient(np.gradient(f, t), t)
    np.testing.assert_allclose((fdd + b1 * np.gradient(f, t) + b2 * f)[5:-5], b0, atol=2e-6)


def test_actuator_on_a_stiff_backbone_reproduces_eq_7():
    """On a backbone a million times stiffer the plates hardly move: the tension k e is eq. 7."""
    arm = hydrogel_arm(per_segment=1, svas=[1], V_a=1.08, E=4e9, tau=0.0)
    t = np.linspace(0, 40, 201)
    res = simulate(arm, t, u={"V1": 1.08}, rtol=1e-10)
    tension = arm.param("sva1.k").value * res["sva1.e"]
    np.testing.assert_allclose(tension, step_force(t, 1.08), atol=1e-6 * 0.05)


def test_arm_period_matches_the_paper():
    arm = hydrogel_arm(per_segment=1, svas=[1])
    f = generate(arm)
    A = np.array(f.jac_rhs(np.zeros(len(arm.states)), np.zeros(1), arm.param_vector())[0])
    ev = np.linalg.eigvals(A)
    w = np.min(np.abs(ev.imag[np.abs(ev.imag) > 1e-6]))
    assert 2 * np.pi / w == pytest.approx(PERIOD, rel=0.02)


def test_heating_pulse_bends_towards_the_heated_row_and_returns():
    arm = hydrogel_arm(per_segment=1, svas=[1, 2, 3, 9])
    t = np.linspace(0, 60, 301)
    res = simulate(arm, t, u={f"V{i}": Piecewise([0, 15], [3.6, 0.0]) for i in (1, 2, 3)}, rtol=1e-7)
    tip = res["tip"]
    assert tip.max() > 1.0 and tip.min() > -0.05  # mm, upper row bends the tip up
    assert abs(tip[-1]) < 0.6 * tip.max()
    assert res.energy_balance_error() < 1e-5


def test_unknown_sva_is_refused():
    with pytest.raises(ModelError, match="1..16"):
        hydrogel_arm(svas=[17])
