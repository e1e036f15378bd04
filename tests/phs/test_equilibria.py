"""Equilibria under constant input, including systems with a conserved quantity.

Three independent answers are compared: :func:`phs.equilibrium`, the
long-time limit of :func:`codegen.simulate` (damped systems settle
exponentially; the horizons below are > 40 slowest time constants, so the
transient is below 1e-17 of the initial offset and the integrator's error,
~1e-9 relative at rtol=1e-10, dominates) and a closed form or a scalar root
of the static equations written here.  Agreement is required to 1e-6
relative; an absolute floor of 1e-9 (in the states' units) covers momenta
that are zero at rest.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize

from codegen import simulate
from components import (
    ForceSource,
    LinearSpring,
    Mass,
    RotationalDamper,
    RotationalInertia,
    TorqueSource,
    TorsionalSpring,
    Transformer,
)
from phs import EquilibriumError, Param, bond, equilibrium, interconnect, series, symbol_of_state

RTOL, ATOL = 1e-6, 1e-9

# curling-joint toy: torque T on an inertia J with a torsional spring K_b and damper b, and a transformer
# n(theta) from the rotation to a linear spring K (rest length L0) with its own length state l.
I_, KB, BD, K, L0, N0 = 0.01, 1.0, 0.5, 2.0, 0.1, 0.5


def _joint(modulation: float):
    """n(theta) = n0 (1 + a theta); a = 0 is a constant ratio."""
    th = symbol_of_state("kb.theta")
    n0 = Param("n0", N0, "m/rad", "lever arm")
    ratio = n0.symbol * (1 + modulation * th) if modulation else n0.symbol
    return interconnect("joint", [TorqueSource("T"), RotationalInertia("J", I=I_), TorsionalSpring("kb", K=KB),
                                  RotationalDamper("b", b=BD), Transformer("tf", ratio, unit="m/rad"),
                                  LinearSpring("k", K=K, L0=L0)],
                        [series("T", "J", "kb", "b", "tf.a"), bond("tf.b", "k")], params=[n0])


def _long_time(system, u, x0, t_end):
    res = simulate(system, np.linspace(0.0, t_end, 201), u=u, x0=x0, rtol=1e-10)
    assert res.energy_balance_error() <= 1e-6
    return res.x[-1]


def test_msd_under_constant_force(msd):
    """k x = F, p = 0."""
    eq = equilibrium(msd, u={"F": 2.0})
    assert eq["k.l"] == pytest.approx(2.0 / 4.0, rel=RTOL)
    assert abs(eq["m.p"]) <= ATOL
    # slowest time constant 1/alpha = 2 m / b = 5 s: 250 s is 50 of them
    np.testing.assert_allclose(eq.x, _long_time(msd, {"F": 2.0}, None, 250.0), rtol=RTOL, atol=ATOL)
    assert eq.conserved == 0


def test_rlc_under_constant_voltage(rlc):
    """Q = C U and no current."""
    eq = equilibrium(rlc, u={"U": 3.0})
    assert eq["C.Q"] == pytest.approx(1e-6 * 3.0, rel=RTOL)
    assert abs(eq["L.phi"]) <= ATOL
    # alpha = R / 2L = 5e3 1/s: 10 ms is 50 time constants
    np.testing.assert_allclose(eq.x, _long_time(rlc, {"U": 3.0}, None, 1e-2), rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize(("T", "x0"), [(0.3, {"kb.theta": 0.2, "k.l": 0.3}), (-0.2, {"kb.theta": -0.1, "k.l": 0.05}),
                                        (0.0, {"kb.theta": 0.4, "k.l": 0.0})])
def test_constant_ratio_conserved_quantity_closed_form(T, x0):
    """l - n theta is conserved; at rest T = K_b theta + n K (l - L0), so
    theta = (T - n K (c - L0)) / (K_b + n^2 K) with c = l0 - n theta0."""
    s = _joint(0.0)
    eq = equilibrium(s, u={"T": T}, x0=x0)
    assert eq.conserved == 1
    c = x0["k.l"] - N0 * x0["kb.theta"]
    theta = (T - N0 * K * (c - L0)) / (KB + N0**2 * K)
    expected = {"J.p": 0.0, "kb.theta": theta, "k.l": c + N0 * theta}
    np.testing.assert_allclose(eq.x, [expected[n] for n in s.state_names], rtol=RTOL, atol=ATOL)
    # the conserved quantity keeps its initial value
    assert eq["k.l"] - N0 * eq["kb.theta"] == pytest.approx(c, rel=RTOL, abs=ATOL)
    # overdamped: slow pole ~ (K_b + n^2 K) / b = 3 1/s; 20 s is 60 time constants
    np.testing.assert_allclose(eq.x, _long_time(s, {"T": T}, x0, 20.0), rtol=RTOL, atol=ATOL)


def test_random_leaves_of_the_constant_ratio_joint(rng):
    """Random inputs and initial states (seeded): each leaf l - n theta = c has the closed-form rest point."""
    s = _joint(0.0)
    for _ in range(5):
        T = float(rng.uniform(-0.5, 0.5))
        x0 = {"kb.theta": float(rng.uniform(-0.5, 0.5)), "k.l": float(rng.uniform(-0.05, 0.25))}
        eq = equilibrium(s, u={"T": T}, x0=x0)
        c = x0["k.l"] - N0 * x0["kb.theta"]
        theta = (T - N0 * K * (c - L0)) / (KB + N0**2 * K)
        assert eq["kb.theta"] == pytest.approx(theta, rel=RTOL, abs=ATOL)
        assert eq["k.l"] == pytest.approx(c + N0 * theta, rel=RTOL, abs=ATOL)


@pytest.mark.parametrize("a", [0.2, -0.3])
def test_state_dependent_ratio_matches_simulation_and_root_finding(a):
    """n(theta) = n0 (1 + a theta): the conserved quantity is l - n0 (theta + a theta^2 / 2); the static
    equation T = K_b theta + n(theta) K (l(theta) - L0) is solved for theta by bracketing."""
    s = _joint(a)
    T, x0 = 0.3, {"kb.theta": 0.2, "k.l": 0.3}
    eq = equilibrium(s, u={"T": T}, x0=x0)

    def N(th):
        return N0 * (th + a * th**2 / 2)

    c = x0["k.l"] - N(x0["kb.theta"])

    def static(th):
        return T - KB * th - N0 * (1 + a * th) * K * (c + N(th) - L0)

    theta = scipy.optimize.brentq(static, -1.0, 1.0, xtol=1e-15, rtol=1e-15)
    expected = {"J.p": 0.0, "kb.theta": theta, "k.l": c + N(theta)}
    np.testing.assert_allclose(eq.x, [expected[n] for n in s.state_names], rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(eq.x, _long_time(s, {"T": T}, x0, 20.0), rtol=RTOL, atol=ATOL)
    assert eq.residual <= 1e-10


def test_equilibrium_result_accessors(msd):
    eq = equilibrium(msd, u=2.0)  # a bare number for a single-input system
    assert eq.as_dict() == {"m.p": pytest.approx(0.0, abs=ATOL), "k.l": pytest.approx(0.5, rel=RTOL)}
    with pytest.raises(KeyError, match="k.x"):
        eq["k.x"]
    np.testing.assert_array_equal(eq.u, [2.0])


def test_parameter_overrides(msd):
    assert equilibrium(msd, u={"F": 2.0}, params={"k.K": 8.0})["k.l"] == pytest.approx(0.25, rel=RTOL)


def test_no_equilibrium_raises_naming_the_residual():
    """A free mass under a constant force accelerates forever."""
    s = interconnect("push", [ForceSource("F"), Mass("m")], [series("F", "m")])
    with pytest.raises(EquilibriumError) as err:
        equilibrium(s, u={"F": 1.0})
    assert "residual" in str(err.value) and "m.p=" in str(err.value) and "'push'" in str(err.value)


def test_hamiltonian_is_stationary_on_the_leaf_at_the_equilibrium():
    """Without input, an equilibrium on the leaf l - n theta = c is a critical point of H restricted to
    the leaf: the derivative of H along the leaf direction (dtheta, dl) = (1, n) vanishes."""
    s = _joint(0.0)
    eq = equilibrium(s, u={"T": 0.0}, x0={"kb.theta": 0.3, "k.l": 0.1})
    grad = np.asarray(s.lambdify(s.grad_H)(eq.x, [0.0]), dtype=float).reshape(-1)
    i_th, i_l = s.state_names.index("kb.theta"), s.state_names.index("k.l")
    along_leaf = grad[i_th] + N0 * grad[i_l]
    assert abs(along_leaf) <= 1e-9 * (abs(grad[i_th]) + N0 * abs(grad[i_l]) + 1e-12)
