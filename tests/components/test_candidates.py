"""Candidate physics keep a model port-Hamiltonian and change it as their docstrings say.

Every candidate attached at every place it fits on three host models (the electrostatic actuator:
mass, spring, capacitor, source with series resistor; the mass-spring-damper; the RLC circuit):

* at seeded hypothesis points, J is skew, [[R, P], [P^T, S]] symmetric PSD, the power balance
  dH/dt = y^T u - z^T D z holds for the generated functions, and the per-element dissipated powers
  (including the candidate's own element) add up to the total;
* the structural checks (symbolic where decidable) pass and every energy term is in joules;
* each candidate's defining relation holds in numbers (independent computations below).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen import generate, simulate
from components.candidates import (
    LIBRARY,
    AddedMass,
    ChargeRetention,
    CoulombFriction,
    Hysteresis,
    Scales,
    SeriesResistance,
    SlewRateLimit,
    TimeDelay,
)
from phs.checks import unit_problems
from phs.errors import ModelError
from systems.electrostatic_actuator import electrostatic_actuator
from systems.examples import mass_spring_damper, rlc_circuit

# tolerances: the laws are identities evaluated in double precision on sums of a few terms
# of very different magnitude (charges ~1e-8 C with voltages ~10 V next to forces ~1e-3 N)
PSD_TOL = 1e-9
BALANCE_TOL = 1e-9

HOSTS = {"electrostatic": electrostatic_actuator, "msd": mass_spring_damper, "rlc": rlc_circuit}
CASES = [(h, c.effect, w) for h, f in HOSTS.items() for c in LIBRARY if c.kind != "input" for w in c.attach_points(f())]


@functools.cache
def augmented(host, effect, where):
    s = HOSTS[host]()
    cand = next(c for c in LIBRARY if c.effect == effect)
    aug = cand.augment(s, where, Scales.of(s))
    a = aug.system
    # move every new parameter away from its start so the candidate's term is not negligible
    a = a.with_params({k: a.param(k).value * 7.0 for k in aug.free})
    D = a.lambdify(a.dissipation_matrix)
    z = a.lambdify(sp.Matrix(list(a.grad_H) + list(a.u)))
    return aug, a, generate(a), D, z


def test_every_effect_attaches_somewhere():
    effects = {e for _, e, _ in CASES} | {c.effect for c in LIBRARY if c.kind == "input"}
    assert effects == {c.effect for c in LIBRARY}
    assert len(LIBRARY) == 13


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-{c[1]}@{c[2]}")
@settings(max_examples=15, deadline=None, derandomize=True)
@given(data=st.data())
def test_laws_hold_for_augmented_models(case, data):
    aug, s, f, D_of, z_of = augmented(*case)
    x = np.array([data.draw(st.floats(-1.0, 1.0)) * st_.typical for st_ in s.states])
    u = np.array([data.draw(st.floats(-1.0, 1.0)) * (5.0 if i.unit == "V" else 1.0) for i in s.inputs])
    p = s.param_vector()
    D = np.atleast_2d(np.asarray(D_of(x, u, p), float))
    ev = np.linalg.eigvalsh((D + D.T) / 2)
    assert ev[0] >= -PSD_TOL * max(abs(ev).max(), 1e-300), ev
    dHdt, dissipated, supplied = (float(v) for v in f.power_balance(x, u, p))
    dH = np.asarray(f.grad_hamiltonian(x, u, p), float).reshape(-1)
    xdot = np.asarray(f.rhs(x, u, p), float).reshape(-1)
    scale = abs(dHdt) + abs(dissipated) + abs(supplied) + float(np.abs(dH * xdot).sum()) + 1e-300
    assert abs(dHdt - (supplied - dissipated)) <= BALANCE_TOL * scale
    zz = np.asarray(z_of(x, u, p), float).reshape(-1)
    parts = np.asarray(f.dissipators(x, u, p), float).reshape(-1)
    form = max(float(np.abs(zz) @ np.abs(D) @ np.abs(zz)), 1e-300)
    assert abs(parts.sum() - dissipated) <= 1e-9 * form
    assert np.all(parts >= -1e-9 * form)


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c[0]}-{c[1]}@{c[2]}")
def test_structural_checks_pass(case):
    aug, s, *_ = augmented(*case)
    rep = s.check(samples=50)
    assert rep.ok, str(rep)
    assert unit_problems(s) == []
    assert set(aug.free) <= set(s.param_names)
    for k in aug.free:
        lo, hi = aug.bounds[k]
        assert lo < s.param(k).value / 7.0 < hi  # the start lies inside the declared bounds


def test_attach_to_unknown_place_names_it():
    with pytest.raises(ModelError, match="coulomb_friction.*'Q'"):
        CoulombFriction().augment(electrostatic_actuator(), "Q", Scales.of(electrostatic_actuator()))


def test_coulomb_friction_force_is_bounded_by_F_c():
    s = mass_spring_damper()
    a = CoulombFriction().augment(s, "m.p", Scales.of(s)).system.with_params({"coulomb_friction.F_c": 0.3})
    i = a.state_names.index("m.p")
    f = generate(a)
    for v in (-5.0, -0.5, 0.5, 5.0):  # momentum p = m v with m = 1: force -F_c v/sqrt(v^2+v_s^2)
        x = np.zeros(len(a.states))
        x[i] = v * a.param("m.m").value if "m.m" in a.param_names else v
        xd_aug = np.asarray(f.rhs(x, [0.0] * len(a.inputs), a.param_vector()), float).reshape(-1)
        xd = np.asarray(generate(s).rhs(x, [0.0] * len(s.inputs), s.param_vector()), float).reshape(-1)
        extra = xd_aug[i] - xd[i]
        assert -0.3 <= -np.sign(v) * extra <= 0.3 * (1 + 1e-12) and np.sign(extra) == -np.sign(v)


def test_added_mass_slows_the_oscillation_by_sqrt_one_plus_mu():
    s = mass_spring_damper().with_params({"b.b": 1e-9})
    a = AddedMass().augment(s, "m.p", Scales.of(s)).system.with_params({"added_mass.mu": 3.0})
    J = np.asarray(generate(a).jac_rhs(np.zeros(2), [0.0], a.param_vector())[0], float)
    J0 = np.asarray(generate(s).jac_rhs(np.zeros(2), [0.0], s.param_vector())[0], float)
    w, w0 = np.abs(np.linalg.eigvals(J)).max(), np.abs(np.linalg.eigvals(J0)).max()
    assert w == pytest.approx(w0 / 2.0, rel=1e-6)  # mass x 4 -> frequency / 2


@pytest.mark.parametrize("before", [CoulombFriction, Hysteresis])
def test_added_mass_after_a_velocity_element_is_a_heavier_body(before):
    """An added mass attached after a friction or a hysteresis (as a diagnosis's second round attaches it)
    gives the dynamics of the body with mass m (1 + mu) and that element: the element reads the body's new
    velocity.  (Reading p / m instead made mu a second knob on the friction's smoothing, which a second
    round took for an added mass.)"""
    s = mass_spring_damper(m=0.5)
    first = before().augment(s, "m.p", Scales.of(s)).system
    mu = 0.6
    both = AddedMass().augment(first, "m.p", Scales.of(first)).system.with_params({"added_mass.mu": mu})
    heavier = first.with_params({"m.m": 0.5 * (1 + mu)})
    f_both, f_heavier = generate(both), generate(heavier)
    rng = np.random.default_rng(0)
    for _ in range(20):  # the right-hand sides agree at any state (the same momentum p)
        x = rng.normal(size=len(both.states)) * np.array([0.3] + [0.05] * (len(both.states) - 1))
        a = np.asarray(f_both.rhs(x, [0.7], both.param_vector()), float).reshape(-1)
        b = np.asarray(f_heavier.rhs(x, [0.7], heavier.param_vector()), float).reshape(-1)
        assert a == pytest.approx(b, rel=1e-12, abs=1e-12)


def test_charge_retention_matches_the_drift_branch_model():
    """The congruence insertion equals building the RC branch with components (DriftBranch)."""
    from components import Capacitor, DriftBranch, Resistor, VoltageSource
    from phs import interconnect, series

    def net(extra):
        return interconnect("n", [VoltageSource("U"), Resistor("R0", R=1e3), Capacitor("C", C=1e-6), *extra],
                            [series("U", "R0", "C", *[e.name for e in extra])])

    nominal = net([])
    built = net([DriftBranch("D", C1=2e-6, R1=5e3)])
    aug = ChargeRetention().augment(nominal, "C.Q", Scales.of(nominal))
    a = aug.system.with_params({"charge_retention.C_r": 2e-6, "charge_retention.tau": 5e3 * 2e-6})
    t = np.linspace(0, 0.05, 501)
    u = {"U": np.where(t > 0.005, 1.0, 0.0)}
    r1, r2 = simulate(built, t, u=u, rtol=1e-10), simulate(a, t, u=u, rtol=1e-10)
    assert np.max(np.abs(r1["U.i"] - r2["U.i"])) <= 1e-6 * np.max(np.abs(r1["U.i"]))
    assert np.max(np.abs(r1["C.Q"] - r2["C.Q"])) <= 1e-6 * np.max(np.abs(r1["C.Q"]))


def test_series_resistance_adds_to_the_source_resistor():
    s = electrostatic_actuator()
    a = SeriesResistance().augment(s, "U", Scales.of(s)).system.with_params({"series_resistance.R_a": 3e4})
    t = np.linspace(0, 0.02, 401)
    u = {"U": np.where(t > 0.001, 10.0, 0.0)}
    r1 = simulate(a, t, u=u)
    r2 = simulate(s.with_params({"R_s": 4e4}), t, u=u)
    for ch in ("position", "current"):
        assert np.max(np.abs(r1[ch] - r2[ch])) <= 1e-5 * np.max(np.abs(r2[ch]))


def test_hysteresis_loop_is_rate_independent():
    """Bouc-Wen/Dahl: force vs displacement traced at two speeds gives the same loop, saturating at
    F_h / (1 + eta) while loading."""
    s = mass_spring_damper()
    a = Hysteresis().augment(s, "m.p", Scales.of(s)).system
    zi = a.state_names.index("hysteresis.z")
    f = generate(a)
    p = a.param_vector()
    kh, Fh, eta = (a.param(f"hysteresis.{k}").value for k in ("k_h", "F_h", "eta"))

    def loop(speed):  # drive the element's displacement directly: dz/dt from the rhs at velocity v
        z, out = 0.0, []
        for v in np.r_[np.full(400, speed), np.full(800, -speed), np.full(400, speed)]:
            x = np.zeros(len(a.states))
            x[a.state_names.index("m.p")] = v  # m = 1
            x[zi] = z
            dz = float(np.asarray(f.rhs(x, [0.0], p)).reshape(-1)[zi])
            z += dz * (1e-3 / speed)
            out.append(kh * z)
        return np.array(out)

    slow, fast = loop(1.0), loop(4.0)
    assert np.max(np.abs(slow - fast)) <= 0.02 * Fh
    # |v| and |z| are smoothed with a small epsilon: the bound holds to 1e-3 relative
    assert np.max(np.abs(slow)) <= Fh / (1 + eta) * (1 + 1e-3)
    assert np.max(np.abs(slow)) >= 0.95 * Fh / (1 + eta)  # the loop reaches saturation


def test_input_elements_transform_as_documented():
    t = np.arange(0, 1, 1e-3)
    u = np.where(t > 0.2, 10.0, 0.0)
    d = TimeDelay().transform(t, u, [0.05])
    assert d[np.searchsorted(t, 0.249)] == 0.0 and d[np.searchsorted(t, 0.252)] == 10.0
    r = SlewRateLimit().transform(t, u, [100.0])
    assert np.max(np.abs(np.diff(r))) <= 100.0 * 1e-3 * (1 + 1e-12)
    assert r[-1] == 10.0


@pytest.mark.parametrize("make", ["curling_hasel2", "msd_hasel"])
def test_series_resistance_is_the_source_seen_through_the_resistor(make):
    """The series resistor's model against the one it extends with its input solved by hand: the source
    ``u`` drives the model through ``R_a``, so the model sees ``v = u − R_a y`` with ``y = c·∇H + d v``
    (``v = (u − R_a c·∇H)/(1 + R_a d)``); with a feedthrough ``d`` (the curling HASEL's) and without one
    (the MSD HASEL's), at random states, to 1e-9 of the rates' size."""
    from systems.curling_hasel import curling_hasel
    from systems.msd_hasel import msd_hasel

    s = curling_hasel(2) if make == "curling_hasel2" else msd_hasel()
    where = SeriesResistance().attach_points(s)[0]
    j = s.input_names.index(where)
    a = SeriesResistance().augment(s, where, Scales.of(s)).system
    Ra = 50 * a.param("series_resistance.R_a").value  # 50 times its start: the resistor matters
    a = a.with_params({"series_resistance.R_a": Ra})

    def parts(sysm):
        f = {k: sysm.lambdify(getattr(sysm, k), with_u=False) for k in ("J", "R", "G", "P", "S", "N", "grad_H")}
        return lambda x: {k: np.asarray(g(x, sysm.param_vector()), float).reshape(getattr(sysm, k).shape) for k, g in f.items()}

    ps, pa = parts(s), parts(a)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = np.array([rng.uniform(0.1, 0.6) * st.typical if st.range is None else  # inside every declared range
                      st.range[0] + rng.uniform(0.2, 0.8) * (st.range[1] - st.range[0]) for st in s.states])
        u = rng.uniform(-1, 1, len(s.inputs)) * 100.0
        m, n = pa(x), ps(x)
        gh = n["grad_H"].reshape(-1)
        c, d = (n["G"] + n["P"])[:, j], (n["S"] + n["N"])[j, :]
        v = u.copy()
        v[j] = (u[j] - Ra * (c @ gh + d @ u - d[j] * u[j])) / (1 + Ra * d[j])
        want = (n["J"] - n["R"]) @ gh + (n["G"] - n["P"]) @ v
        got = (m["J"] - m["R"]) @ m["grad_H"].reshape(-1) + (m["G"] - m["P"]) @ u
        assert np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want))), (got, want)
