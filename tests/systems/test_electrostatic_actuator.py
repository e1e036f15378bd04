"""The tutorial's electrostatic actuator: statics against the analytic force balance, pull-in, domain."""

import numpy as np
import pytest

from codegen import simulate
from phs import DomainError, EquilibriumError, equilibrium
from phs.signals import step
from systems.electrostatic_actuator import electrostatic_actuator


@pytest.fixture(scope="module")
def act():
    return electrostatic_actuator()


def _pull_in(act):
    pv = act.param_values()
    return np.sqrt(8 * pv["k"] * pv["g0"] ** 3 / (27 * pv["eps"] * pv["A"])), pv


def test_static_curve_matches_force_balance_up_to_pull_in(act):
    V_pi, pv = _pull_in(act)
    k, g0, eps, A = pv["k"], pv["g0"], pv["eps"], pv["A"]
    for frac in (0.2, 0.6, 0.9, 0.98):
        V = frac * V_pi
        roots = np.roots([2 * k, -4 * k * g0, 2 * k * g0**2, -eps * A * V**2])
        stable = min(r.real for r in roots if abs(r.imag) < 1e-12 * g0 and r.real >= 0)
        eq = equilibrium(act, u={"U": V})
        assert eq["x"] == pytest.approx(stable, rel=1e-6)  # the stable branch, not the unstable root
        assert eq.info["stable"]


def test_no_equilibrium_beyond_pull_in(act):
    V_pi, _ = _pull_in(act)
    with pytest.raises(EquilibriumError, match="pull-in"):
        equilibrium(act, u={"U": 1.05 * V_pi})


def test_snap_through_stops_with_a_domain_error(act):
    V_pi, _ = _pull_in(act)
    with pytest.raises(DomainError, match="gap open"):
        simulate(act, np.linspace(0, 0.05, 501), u={"U": step(1.2 * V_pi, at=0.005)})


def test_energy_balance_below_pull_in(act):
    V_pi, _ = _pull_in(act)
    res = simulate(act, np.linspace(0, 0.1, 2001), u={"U": step(0.9 * V_pi, at=0.005)}, rtol=1e-9)
    assert res.energy_balance_error() <= 1e-6
