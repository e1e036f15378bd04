"""The planar Cosserat rod: structure (J skew, R PSD), statics against a boundary-value solution of the
same continuum rod (``scipy.integrate.solve_bvp``), linear frequencies against the Euler–Bernoulli
closed form, the semi-discrete energy balance and the observed order of convergence.  The dynamics against
``pyelastica`` are in ``test_rod_pyelastica.py``, the run time at equal accuracy in ``bench/rod.py``.

The reference solutions here are written independently of the model: the continuum equations of the
planar Simo–Reissner rod, ``r' = R(theta)(e1 + nu)``, ``theta' = m/EI``, ``n' = -f``, ``m' = -(r' x n)``
with ``nu = (N/EA, V/(k_s G A))`` the material components of ``n``.
"""

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_bvp

from codegen import generate, simulate
from components import ForceSource, TorqueSource
from components.rod import CosseratRod, element_strains
from phs import ModelError, interconnect, series
from phs.signals import step

L, E, I, A, RHO = 1.0, 1e6, 1e-8, 1e-4, 1000.0  # noqa: E741
G, KS = E / 3, 5 / 6
EI = E * I


def loaded_rod(n, **kw):
    """A cantilever with a tip force (Fx, Fy) and torque M in the fixed frame."""
    rod = CosseratRod("rod", n=n, L=L, E=E, I=I, A=A, rho=RHO, tip="force", **kw)
    return interconnect("cantilever", [rod, ForceSource("Fx"), ForceSource("Fy"), TorqueSource("M")],
                        [series("Fx", "rod.tip_x"), series("Fy", "rod.tip_y"), series("M", "rod.tip_m")])


def static_state(system, u, steps=4):
    """Rest state for the inputs ``u`` (dict): Newton on the generated right-hand side, load stepped."""
    f = generate(system)
    p = system.param_vector()
    x = np.zeros(len(system.states))
    uvec = np.array([u.get(name, 0.0) for name in system.input_names])
    for lam in np.linspace(0, 1, steps + 1)[1:]:
        for _ in range(60):
            r = np.array(f.rhs(x, lam * uvec, p)).ravel()
            if np.max(np.abs(r)) < 1e-13:
                break
            Ajac = np.array(f.jac_rhs(x, lam * uvec, p)[0])
            x = x - np.linalg.solve(Ajac, r)
    return x


def bvp_tip(Fx=0.0, Fy=0.0, M=0.0, q=0.0):
    """Tip position of the continuum rod under a tip load and a uniform load ``q`` [N/m] along y."""
    EA, GA = E * A, KS * G * A

    def rhs(s, Y):
        x, y, th, nx, ny, m = Y
        c, sn = np.cos(th), np.sin(th)
        nu1, nu2 = (c * nx + sn * ny) / EA, (-sn * nx + c * ny) / GA
        xp, yp = (1 + nu1) * c - nu2 * sn, (1 + nu1) * sn + nu2 * c
        return np.vstack([xp, yp, m / EI, 0 * s, -q + 0 * s, -(xp * ny - yp * nx)])

    def bc(a, b):
        return np.array([a[0], a[1], a[2], b[3] - Fx, b[4] - Fy, b[5] - M])

    s = np.linspace(0, L, 101)
    Y0 = np.zeros((6, s.size))
    Y0[0] = s
    sol = solve_bvp(rhs, bc, s, Y0, tol=1e-10, max_nodes=200000)
    assert sol.success
    return sol.y[0, -1], sol.y[1, -1]


def tip_of(system, x, n):
    d = dict(zip(system.state_names, x))
    return L + d[f"rod.ux{n}"], d[f"rod.uy{n}"]


# -- structure -----------------------------------------------------------------------------------------------------
def test_strains_vanish_under_rigid_motion_and_measure_bending():
    a = sp.Symbol("a", real=True)
    strains = element_strains(1.0, 2.0, a, 1.0 + sp.cos(a), 2.0 + sp.sin(a), a, 1)
    assert all(sp.simplify(s) == 0 for s in strains)
    assert element_strains(0, 0, 0, 1, 0, 0.2, 1)[2] == pytest.approx(0.2)


def test_J_is_canonical_and_R_is_psd():
    s = interconnect("rod", [CosseratRod("rod", n=4, tau=0.02, c_v=0.3, L=L, E=E, I=I, A=A, rho=RHO)])
    nq = len(s.states)
    assert (s.J + s.J.T).is_zero_matrix
    assert all(v in (0, 1, -1) for v in s.J)
    Rn = np.array(s.R.subs({p.symbol: p.value for p in s.params}), dtype=float)
    assert np.allclose(Rn, Rn.T)
    assert np.min(np.linalg.eigvalsh(Rn)) > -1e-12 * np.max(np.abs(Rn))
    # only momenta are damped: rows of configuration states are zero
    qrows = [i for i, name in enumerate(s.state_names) if name.split(".")[1][:2] in ("ux", "uy", "th")]
    assert np.all(Rn[qrows] == 0) and nq == 24


def test_exact_kelvin_voigt_R_is_psd_at_deformed_states():
    s = interconnect("rod", [CosseratRod("rod", n=2, tau=0.02, damping="kelvin_voigt", L=L, E=E, I=I, A=A, rho=RHO)])
    assert s.R.free_symbols & set(s.x)  # configuration dependent
    f = s.lambdify(s.R)
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.uniform(-0.5, 0.5, len(s.states))
        Rn = np.asarray(f(x, [], s.param_vector()), dtype=float)
        assert np.min(np.linalg.eigvalsh((Rn + Rn.T) / 2)) > -1e-9 * np.max(np.abs(Rn))
    assert s.check().ok


@pytest.mark.parametrize("kw, culprit", [
    ({"n": 0}, "n"), ({"tip": "pinned"}, "tip"), ({"damping": "coulomb"}, "damping"), ({"couples": [9]}, "couples"),
    ({"couples": [(2, 1)]}, "couples"),
    ({"distributed": ["z"]}, "'x' or 'y'"), ({"tau": -1.0}, "tau"), ({"E": -1.0}, "'E'"),
])
def test_invalid_options_name_the_culprit(kw, culprit):
    with pytest.raises(ModelError, match=culprit):
        CosseratRod("rod", **{"n": 3, **kw})


# -- statics against the continuum boundary-value problem --------------------------------------------------------------
@pytest.mark.parametrize("load", [{"Fy": -0.5 * EI / L**2}, {"Fx": 0.2 * EI / L**2, "Fy": -0.3 * EI / L**2, "M": 0.1 * EI / L}])
def test_tip_load_statics_match_bvp(load):
    n = 20
    s = loaded_rod(n)
    x = static_state(s, load)
    ref = bvp_tip(**load)
    assert np.hypot(*(np.array(tip_of(s, x, n)) - ref)) < 1e-4 * L


def test_gravity_statics_match_bvp():
    n = 20
    rod = CosseratRod("rod", n=n, L=L, E=E, I=I, A=A, rho=RHO, gravity=True, g=0.5 * EI / (RHO * A * L**3))
    s = interconnect("hanging", [rod])
    x = static_state(s, {})
    ref = bvp_tip(q=-0.5 * EI / L**3)
    assert np.hypot(*(np.array(tip_of(s, x, n)) - ref)) < 1e-4 * L


def test_follower_load_equals_fixed_load_at_the_deformed_tip_angle():
    """A follower normal force F bends the rod like the fixed-frame force F(-sin phi, cos phi) at the tip angle phi."""
    n = 10
    rod = CosseratRod("rod", n=n, L=L, E=E, I=I, A=A, rho=RHO, tip="follower")
    s = interconnect("follower", [rod, ForceSource("Ft"), ForceSource("Fn"), TorqueSource("M")],
                     [series("Ft", "rod.tip_t"), series("Fn", "rod.tip_n"), series("M", "rod.tip_m")])
    F = -0.5 * EI / L**2
    x = static_state(s, {"Fn": F})
    phi = dict(zip(s.state_names, x))[f"rod.theta{n}"]
    fixed = loaded_rod(n)
    xf = static_state(fixed, {"Fx": -F * np.sin(phi), "Fy": F * np.cos(phi)})
    np.testing.assert_allclose(tip_of(s, x, n), tip_of(fixed, xf, n), atol=1e-9)


def test_convergence_order_is_two():
    load = {"Fy": -0.5 * EI / L**2}
    ref = np.array(bvp_tip(**load))
    errs = []
    for n in (5, 10, 20):
        s = loaded_rod(n)
        errs.append(np.hypot(*(np.array(tip_of(s, static_state(s, load), n)) - ref)))
    order = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(order - 2) < 0.1), order


# -- linear vibration -------------------------------------------------------------------------------------------------------
def linear_frequencies(system):
    f = generate(system)
    Ajac = np.array(f.jac_rhs(np.zeros(len(system.states)), np.zeros(len(system.inputs)), system.param_vector())[0])
    w = np.sort(np.abs(np.linalg.eigvals(Ajac).imag))
    return np.unique(np.round(w[w > 1e-9], 6))


def test_first_three_bending_frequencies_match_euler_bernoulli():
    Islender = 1e-10  # radius of gyration L/1000: shear and rotary inertia change the first modes by < 1e-4
    s = interconnect("rod", [CosseratRod("rod", n=40, L=L, E=E, I=Islender, A=A, rho=RHO)])
    w = linear_frequencies(s)[:3]
    beta = np.array([1.875104069, 4.694091133, 7.854757438])
    exact = beta**2 * np.sqrt(E * Islender / (RHO * A * L**4))
    np.testing.assert_allclose(w, exact, rtol=0.01)


# -- dynamics ----------------------------------------------------------------------------------------------------------------
def test_energy_balance_with_damping_and_a_tip_force():
    s = loaded_rod(8, tau=0.01, c_v=0.05)
    t = np.linspace(0, 2.0, 401)
    res = simulate(s, t, u={"Fy": step(-0.5 * EI / L**2, at=0.1)}, rtol=1e-10)
    assert res.energy_balance_error() < 1e-6
    assert np.max(res["rod.damping1"]) > 0 and np.min(res["dissipated"]) >= -1e-15


@pytest.mark.slow
def test_statics_match_bvp_at_n40_for_a_large_deflection():
    n = 40
    load = {"Fy": -2 * EI / L**2}
    s = loaded_rod(n)
    ref = bvp_tip(**load)
    assert np.hypot(*(np.array(tip_of(s, static_state(s, load, steps=8), n)) - ref)) < 1e-4 * L
