"""Every component of the library passes the same port-Hamiltonian laws.

Each case is a small model that embeds one component type (with the few
others it needs to be a closed, driven system).  At seeded hypothesis points
inside the states' declared ranges, with random inputs:

* J is skew-symmetric and [[R, P], [P^T, S]] is symmetric positive semidefinite;
* the power balance dH/dt = y^T u - z^T [[R, P], [P^T, S]] z holds for the
  generated CasADi functions and for the sympy-lambdified expressions;
* the per-element dissipated powers (computed by the library from the port
  variables of each resistive element) add up to the total dissipated power.

A completeness test makes sure every component class exported by
``components`` is covered by some case.
"""

from __future__ import annotations

import functools
import inspect

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import components
from codegen import generate
from components import (
    Capacitor,
    Chamber,
    ConfigurationInertia,
    CurrentSource,
    Damper,
    DriftBranch,
    FlowSource,
    ForceSource,
    GeometricConstraint,
    Geometry,
    Gravity,
    Gyrator,
    Inductor,
    KinematicChain,
    LinearSpring,
    Mass,
    NonlinearSpring,
    PeanoHasel,
    PositionLoop,
    Potential,
    PressureTransducer,
    Resistor,
    RotationalDamper,
    RotationalInertia,
    TorqueSource,
    TorsionalSpring,
    Transformer,
    VariableCapacitor,
    VelocityLoop,
    VoltageSource,
    geometric_symbol,
)
from phs import Component, Param, bond, interconnect, parallel, series, symbol_of_state
from phs.checks import unit_problems
from phs.structure_units import structure_unit_problems

# Power balance: rounding of the products and sums is bounded by a few ulps of the sum of the
# absolute values of the summands (|dH/dt|, |y^T u|, |dissipated| and the terms dH_i * x'_i of
# dH/dt).  1e-9 of that is six orders above rounding and far below any modelling error.
BALANCE_TOL = 1e-9
# Dissipators: the per-element powers and the quadratic form are sums of the same products
# z_i D_ij z_j (which can cancel, e.g. (U - Q/C)^2 / R); relative to sum |z_i D_ij z_j| the two
# evaluation orders agree to a few ulps, so 1e-12 leaves three to four orders of margin.
DISSIPATOR_TOL = 1e-12
# PSD: eigenvalues of a symmetric matrix are accurate to ~n*eps*||D||.
PSD_TOL = 1e-10

POINTS = settings(max_examples=25, deadline=None, database=None, derandomize=True)


def _spec(name, comps, conns, params=()):
    """What a case passes to :func:`phs.interconnect` (kept so the coverage test can inspect it)."""
    return name, list(comps), list(conns), list(params)


def _rc_like(store, name="m"):
    return _spec(name, [VoltageSource("U"), Resistor("R", R=1e3), store], [series("U", "R", store.name)])


def _capacitor():
    return _rc_like(Capacitor("C", C=1e-6))


def _variable_capacitor():
    """Capacitance modulated by a spring length: the electrostatic force enters through dH/dl."""
    C0 = Param("C0", 1e-6, "F", "nominal capacitance")
    l0 = Param("l0", 0.01, "m", "modulation length")
    l = symbol_of_state("k.l")  # noqa: E741
    return _spec(
        "varcap",
        [VoltageSource("U"), Resistor("R", R=1e3),
         VariableCapacitor("Cv", C=C0.symbol * (2 + sp.sin(l / l0.symbol)), C_typical=1e-6),
         Mass("m", m=0.01), LinearSpring("k", K=100.0), Damper("b", b=0.5)],
        [series("U", "R", "Cv"), series("m", "k", "b")],
        params=[C0, l0],
    )


def _inductor():
    return _spec("rl", [VoltageSource("U"), Resistor("R", R=10.0), Inductor("L", L=1e-3), Capacitor("C")],
                        [series("U", "R", "L", "C")])


def _resistor_conductance():
    return _spec("rg", [VoltageSource("U"), Resistor("G", G=1e-3), Capacitor("C")], [series("U", "G", "C")])


def _modulated_resistor():
    """Resistance depending on the charge: R = R0 (2 + sin(Q / Qs))."""
    R0 = Param("R0", 1e3, "Ohm", "nominal resistance")
    Qs = Param("Qs", 1e-3, "C", "modulation charge")
    q = symbol_of_state("C.Q")
    return _spec("rmod", [VoltageSource("U"), Resistor("R", R=R0.symbol * (2 + sp.sin(q / Qs.symbol))),
                          Capacitor("C")], [series("U", "R", "C")], params=[R0, Qs])


def _current_source():
    return _spec("ic", [CurrentSource("I"), Capacitor("C"), Resistor("R", R=1e3)], [parallel("I", "C", "R")])


def _drift_branch():
    return _spec("drift", [VoltageSource("U"), Resistor("R0", R=1e3), Capacitor("C", C=1e-8),
                                  DriftBranch("D", C1=1e-6, R1=1e5)], [series("U", "R0", "C", "D")])


def _msd():
    return _spec("msd", [ForceSource("F"), Mass("m", m=1.0), LinearSpring("k", K=4.0, L0=0.05),
                                Damper("b", b=0.4)], [series("F", "m", "k", "b")])


def _nonlinear_spring():
    q = sp.Symbol("q", real=True)
    k, k3 = Param("k", 2.0, "N/m", "linear stiffness"), Param("k3", 50.0, "N/m**3", "cubic stiffness")
    g, w = Param("g0", 0.5, "N", "gaussian force"), Param("w", 0.05, "m", "gaussian width")
    force = k.symbol * q + k3.symbol * q**3 + g.symbol * sp.exp(-(q / w.symbol) ** 2) * q / w.symbol
    return _spec("nls", [ForceSource("F"), Mass("m", m=0.5), Damper("b", b=0.2),
                         NonlinearSpring("s", force=force, variable=q, params=[k, k3, g, w])],
                        [series("F", "m", "s", "b")])


def _rotational():
    return _spec("rot", [TorqueSource("T"), RotationalInertia("J", I=1e-4), TorsionalSpring("kb", K=0.04),
                                RotationalDamper("b", b=3e-3)], [series("T", "J", "kb", "b")])


def _gravity():
    """Pendulum: gravity acts on the angle of a torsional spring through H only."""
    th = symbol_of_state("kb.theta")
    Lp = Param("L_p", 0.1, "m", "pendulum length")
    return _spec("pend", [TorqueSource("T"), RotationalInertia("J", I=1e-3), TorsionalSpring("kb", K=0.01),
                          RotationalDamper("b", b=1e-3), Gravity("grav", height=-Lp.symbol * sp.cos(th), m=0.05)],
                 [series("T", "J", "kb", "b")], params=[Lp])


def _potential():
    """A stateless quartic potential on a torsional spring's angle (a hardening joint)."""
    th = symbol_of_state("kb.theta")
    k4 = Param("k4", 0.5, "N*m/rad", "quartic stiffness")
    return _spec("quartic", [TorqueSource("T"), RotationalInertia("J", I=1e-3), TorsionalSpring("kb", K=0.01),
                             RotationalDamper("b", b=1e-3), Potential("hard", k4.symbol * th**4 / 4, params=[k4])],
                 [series("T", "J", "kb", "b")], params=[k4])


def _transformer():
    """Lever whose ratio depends on the lever's own spring length (a modulated transformer)."""
    n0 = Param("n0", 2.0, "1", "nominal lever ratio")
    l0 = Param("l0", 0.1, "m", "modulation length")
    l = symbol_of_state("k.l")  # noqa: E741
    return _spec("lever", [ForceSource("F"), Mass("m"), Transformer("tf", n0.symbol * (1 + (l / l0.symbol) ** 2)),
                           LinearSpring("k", K=3.0), Damper("b", b=0.3)],
                 [series("F", "m", "tf.a"), series("tf.b", "k", "b")], params=[n0, l0])


def _gyrator():
    """DC motor: electrical loop and rotor joined by a gyrator (torque constant)."""
    return _spec("motor", [VoltageSource("U"), Resistor("R", R=2.0), Inductor("L", L=1e-3),
                                  Gyrator("kt", 0.05, "N*m/A"), RotationalInertia("J", I=1e-5), RotationalDamper("b", b=1e-5)],
                        [series("U", "R", "L", "kt.a"), series("kt.b", "J", "b")])


def _geometric_constraint():
    """A geometric variable l_e solved from a relation with the angle, used in a capacitance."""
    th = symbol_of_state("kb.theta")
    le = geometric_symbol("l_e")
    Lt = Param("L_t", 0.05, "m", "total length")
    r = Param("r", 0.01, "m/rad", "winding radius")
    con = GeometricConstraint("geo", "l_e", sp.Eq(Lt.symbol, le + r.symbol * th), params=[Lt, r],
                              conditions=[("l_e positive", le)], unit="m")
    eps = Param("eps_w", 1e-4, "F/m", "capacitance per unit length")
    return _spec("geocap", [VoltageSource("U"), Resistor("R", R=1e3),
                                   VariableCapacitor("Ce", C=eps.symbol * le, C_typical=2e-6), con,
                                   TorqueSource("T"), RotationalInertia("J", I=1e-4), TorsionalSpring("kb", K=0.04),
                                   RotationalDamper("b", b=3e-3)],
                        [series("U", "R", "Ce"), series("T", "J", "kb", "b")], params=[eps])


def _geometry():
    """An explicit geometric definition (tip height) used by gravity."""
    th = symbol_of_state("kb.theta")
    Lp = Param("L_p", 0.1, "m", "pendulum length")
    geo = Geometry("geo", {"tip": -Lp.symbol * sp.cos(th)}, params=[Lp], units={"tip": "m"})
    return _spec("geopend", [TorqueSource("T"), RotationalInertia("J", I=1e-3), TorsionalSpring("kb", K=0.01),
                                    RotationalDamper("b", b=1e-3), geo,
                                    Gravity("grav", height=geometric_symbol("tip"), m=0.05)],
                        [series("T", "J", "kb", "b")])


def _kinematic_chain():
    """Double pendulum on damped torsional joints, driven at the first joint."""
    arm = KinematicChain("arm", ["j1.theta", "j2.theta"], lengths=[0.1, 0.08], masses=[0.05, 0.03])
    return _spec("arm", [arm, TorqueSource("T"), TorsionalSpring("j1", K=0.04, state="j1.theta"),
                         RotationalDamper("b1", b=1e-3), TorsionalSpring("j2", K=0.02, state="j2.theta"),
                         RotationalDamper("b2", b=1e-3)],
                 [series("T", "arm.p1", "j1", "b1"), series("arm.p2", "j2", "b2")])


def _configuration_inertia():
    """A rod whose inertia depends on its angle, M(q) = I0 (1 + cos(q)^2)."""
    q = symbol_of_state("j.theta")
    I0 = Param("I0", 1e-4, "kg*m**2", "base inertia")
    rod = ConfigurationInertia("rod", ["j.theta"], sp.Matrix([[I0.symbol * (1 + sp.cos(q) ** 2)]]), params=[I0])
    return _spec("rod", [rod, TorqueSource("T"), TorsionalSpring("j", K=0.04, state="j.theta"),
                         RotationalDamper("b", b=1e-3)], [series("T", "rod.p1", "j", "b")])


def _bonded_transformer_chain():
    """A transformer bonded straight to a spring (``bond``) inside a force-driven chain."""
    return _spec("tfbond", [ForceSource("F"), Mass("m"), Damper("b"), Transformer("tf", 0.5),
                                   LinearSpring("k", K=2.0)], [series("F", "m", "b", "tf.a"), bond("tf.b", "k")])


def _position_loop():
    """A mass-spring-damper under PD position control (unfiltered reference)."""
    return _spec("servo", [Mass("m", m=0.5), LinearSpring("k", K=4.0), Damper("b", b=0.2),
                           PositionLoop("pd", K_p=20.0, K_d=2.0)], [series("m", "k", "b", "pd")])


def _position_loop_filtered():
    """PD position control on a first-order filtered reference, acting on the plant's own position state."""
    return _spec("servo_f", [Mass("m", m=0.5), LinearSpring("k", K=4.0), Damper("b", b=0.2),
                             PositionLoop("pd", K_p=20.0, K_d=0.5, tau=0.05, position="k.l")],
                 [series("m", "k", "b", "pd")])


def _velocity_loop():
    """A mass with viscous friction under velocity control (a virtual damper to a reference velocity)."""
    return _spec("cruise", [Mass("m", m=0.5), Damper("b", b=0.2), VelocityLoop("vc", K_v=3.0)],
                 [series("m", "b", "vc")])


def _rod_and_hydrogel():
    """A two-element Cosserat rod (exact Kelvin-Voigt damping, gravity, drag) under a follower tip force,
    bent by a hydrogel actuator on its first element."""
    from components import CosseratRod, HydrogelActuator

    rod = CosseratRod("rod", n=2, L=0.1, E=1e5, I=1e-10, A=1e-5, tau=0.01, damping="kelvin_voigt", c_v=0.01,
                      gravity=True, tip="follower", couples=[1])
    return _spec("rodsva", [rod, ForceSource("Ft"), ForceSource("Fn"), TorqueSource("M"), HydrogelActuator("sva", input="V")],
                 [series("Ft", "rod.tip_t"), series("Fn", "rod.tip_n"), series("M", "rod.tip_m"), series("rod.c1", "sva.c")])


def _peano_hasel():
    """A Peano-HASEL (eq. 3 of the swimmer paper) pulling a mass against a spring; strain from the spring's length."""
    l = symbol_of_state("k.l")  # noqa: E741
    L0 = Param("L0", 0.05, "m", "flat length")
    act = PeanoHasel("act", strain=(L0.symbol - l) / L0.symbol, L0=L0)
    # lengths from 0.05 % longer than flat (film taut) to 6 % shorter (beyond the fit's minimum)
    return _spec("peano", [VoltageSource("U"), Resistor("R", R=1e6), act, Mass("m", m=0.01),
                           LinearSpring("k", K=200.0, range=(0.047, 0.050025)), Damper("b", b=0.5)],
                 [series("U", "R", "act"), series("m", "k", "b")], params=[L0])


def _hydraulic():
    """A flow source filling a cubic chamber whose pressure pushes a piston against a spring."""
    return _spec("piston", [FlowSource("q"), Chamber("ch", k1=1e9, k2=7e14, k3=2e19), PressureTransducer("A", A=2e-5),
                            Mass("m", m=0.02), LinearSpring("k", K=2000.0), Damper("b", b=2.0)],
                 [parallel("q", "ch", "A.a"), series("A.b", "m", "k", "b")])


CASES = {
    "CosseratRod": _rod_and_hydrogel,
    "HydrogelActuator": _rod_and_hydrogel,
    "Capacitor": _capacitor,
    "VariableCapacitor": _variable_capacitor,
    "Inductor": _inductor,
    "Resistor": _capacitor,
    "Resistor(G)": _resistor_conductance,
    "Resistor(modulated)": _modulated_resistor,
    "VoltageSource": _capacitor,
    "CurrentSource": _current_source,
    "DriftBranch": _drift_branch,
    "Mass": _msd,
    "LinearSpring": _msd,
    "Damper": _msd,
    "ForceSource": _msd,
    "NonlinearSpring": _nonlinear_spring,
    "RotationalInertia": _rotational,
    "TorsionalSpring": _rotational,
    "RotationalDamper": _rotational,
    "TorqueSource": _rotational,
    "Gravity": _gravity,
    "Potential": _potential,
    "Transformer": _transformer,
    "Transformer(bond)": _bonded_transformer_chain,
    "Gyrator": _gyrator,
    "GeometricConstraint": _geometric_constraint,
    "Geometry": _geometry,
    "KinematicChain": _kinematic_chain,
    "ConfigurationInertia": _configuration_inertia,
    "PositionLoop": _position_loop,
    "PositionLoop(filtered)": _position_loop_filtered,
    "VelocityLoop": _velocity_loop,
    "PeanoHasel": _peano_hasel,
    "Chamber": _hydraulic,
    "FlowSource": _hydraulic,
    "PressureTransducer": _hydraulic,
}
MODELS = sorted(set(CASES.values()), key=lambda f: f.__name__)


@functools.cache
def model(builder):
    """The system of a case and its numeric functions, built once per session."""
    name, comps, conns, params = builder()
    s = interconnect(name, comps, conns, params=params)
    pb = s.power_balance
    z = list(s.grad_H) + list(s.u)
    return {
        "system": s,
        "f": generate(s),
        "J": s.lambdify(s.J),
        "D": s.lambdify(s.dissipation_matrix),
        "pb": s.lambdify([pb["dHdt"], pb["dissipated"], pb["supplied"]]),
        "z": s.lambdify(sp.Matrix(z)) if z else None,
        "parts": s.lambdify(list(s.dissipator_powers().values())) if s.dissipators else None,
    }


def _point(data, s):
    x = np.array([data.draw(st.floats(*st_.range), label=st_.name) for st_ in s.states])
    u = np.array([data.draw(st.floats(-1.0, 1.0), label=i.name) * _input_scale(i) for i in s.inputs])
    return x, u


def _input_scale(inp) -> float:
    return {"V": 100.0, "A": 1e-3, "N": 1.0, "N*m": 1e-2, "m**3/s": 1e-6}.get(inp.unit, 1.0)


def test_every_component_is_covered():
    classes = {c for n in components.__all__ if inspect.isclass(c := getattr(components, n))
               and issubclass(c, Component)}
    used = {type(c) for builder in MODELS for c in builder()[1]}
    assert classes - used == set(), "components without a law case"
    for name, builder in CASES.items():
        assert name.split("(")[0] in {type(c).__name__ for c in builder()[1]}, name


@pytest.mark.parametrize("builder", MODELS, ids=lambda f: f.__name__.strip("_"))
@POINTS
@given(data=st.data())
def test_laws_at_random_points(builder, data):
    m = model(builder)
    s, f = m["system"], m["f"]
    x, u = _point(data, s)
    p = s.param_vector()

    J = np.atleast_2d(np.asarray(m["J"](x, u, p), dtype=float))
    D = np.atleast_2d(np.asarray(m["D"](x, u, p), dtype=float))
    assert np.all(np.isfinite(J)) and np.all(np.isfinite(D))
    assert np.max(np.abs(J + J.T), initial=0.0) <= 1e-14 * max(1.0, np.max(np.abs(J), initial=0.0))
    assert np.max(np.abs(D - D.T), initial=0.0) <= 1e-14 * max(1e-300, np.max(np.abs(D), initial=0.0))
    ev = np.linalg.eigvalsh(D) if D.size else np.zeros(1)
    assert ev[0] >= -PSD_TOL * max(np.max(np.abs(ev)), 1e-300), f"[[R, P], [P^T, S]] eigenvalues {ev}"

    dH = np.asarray(f.grad_hamiltonian(x, u, p), dtype=float).reshape(-1)
    xdot = np.asarray(f.rhs(x, u, p), dtype=float).reshape(-1)
    summands = float(np.sum(np.abs(dH * xdot)))
    cas = [float(v) for v in f.power_balance(x, u, p)]
    sym = [float(v) for v in m["pb"](x, u, p)]
    for dHdt, dissipated, supplied in (cas, sym):
        scale = max(abs(dHdt) + abs(dissipated) + abs(supplied) + summands, 1e-280)
        assert abs(dHdt - (supplied - dissipated)) <= BALANCE_TOL * scale, (dHdt, supplied, dissipated)

    # dissipators: per-element powers sum to the quadratic form (CasADi and sympy)
    labels = [label for label, _ in s.dissipators]
    assert len(labels) == len(set(labels))
    zz = np.asarray(m["z"](x, u, p), dtype=float).reshape(-1)
    # (scales floored at 1e-280: products of hypothesis' tiny draws fall into the subnormal range,
    # where doubles lose their relative precision)
    form_scale = max(float(np.abs(zz) @ np.abs(D) @ np.abs(zz)), 1e-280)
    parts_cas = np.asarray(f.dissipators(x, u, p), dtype=float).reshape(-1)
    parts_sym = np.asarray(m["parts"](x, u, p), dtype=float).reshape(-1)
    assert len(parts_cas) == len(parts_sym) == len(labels) >= 1
    for parts, total in ((parts_cas, cas[1]), (parts_sym, sym[1])):
        assert np.all(parts >= -DISSIPATOR_TOL * form_scale), dict(zip(labels, parts))
        assert abs(parts.sum() - total) <= DISSIPATOR_TOL * form_scale, (parts, total)


@pytest.mark.parametrize("builder", MODELS, ids=lambda f: f.__name__.strip("_"))
def test_energy_terms_are_in_joules(builder):
    """Each component declares units that make its stored energy come out in joules."""
    s = model(builder)["system"]
    assert unit_problems(s) == []


@pytest.mark.parametrize("builder", MODELS, ids=lambda f: f.__name__.strip("_"))
def test_structure_units_agree(builder):
    """Each component's J, R, G, P, S, N, ports and measured outputs agree with its states' and ports' units."""
    assert structure_unit_problems(model(builder)["system"])[0] == []
