"""The catheter bender: static force at hand-computed points, volume tracking, the paper's regression reproduced."""

import numpy as np
import pytest

from codegen import simulator
from phs import equilibrium
from phs.errors import ModelError
from phs.workflows.regression import regress
from systems import catheter_bender, volume_chirp
from systems.catheter_bender import ML


def test_static_force_at_five_millilitres():
    """x = 5 mL: P(5 mL) = 1e9*5e-6 + 7e14*25e-12 + 2e19*125e-18 = 25000 Pa; the wall takes A y = 5e-9 m^3,
    so P(4.995e-6) = 25000 - 9.5e9 * 5e-9 = 24952.5 Pa (dP/dV = 9.5e9), y = A P / (K_b + k_c) = 2.49525e-4 m,
    F = 0.0122 + 500 y = 0.136963 N."""
    s = catheter_bender()
    eq = equilibrium(s, u={"q": 0.0}, x0={"chamber.V": 5 * ML}).as_dict()
    assert eq["chamber.V"] + 2e-5 * eq["tip_spring.l"] == pytest.approx(5 * ML, rel=1e-9)  # volume conserved
    assert eq["tip_spring.l"] == pytest.approx(2.49525e-4, rel=1e-4)
    assert 500 * eq["tip_spring.l"] + 0.0122 == pytest.approx(0.136963, rel=1e-5)


def test_constrained_static_force_at_ten_millilitres():
    """x = 10 mL: P(1e-5) = 5e8*1e-5 + 1e14*1e-10 + 1e20*1e-15 = 115000 Pa; the wall takes A y = A^2 P / K =
    2.4e-13 P, which lowers P by dP/dV A y = 3.25e10 * 2.4e-13 P (dP/dV = 5e8 + 2e9 + 3e10), so
    P = 115000 / 1.0078 = 114110 Pa (+2 Pa of curvature: P'' (A y)^2 / 2 = 6.0e15 * (2.74e-8)^2 / 2) = 114112 Pa;
    F = 0.00242 + 500 * 2e-5 P / 1666.67 = 0.00242 + 6e-6 P = 0.687092 N."""
    s = catheter_bender("constrained")
    eq = equilibrium(s, u={"q": 0.0}, x0={"chamber.V": 10 * ML}).as_dict()
    assert 500 * eq["tip_spring.l"] + 0.00242 == pytest.approx(0.687092, rel=2e-5)


def test_unknown_loading_and_parameter():
    with pytest.raises(ModelError, match="sideways"):
        catheter_bender("sideways")
    with pytest.raises(ModelError, match="nope"):
        catheter_bender(nope=1.0)


@pytest.fixture(scope="module")
def chirp_run():
    s = catheter_bender()
    x, q = volume_chirp(5 * ML, 4 * ML, 0.01, 5.0, 120.0)
    t = np.linspace(0.0, 120.0, 120 * 83 + 1)  # the paper's 83 Hz sampling
    res = simulator(s).run(t, u={"q": q}, x0=equilibrium(s, u={"q": 0.0}, x0={"chamber.V": 5 * ML}).as_dict())
    return t, x, res


def test_volume_follows_the_chirp_and_energy_balances(chirp_run):
    t, x, res = chirp_run
    assert np.max(np.abs(res["volume"] - x(t))) < 1e-3 * ML
    assert res.energy_balance_error() < 1e-4


def test_regression_recovers_the_static_polynomial(chirp_run):
    """Quasi-statically F - F_pre = tau P(x) with tau = 500 * 2e-5 / 2000 = 5e-6 m^2: per mL,
    tau k1 1e-6 = 5e-3 N, tau k2 1e-12 = 3.5e-3 N, tau k3 1e-18 = 1e-4 N; the selection keeps the static terms."""
    t, _, res = chirp_run
    r = regress({"t": t, "x": res["volume"] / ML, "F": res["force"]})
    assert set(r.terms) == {"x**3", "x**2", "x", "1"}
    c = dict(zip(r.terms, r.coefficients, strict=True))
    assert c["x**2"] == pytest.approx(3.5e-3, rel=0.05)
    assert c["x"] == pytest.approx(5e-3, rel=0.05)
    assert c["1"] == pytest.approx(0.0122, rel=0.05)
    assert r.steps[0]["terms"] == ("x**2", "1")  # the best single term, as in eq. 11
    assert max(r.dropped, key=r.dropped.get) == "x**2"
