"""Kinematic chains: inertia matrix, energy without symbolic inversion, assembly and power balance."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from codegen.functions import generate
from codegen.translate import Translator
from components import RotationalDamper, RotationalInertia, TorqueSource, TorsionalSpring
from components.kinematics import (
    ConfigurationInertia,
    InverseEntry,
    InverseQuadraticForm,
    KinematicChain,
    LinearSolve,
    planar_chain_inertia,
    reduced_inertia,
)
from phs import ModelError, Param, interconnect, series, symbol_of_state

LENGTHS = [0.1, 0.2, 0.15]
MASSES = [0.05, 0.03, 0.02]


def chain_system(n: int, torque: bool = True, **kw):
    """n-link chain, each joint a torsional spring and a damper in series with its momentum; torque at joint 1."""
    chain = KinematicChain("arm", [f"seg{i}.theta" for i in range(1, n + 1)], LENGTHS[:n], MASSES[:n], **kw)
    parts, junctions = [chain], []
    for i in range(1, n + 1):
        parts += [TorsionalSpring(f"seg{i}", K=0.04 * i, state=f"seg{i}.theta"), RotationalDamper(f"b{i}", b=1e-3 * i)]
        junctions.append([f"arm.p{i}", f"seg{i}", f"b{i}"])
    if torque:
        parts.append(TorqueSource("T"))
        junctions[0].append("T")
    return interconnect(f"chain{n}", parts, [series(*j) for j in junctions])


def numeric_inertia(theta, a, m, c, inertia):
    """Eq. 12 with J_v from complex-step derivatives of the centre-of-mass positions (exact to rounding)."""
    n = len(theta)

    def positions(th):
        phi = np.cumsum(th)
        out = []
        for i in range(n):
            x = sum(a[j] * np.cos(phi[j]) for j in range(i)) + c[i] * np.cos(phi[i])
            y = sum(a[j] * np.sin(phi[j]) for j in range(i)) + c[i] * np.sin(phi[i])
            out.append(np.array([x, y]))
        return out

    h = 1e-30
    Jv = [np.zeros((2, n)) for _ in range(n)]
    for k in range(n):
        th = np.array(theta, dtype=complex)
        th[k] += 1j * h
        for i, r in enumerate(positions(th)):
            Jv[i][:, k] = r.imag / h
    M = np.zeros((n, n))
    for i in range(n):
        Jw = np.array([[1.0] * (i + 1) + [0.0] * (n - i - 1)])
        M += m[i] * Jv[i].T @ Jv[i] + inertia[i] * Jw.T @ Jw
    return M


def chain_values(system, n):
    v = system.param_values()
    a = np.array([v[f"arm.a{i}"] for i in range(1, n + 1)])
    m = np.array([v[f"arm.m{i}"] for i in range(1, n + 1)])
    return a, m, a / 2, m * a**2 / 12


def rel(x, y):
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return np.max(np.abs(x - y)) / max(np.max(np.abs(y)), 1e-300)


# -- 1. inertia matrix -------------------------------------------------------------------------------------


def test_two_link_inertia_is_the_double_pendulum_closed_form():
    chain = KinematicChain("dp", ["q1", "q2"], lengths=[0.3, 0.2], masses=[1.0, 0.5], com=[0.1, 0.12],
                           inertia=[0.01, 0.004])
    M = chain.inertia_matrix()
    a1, m1, m2, c1, c2, I1, I2 = (sp.Symbol(f"dp.{k}", positive=True) for k in "a1 m1 m2 c1 c2 I1 I2".split())
    q2 = symbol_of_state("q2")
    m12 = m2 * (c2**2 + a1 * c2 * sp.cos(q2)) + I2
    expected = sp.Matrix([
        [m1 * c1**2 + I1 + m2 * (a1**2 + c2**2 + 2 * a1 * c2 * sp.cos(q2)) + I2, m12],
        [m12, m2 * c2**2 + I2],
    ])
    assert (M - expected).applyfunc(sp.expand) == sp.zeros(2, 2)
    assert {p.name for p in chain.piece().params} == {"dp.a1", "dp.a2", "dp.m1", "dp.m2", "dp.c1", "dp.c2",
                                                     "dp.I1", "dp.I2"}


def test_three_link_inertia_matches_the_jacobians_of_the_centres_of_mass():
    q = sp.symbols("q1:4", real=True)
    M = sp.lambdify(q, planar_chain_inertia(q, LENGTHS, MASSES, [0.04, 0.11, 0.03], [1e-4, 2e-4, 5e-5]))
    rng = np.random.default_rng(3)
    for theta in rng.uniform(-np.pi, np.pi, size=(5, 3)):
        ref = numeric_inertia(theta, np.array(LENGTHS), np.array(MASSES), [0.04, 0.11, 0.03], [1e-4, 2e-4, 5e-5])
        assert rel(M(*theta), ref) < 1e-13


def test_shared_parameters_and_expressions_are_used_as_given():
    L = Param("L", 0.015, "m", "segment length")
    chain = KinematicChain("c", ["s1.theta", "s2.theta"], lengths=[L, 2 * L.symbol], masses=[0.007, 0.007])
    names = {p.name for p in chain.piece().params}
    assert "L" in names and "c.a1" not in names and "c.a2" not in names
    assert chain.inertia_matrix()[1, 1] == sp.Symbol("c.m2", positive=True) * (2 * L.symbol) ** 2 / 3


# -- 2. energy and gradient: numpy, CasADi and an independent numpy computation ---------------------------


def test_energy_agrees_between_numpy_casadi_and_a_direct_solve():
    s = chain_system(2)
    fH, gen = s.lambdify(s.H), generate(s)
    a, m, c, inertia = chain_values(s, 2)
    pv = s.param_vector()
    k = np.array([0.04, 0.08])
    for x in s.sample_box(20, seed=1):
        p, theta = x[:2], x[2:]
        M = numeric_inertia(theta, a, m, c, inertia)
        ref = 0.5 * p @ np.linalg.inv(M) @ p + 0.5 * k @ theta**2
        assert rel(fH(x, [0.0], pv), ref) < 1e-12
        assert rel(gen.hamiltonian(x, [0.0], pv).full(), ref) < 1e-12


@pytest.mark.parametrize("n", [2, 3])
def test_symbolic_gradient_agrees_with_casadi_automatic_differentiation(n):
    s = chain_system(n)
    fg, gen = s.lambdify(s.grad_H), generate(s)
    pv = s.param_vector()
    for x in s.sample_box(20, seed=2):
        assert rel(np.ravel(fg(x, [0.0], pv)), gen.grad_hamiltonian(x, [0.0], pv).full().ravel()) < 1e-10


def test_second_derivatives_translate_to_casadi_and_agree_with_numpy():
    """The Hessian uses InverseEntry; translated to CasADi it matches numpy and CasADi's AD Hessian."""
    import casadi as ca

    s = chain_system(2, torque=False)
    hess = sp.Matrix(s.grad_H).jacobian(s.x)
    gen = generate(s)
    X, P = gen.sx["x"], gen.sx["p"]
    tr = Translator({**{v: X[i] for i, v in enumerate(s.x)}, **{v: P[i] for i, v in enumerate(s.p)}})
    f_sym = ca.Function("h", [X, P], [tr(hess)])
    f_ad = ca.Function("h", [X, P], [ca.hessian(gen.sx["H"], X)[0]])
    f_np = s.lambdify(hess)
    pv = s.param_vector()
    for x in s.sample_box(10, seed=4):
        ref = f_ad(x, pv).full()
        assert rel(f_sym(x, pv).full(), ref) < 1e-10
        assert rel(f_np(x, [], pv), ref) < 1e-10


def test_inverse_functions_evaluate_exactly_on_numbers_and_broadcast_in_numpy():
    M = sp.Matrix([[4, 1, 0], [1, 3, 1], [0, 1, 2]])
    p = sp.Matrix([1, -2, 3])
    up = [M[i, j] for i in range(3) for j in range(i, 3)]
    assert InverseQuadraticForm(*up, *p) == (p.T * M.inv() * p)[0] / 2
    assert [LinearSolve(k, *up, *p) for k in range(3)] == list(M.inv() * p)
    assert InverseEntry(2, 0, *up) == InverseEntry(0, 2, *up) == M.inv()[0, 2]
    x = sp.Symbol("x", real=True)
    f = sp.lambdify(x, InverseQuadraticForm(*up[:-1], 2 + x, *p), "numpy")
    xs = np.array([0.0, 1.0, 2.5])
    ref = [float((p.T * M.subs(M[2, 2], 2 + v).inv() * p)[0]) / 2 for v in xs]
    assert rel(f(xs), ref) < 1e-14
    with pytest.raises(ModelError, match="upper triangle"):
        InverseQuadraticForm(x, x, x)


# -- 3. assembly and structure -------------------------------------------------------------------------------


def test_three_link_chain_assembles_with_skew_j_and_psd_r():
    s = chain_system(3)
    assert s.state_names == ["arm.p1", "arm.p2", "arm.p3", "seg1.theta", "seg2.theta", "seg3.theta"]
    assert (s.J + s.J.T) == sp.zeros(6, 6)
    report = s.check()
    for item in ("J skew-symmetric", "R symmetric", "R positive semidefinite", "H bounded below"):
        assert report[item].verdict == "pass", str(report)


def test_three_link_chain_passes_every_check_including_units():
    assert chain_system(3).check().ok


def test_energy_dimension_hook_gives_joules():
    from phs.units import JOULE, dimension, parse_unit

    s = chain_system(3)
    units = {v.symbol: parse_unit(v.unit) for v in s.states} | {q.symbol: parse_unit(q.unit) for q in s.params}
    H = s.energy_terms[0].expr
    assert isinstance(H, InverseQuadraticForm)
    assert H._dimension([dimension(a, units) for a in H.args]) == JOULE


# -- 4. power balance ----------------------------------------------------------------------------------------


def test_power_balance_holds_at_random_states():
    s = chain_system(3)
    pb = s.power_balance
    f_terms = s.lambdify([pb["dissipated"], pb["supplied"]])
    f_grad, f_dyn = s.lambdify(s.grad_H), s.lambdify(s.dynamics)
    gen = generate(s)
    pv = s.param_vector()
    rng = np.random.default_rng(5)
    for x in s.sample_box(20, seed=6):
        u = rng.uniform(-0.05, 0.05, size=1)
        dHdt = float(np.ravel(f_grad(x, u, pv)) @ np.ravel(f_dyn(x, u, pv)))
        dissipated, supplied = (float(v) for v in f_terms(x, u, pv))
        scale = max(abs(dHdt), abs(dissipated), abs(supplied))
        assert abs(dHdt - (supplied - dissipated)) < 1e-9 * scale
        assert dissipated >= 0
        c_dHdt, c_diss, c_sup = (float(v) for v in gen.power_balance(x, u, pv))
        assert abs(c_dHdt - dHdt) < 1e-9 * scale and abs(c_diss - dissipated) < 1e-9 * scale
        assert abs(c_sup - supplied) < 1e-9 * scale


# -- 5. closed chains ----------------------------------------------------------------------------------------


def test_parallelogram_reduces_to_a_constant_inertia():
    """Crank (a, m1) - coupler (d, m2) - crank (a, m3) closing on the ground: cranks turn, coupler translates."""
    a, d, m1, m2, m3 = sp.symbols("a d m1 m2 m3", positive=True)
    phi = sp.Symbol("phi", real=True)
    th = sp.symbols("t1:4", real=True)
    M = planar_chain_inertia(th, [a, d, a], [m1, m2, m3])
    closure = {th[0]: phi, th[1]: -phi, th[2]: phi + sp.pi}  # coupler stays parallel to the ground
    T = sp.Matrix([sp.diff(v, phi) for v in closure.values()])
    Mr = reduced_inertia(M.subs(closure), T)
    # each crank rotates about its ground pivot (m a**2/3), the coupler translates on a circle of radius a
    assert sp.simplify(Mr[0, 0] - (m1 * a**2 / 3 + m2 * a**2 + m3 * a**2 / 3)) == 0
    with pytest.raises(ModelError, match="reduced_inertia"):
        reduced_inertia(M, sp.Matrix([1, 1]))


def test_reduced_chain_behaves_like_the_equivalent_rigid_body():
    a, m = 0.1, [0.05, 0.08, 0.05]
    phi = symbol_of_state("crank.phi")
    th = sp.symbols("t1:4", real=True)
    M = planar_chain_inertia(th, [a, 0.3, a], m)
    closure = {th[0]: phi, th[1]: -phi, th[2]: phi + sp.pi}
    Mr = reduced_inertia(M.xreplace(closure), sp.Matrix([1, -1, 1]))
    parts = [ConfigurationInertia("link", ["crank.phi"], Mr), TorsionalSpring("crank", K=0.2, state="crank.phi")]
    s = interconnect("four_bar", parts, [series("link.p1", "crank")])
    I_eq = m[0] * a**2 / 3 + m[1] * a**2 + m[2] * a**2 / 3
    ref = interconnect("body", [RotationalInertia("link", I=I_eq, state="link.p1"),
                                TorsionalSpring("crank", K=0.2, state="crank.phi")], [series("link", "crank")])
    f, g = s.lambdify(s.dynamics), ref.lambdify(ref.dynamics)
    for x in s.sample_box(5, seed=7):
        assert rel(f(x, [], s.param_vector()), g(x, [], ref.param_vector())) < 1e-12


# -- 6. invalid input --------------------------------------------------------------------------------------


@pytest.mark.parametrize("kw, culprit", [
    (dict(lengths=[0.1], masses=[0.1, 0.1]), "lengths"),
    (dict(lengths=[0.1, 0.1], masses=[0.1, -0.1]), "masses"),
    (dict(lengths=[0.1, 0.1], masses=[0.1, 0.1], com=[0.05]), "com"),
    (dict(lengths=[0.1, 0.1], masses=[0.1, 0.1], momenta=["x.p"]), "momenta"),
])
def test_invalid_arguments_name_the_culprit(kw, culprit):
    with pytest.raises(ModelError, match=culprit):
        KinematicChain("bad", ["s1.theta", "s2.theta"], **kw)


def test_inertia_must_not_depend_on_the_chain_momenta():
    p = symbol_of_state("c.p1")
    with pytest.raises(ModelError, match="own momenta"):
        ConfigurationInertia("c", ["q"], sp.Matrix([[1 + p**2]])).piece()


def test_inertia_matrix_must_be_symmetric_and_square():
    q = symbol_of_state("q")
    with pytest.raises(ModelError, match="symmetric 2 x 2"):
        ConfigurationInertia("c", ["q", "r"], sp.Matrix([[1, q], [0, 1]])).piece()
    with pytest.raises(ModelError, match="domain"):
        ConfigurationInertia("c", ["q"], sp.Matrix([[1]]), domain="electrical")


def test_translational_coordinates_get_linear_momenta():
    st = ConfigurationInertia("plat", ["x"], sp.Matrix([[2.0]]), domain="translational").piece().storages[0]
    assert (st.state.unit, st.port.domain, st.state.range) == ("kg*m/s", "translational", (-20.0, 20.0))
