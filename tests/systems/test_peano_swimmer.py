"""The Peano-HASEL swimmer: eq. 3 at hand-computed points, the pair's torques through grad H, the speed sweep."""

import numpy as np
import pytest

from codegen import generate, simulator
from components.peano import peano_force
from phs.errors import ModelError
from systems import peano_swimmer, swimmer_drive
from systems.peano_swimmer import default_parameters

# eq. 3, F(e) = e + 21.71 (1/(e + 0.22) - 0.39), by hand (strain in percent, force in N)
TABLE = [(0.0, 90.21500), (2.0, 3.31237), (2.5, 2.01471), (4.0, 0.67765)]
E_STAR, F_STAR = 4.439399, 0.631898  # minimum: e* = sqrt(21.71) - 0.22, F(e*) = 2 sqrt(21.71) - 0.22 - 21.71 * 0.39


@pytest.mark.parametrize(("e", "F"), TABLE)
def test_eq3_at_hand_computed_points(e, F):
    assert peano_force(e) == pytest.approx(F, rel=2e-5)


def test_eq3_minimum():
    assert peano_force(E_STAR) == pytest.approx(F_STAR, rel=2e-5)


@pytest.fixture(scope="module")
def model():
    s = peano_swimmer()
    return s, generate(s)


def _grad(model, **x):
    s, f = model
    vec = np.array([x.get(n, 0.0) for n in s.state_names])
    return dict(zip(s.state_names, np.asarray(f.grad_hamiltonian(vec, np.zeros(2), s.param_vector()), dtype=float).ravel(),
                    strict=True))


def test_actuator_torque_is_eq3_times_arm_at_the_reference_voltage(model):
    """At rest (e = s_n = 2.5 %) and the charge Q_ref = C(s_n) V_ref, dH/dphi = -r F(2.5) = -0.004 * 2.01471."""
    Q_ref = default_parameters()["Q_ref"].value
    g = _grad(model, **{"left.Q": Q_ref})
    assert g["phi"] == pytest.approx(-0.004 * 2.01471, rel=1e-4)
    assert _grad(model, **{"right.Q": Q_ref})["phi"] == pytest.approx(0.004 * 2.01471, rel=1e-4)


def test_actuator_voltage_at_reference_charge(model):
    assert _grad(model, **{"left.Q": default_parameters()["Q_ref"].value})["left.Q"] == pytest.approx(6000.0, rel=1e-12)


def test_force_is_held_beyond_the_fits_minimum(model):
    """At e_L = 4.9 % (phi = 0.3; e_R = 0.1 %), beyond e* = 4.44 %, the left actuator pulls with F(e*) = 0.63188 N.

    Charge chosen for V = V_ref from C at that strain: C(e) = C0 + 2 L0/(100 V_ref^2) (I(e*) + F(e*)(e - e*)),
    I(e*) = e*^2/2 + 21.71 ln(1 + e*/0.22) - 21.71 * 0.39 e* = 9.85413 + 66.28094 - 37.58795.
    """
    e = 2.5 + 100 * 0.004 * 0.3 / 0.05
    integral = 9.85413 + 66.28094 - 37.58795 + F_STAR * (e - E_STAR)
    C = 1.5e-9 + 2 * 0.05 / (100 * 6000.0**2) * integral
    g_on = _grad(model, phi=0.3, **{"left.Q": C * 6000.0})
    g_off = _grad(model, phi=0.3)
    assert g_on["left.Q"] == pytest.approx(6000.0, rel=1e-5)
    assert g_on["phi"] - g_off["phi"] == pytest.approx(-0.004 * F_STAR, rel=1e-4)


def test_stretched_actuator_resists_through_its_film(model):
    """phi = 0.325: right strain -0.1 %, stretch d = 5e-5 m, F_film = 1e5 (d + sqrt(d^2 + (2e-5)^2))/2 = 5.19258 N.

    The left film (e_L = 5.1 %, d = -2.55e-3 m) still pushes with 1e5 (2e-5)^2 / (4 * 2.55e-3) = 3.92e-3 N.
    dH/dphi = K_s phi + r F_film(right) - r F_film(left) = 0.01625 + 0.0207703 - 1.569e-5.
    """
    assert _grad(model, phi=0.325)["phi"] == pytest.approx(0.01625 + 0.004 * 5.19258 - 0.004 * 3.922e-3, rel=1e-4)


def test_thrust_is_a_lossless_coupling(model):
    s, f = model
    x = np.array([{"tail.p": 1e-4, "body.p": 1e-3}.get(n, 0.0) for n in s.state_names])
    dHdt, dissipated, supplied = (float(v) for v in f.power_balance(x, np.zeros(2), s.param_vector()))
    assert supplied == 0.0 and dissipated > 0 and dHdt == pytest.approx(-dissipated, rel=1e-12)
    xdot = np.asarray(f.rhs(x, np.zeros(2), s.param_vector()), dtype=float).ravel()
    assert xdot[s.state_names.index("body.p")] > 0  # the fin's rotation pushes the head forward


def test_unknown_parameter_is_named():
    with pytest.raises(ModelError, match="nope"):
        peano_swimmer(nope=1.0)


def test_speed_rises_to_the_fin_resonance_and_falls_beyond():
    s = peano_swimmer()
    sim = simulator(s)
    speeds = {}
    for f in (1.0, 5.0, 12.0):
        T = max(8.0, 16 / f)
        t = np.linspace(0.0, T, int(T * 200) + 1)
        res = sim.run(t, u=swimmer_drive(6000.0, f))
        assert res.energy_balance_error() < 1e-5
        speeds[f] = float(np.mean(res["U"][len(t) // 2:]))
    assert 0 < speeds[1.0] < speeds[5.0] and speeds[12.0] < speeds[5.0]
