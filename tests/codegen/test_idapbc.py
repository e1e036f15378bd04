"""IDA-PBC design (codegen.idapbc): equilibrium assignment, matching, law, certificates, closed loop, C export.

Tolerances (each stated where used):
* matching residual 1e-8 of the largest scaled rate: the law cancels the plant's rates exactly, so the residual
  is rounding (1e-16..1e-14 measured); 1e-8 leaves room for the ill-scaled electrical rows of the HASEL.
* H_d non-increasing: the largest increase between samples must stay below 1e-8 of the initial H_d - H_d*
  (CVODES at rtol 1e-9 and the quadrature of Phi measured ~1e-14 relative).
* regulation "within 1 %" is the issue's requirement.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen.idapbc import design
from phs import EquilibriumError, InputDataError, Measured, Param, PHSystem, StateInfo
from phs.params import InputInfo
from systems.curling_hasel import curling_hasel
from systems.electrostatic_actuator import electrostatic_actuator
from systems.examples import mass_spring_damper
from systems.msd_hasel import msd_hasel

N = 4
REST = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}  # the curling HASEL at rest (theta = 0, l_p = L_v)
TIP = 0.03  # 30 mm: inside the documented operating range (46 mm at 5 kV without drift)


@pytest.fixture(scope="module")
def hasel():
    return curling_hasel(N)


@pytest.fixture(scope="module")
def hasel_ctrl(hasel):
    # the controller is designed on the model with the charge-retention capacitor shorted (its slow charge is
    # a disturbance for the design: keeping it makes R_d indefinite, see test_drift_in_the_design_model_...)
    return design(hasel, {"tip": TIP}, x0=REST, neglect=["seg*.Q1"])


@pytest.fixture(scope="module")
def msd():
    return msd_hasel(fit_length="mm")  # the numbers of docs/workflows/idapbc.md


@pytest.fixture(scope="module")
def hasel_certs(hasel_ctrl):
    return hasel_ctrl.certify(rays=16, simulations=4)


# -- curling HASEL ------------------------------------------------------------------------------------------------
def test_curling_hasel_assigned_equilibrium_holds_the_tip(hasel_ctrl):
    c = hasel_ctrl
    assert c.system.state_names == [f"seg{i}.{s}" for i in range(1, N + 1) for s in ("theta", "l_p", "p", "Q2")]
    assert c.assignment.achieved["tip"] == pytest.approx(TIP, rel=1e-12)
    assert 1500.0 < c.u_star[0] < 3000.0  # between the 2 kV (27 mm) and 3 kV (37 mm) equilibria
    assert c.structure.kind == "electromechanical"
    # the input map gamma1 cos(gamma2 theta) turns with the angle: one momentum-charge coupling per segment
    assert c.structure.coupling == [(f"seg{i}.p", f"seg{i}.Q2") for i in range(1, N + 1)]
    np.testing.assert_allclose(c.law(c.x_star), c.u_star, rtol=1e-12)


def test_curling_hasel_certificates_pass_with_numbers(hasel_certs):
    rep = hasel_certs
    assert rep.passed, rep.text()
    names = [c.name for c in rep.items]
    assert names == ["matching", "interconnection", "dissipation", "conserved", "equilibrium", "hessian",
                     "integrability", "linearization", "region", "simulations"]
    assert rep["matching"].numbers["relative_residual"] <= 1e-8
    assert rep["conserved"].numbers["count"] == N  # one conserved quantity per segment (l_p tied to theta)
    assert min(rep["hessian"].numbers["eigenvalues"]) > 0
    assert rep["linearization"].numbers["max_real"] < 0
    assert rep["region"].numbers["c"] > 0
    assert "input map" in rep["region"].numbers["limit"]  # the sublevel set ends at the input map's zero
    assert rep["dissipation"].numbers["min_scaled_eigenvalue_on_leaf"] > 0.9


def test_curling_hasel_regulates_tip_within_1_percent_in_2_s(hasel_ctrl):
    res = hasel_ctrl.simulate(np.linspace(0.0, 2.0, 2001))  # from rest, plant = the design model
    assert res.settling_time(0.01) <= 2.0
    assert abs(res.error()[-1]) < 1e-3
    assert res.H_d[0] > 0 and abs(res.H_d[-1]) < 1e-6 * res.H_d[0]
    assert res.max_increase("H_d") <= 1e-8 * res.H_d[0]


def test_curling_hasel_mismatch_and_drift_integral_action(hasel, hasel_ctrl):
    """10 % stiffer bottom film and the drift branch active: the plain law leaves a steady-state error, passive
    integral action removes the drift's share of it, integral action on the tip removes all of it."""
    t = np.linspace(0.0, 150.0, 1501)  # the drift settles with a time constant of about 15 s
    plant = {"plant": hasel, "params": {"K_b": 0.044}}
    plain = hasel_ctrl.simulate(t, **plant)
    passive = hasel_ctrl.with_integral("passive").simulate(t, **plant)
    output = hasel_ctrl.with_integral("output").simulate(t, **plant)
    e_plain, e_passive, e_output = (abs(r.error()[-1]) for r in (plain, passive, output))
    assert e_plain > 0.3  # the retained charge lowers the electrode voltage: the tip falls by ~48 %
    assert e_output < 1e-4  # the integral of the tip error removes it
    assert np.max(np.abs(output.error()[t >= 100])) < 1e-3  # and it has settled
    # passive integral action restores the electrode voltage exactly: what remains is the K_b mismatch, i.e.
    # the equilibrium of the drift-free model at u* with K_b = 0.044 (computed independently)
    from phs import equilibrium

    eq = equilibrium(hasel_ctrl.system, u={"U": float(hasel_ctrl.u_star[0])}, x0=REST, params={"K_b": 0.044})
    tip = hasel_ctrl.system.lambdify(hasel_ctrl.system.measured_expressions[0])
    tip_kb = float(tip(eq.x, hasel_ctrl.u_star, hasel_ctrl.system.param_vector({"K_b": 0.044})))
    assert passive["tip"][-1] == pytest.approx(tip_kb, rel=1e-5)
    assert e_passive < e_plain / 10
    for r in (plain, passive, output):
        assert not any(v["exceeded"] for v in r.info["input_ranges"].values())


def test_drift_in_the_design_model_makes_R_d_indefinite(hasel):
    """Keeping the retention capacitor in the design: the coupling it needs (1/2 C1 mu* |m'|) exceeds what the
    rotational damping allows, and the dissipation certificate says so (no crash)."""
    c = design(hasel, {"tip": TIP}, x0=REST)
    rep = c.certify(rays=4, simulations=1)
    assert not rep.passed
    assert rep["dissipation"].verdict == "fail"
    assert rep["dissipation"].numbers["min_scaled_eigenvalue_on_leaf"] < -1
    assert rep["matching"].passed and rep["interconnection"].passed


def test_unreachable_tip_is_reported(hasel):
    with pytest.raises(EquilibriumError, match=r"needs U beyond its range \[-10000, 10000\] V \(more than the maximum U\)"):
        design(hasel, {"tip": 0.08}, x0=REST, neglect=["seg*.Q1"])


def test_c_export_compiles_and_matches(hasel_ctrl, tmp_path):
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not available")
    ctrl = hasel_ctrl.with_integral("passive")
    c_file, h_file = ctrl.export_c(tmp_path / "out")
    x = ctrl.x_star + 0.01 * ctrl.num.scale * np.arange(len(ctrl.x_star))
    xi = 0.3
    main = tmp_path / "main.c"
    main.write_text(f"""#include <stdio.h>
#include <stdlib.h>
#include "{os.path.basename(h_file)}"
int main(void) {{
  casadi_real x[] = {{{", ".join(repr(float(v)) for v in x)}}}, xi[] = {{{xi!r}}}, u[1];
  casadi_int n_arg, n_res, n_iw, n_w;
  {ctrl.name}_law_work(&n_arg, &n_res, &n_iw, &n_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * (n_arg + 2));
  casadi_real** res = malloc(sizeof(casadi_real*) * (n_res + 1));
  casadi_int* iw = malloc(sizeof(casadi_int) * (n_iw + 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (n_w + 1));
  arg[0] = x; arg[1] = xi; res[0] = u;
  if ({ctrl.name}_law(arg, res, iw, w, 0)) return 1;
  printf("%.17g\\n", u[0]);
  return 0;
}}
""")
    exe = tmp_path / "law"
    proc = subprocess.run([gcc, "-std=c99", "-O2", "-I", str(tmp_path / "out"), str(main), c_file, "-o", str(exe), "-lm"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    # same arithmetic up to the compiler's reassociation at -O2
    assert float(out) == pytest.approx(float(ctrl.law(x, [xi])[0]), rel=1e-12)
    assert "seg1.theta [rad]" in open(h_file).read()


# -- MSD HASEL ----------------------------------------------------------------------------------------------------
def test_msd_hasel_regulates_stack_height(msd):
    s = msd
    ctrl = design(s, {"displacement": 0.5e-3}, inputs=["V"], stiffness={"x": 2000.0}, damping={"p": 20.0})
    assert ctrl.structure.kind == "ansatz" and ctrl.input_names == ["V"]
    assert ctrl.u_star[0] == pytest.approx(938.6, rel=1e-3)  # the open-loop static curve (docs/systems/msd_hasel.md)
    rep = ctrl.certify(rays=16, simulations=4)
    assert rep.passed, rep.text()
    # the added stiffness is exactly the curvature asked for
    assert ctrl.structure.coefficients["(x - *)^2/2"] == pytest.approx(2000.0, rel=1e-12)
    from phs import equilibrium

    rest = equilibrium(s, u={"V": 0.0}, x0={"x": 0.0})  # the loaded actuator at rest without voltage
    res = ctrl.simulate(np.linspace(0.0, 0.3, 601), x0=rest.as_dict())
    assert res.settling_time(0.01) < 0.1
    assert abs(res.error()[-1]) < 1e-6
    assert res.max_increase("H_d") <= 1e-8 * res.H_d[0]
    assert not res.info["input_ranges"]["V"]["exceeded"]  # 0 V <= V <= 6 kV throughout


def test_msd_hasel_target_beyond_the_maximum_voltage(msd):
    with pytest.raises(EquilibriumError, match="more than the maximum V"):
        design(msd, {"displacement": 1.0e-3}, inputs=["V"])


# -- linear mass-spring: the closed-form law ----------------------------------------------------------------------
def closed_form(m, k, q_star, k_a, r):
    """Energy shaping + damping injection: H_d = p^2/2m + (k + k_a)(q - q*)^2/2, R_d = R + r on p."""
    q, p = sp.Symbol("k.l", real=True), sp.Symbol("m.p", real=True)
    return k * q_star - k_a * (q - q_star) - r * p / m, q, p


def test_linear_mass_spring_matches_closed_form_law():
    m, k, b, q_star, k_a, r = 1.0, 4.0, 0.4, 0.5, 6.0, 2.0
    ctrl = design(mass_spring_damper(m=m, k=k, b=b), {"position": q_star}, stiffness={"k.l": k_a}, damping=r)
    law = ctrl.law_expression()[0]
    ref, q, p = closed_form(m, k, q_star, k_a, r)
    diff = sp.expand(law - ref)
    assert all(abs(float(cf)) < 1e-12 for cf in sp.Poly(diff, q, p).coeffs()), diff
    assert ctrl.structure.symbolic  # matching solved by coefficient equations, not sampled
    rep = ctrl.certify(rays=8, simulations=2)
    assert rep.passed
    # closed loop: s^2 m + (b + r) s + (k + k_a) = 0
    ev = np.sort_complex(np.array(rep["linearization"].numbers["eigenvalues"]))
    np.testing.assert_allclose(ev, np.sort_complex(np.roots([m, b + r, k + k_a])), rtol=1e-10)


@settings(max_examples=8, deadline=None)
@given(m=st.floats(0.1, 10), k=st.floats(0.5, 50), b=st.floats(0.01, 2.0), q_star=st.floats(-1.0, 1.0),
       k_a=st.floats(0.0, 50.0), r=st.floats(0.0, 10.0))
def test_mass_spring_law_is_the_closed_form_for_any_gains(m, k, b, q_star, k_a, r):
    ctrl = design(mass_spring_damper(m=m, k=k, b=b), {"position": q_star}, stiffness={"k.l": k_a}, damping=r)
    rng = np.random.default_rng(0)
    ref, q, p = closed_form(m, k, q_star, k_a, r)
    f = sp.lambdify([p, q], ref)
    for x in rng.uniform(-2, 2, (5, 2)):
        assert ctrl.law(x)[0] == pytest.approx(f(*x), rel=1e-9, abs=1e-9 * (k + k_a + r))
    # J_d stays skew and R_d PSD whatever the gains (structural law of the design)
    Jd, Rd = ctrl.J_d, ctrl.R_d
    assert (Jd + Jd.T).is_zero_matrix
    assert min(np.linalg.eigvalsh(np.array(Rd, dtype=float))) >= 0


# -- reported, not crashed ----------------------------------------------------------------------------------------
def test_non_positive_definite_hessian_is_reported():
    """Beyond pull-in (x* > g0/3) holding the voltage is unstable: the certificates say so; shaping the charge
    (matched: the one input drives the one charge) makes x* a strict minimum."""
    e = electrostatic_actuator()
    voltage = design(e, {"position": 5e-5})
    rep = voltage.certify(rays=8, simulations=2)
    assert rep["hessian"].verdict == "fail" and min(rep["hessian"].numbers["eigenvalues"]) < 0
    assert rep["linearization"].verdict == "fail" and "UNSTABLE" in rep["linearization"].summary
    assert not rep.passed
    charge = design(e, {"position": 5e-5}, stiffness={"Q": 1e12})
    assert charge.certify(rays=8, simulations=2).passed
    negative = design(mass_spring_damper(), {"position": 0.5}, stiffness={"k.l": -6.0})  # k + k_a = -2
    rep = negative.certify(rays=4, simulations=1)
    assert rep["hessian"].verdict == "fail" and "NOT positive definite" in rep["hessian"].summary


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"target": {"nope": 1.0}}, InputDataError, "no state or measured output"),
    ({"target": {"position": 0.5, "k.l": 0.5}}, InputDataError, "2 target"),
    ({"target": {"position": float("nan")}}, InputDataError, "not finite"),
    ({"target": {"position": 0.5}, "inputs": ["G"]}, InputDataError, "no input 'G'"),
    ({"target": {"position": 0.5}, "damping": -1.0}, InputDataError, "damping"),
    ({"target": {"position": 0.5}, "stiffness": {"m.p": 3.0}}, InputDataError, "'m.p' is not compatible"),
    ({"target": {"position": 0.5}, "structure": "electromechanical"}, InputDataError, "does not apply"),
    ({"target": {"position": 0.5}, "integral": "sometimes"}, InputDataError, "integral"),
])
def test_invalid_design_inputs_name_the_culprit(kwargs, error, match):
    kw = dict(kwargs)
    target = kw.pop("target")
    with pytest.raises(error, match=match):
        design(mass_spring_damper(), target, **kw)


def test_hasel_input_errors(hasel):
    with pytest.raises(InputDataError, match="outside the validity domain"):
        design(hasel, {"tip": TIP}, x0={k: 0.0145 for k in REST}, neglect=["seg*.Q1"])  # l_p below the chord
    with pytest.raises(InputDataError, match="not matched"):
        design(hasel, {"tip": TIP}, x0=REST, neglect=["seg*.Q1"], stiffness={"seg1.Q2": 1e9})
    with pytest.raises(InputDataError, match="no state matches 'seg\\*.Q3'"):
        design(hasel, {"tip": TIP}, x0=REST, neglect=["seg*.Q3"])


def test_passive_integral_needs_a_static_response():
    ctrl = design(mass_spring_damper(), {"position": 0.5}, damping=1.0)
    with pytest.raises(InputDataError, match="passive output does not respond statically"):
        ctrl.with_integral("passive")  # y_d = velocity: zero at every rest point
    assert ctrl.with_integral("passive", gain=2.0).K_i[0, 0] == 2.0


# -- sympy's PDE solver for a scalar first-order case ---------------------------------------------------------------
def _transmission_actuator():
    """A shell with a constant transmission l' = c theta' (a conserved quantity l - c theta), a gap capacitor
    C0 (1 + theta) and a voltage input through R with the input map cos(theta)."""
    P = {a[0]: Param(*a) for a in [("k", 0.05, "N*m/rad"), ("K", 20.0, "N/m"), ("L", 0.015, "m"),
                                   ("I", 1e-5, "kg*m**2"), ("b", 3e-3, "N*m*s/rad"), ("c", 0.01, "m/rad"),
                                   ("C0", 1e-9, "F"), ("R", 1e3, "Ohm")]}
    S = {k: v.symbol for k, v in P.items()}
    th, l, p, Q = (sp.Symbol(n, real=True) for n in ("theta", "l", "p", "Q"))  # noqa: E741
    H = S["k"] * th**2 / 2 + S["K"] * (l - S["L"]) ** 2 / 2 + p**2 / (2 * S["I"]) + Q**2 / (2 * S["C0"] * (1 + th))
    J = sp.Matrix([[0, 0, 1, 0], [0, 0, S["c"], 0], [-1, -S["c"], 0, 0], [0, 0, 0, 0]])
    R = sp.diag(0, 0, S["b"], 1 / S["R"])
    G = sp.Matrix([0, 0, 0, sp.cos(th) / S["R"]])
    states = [StateInfo("theta", "rad", (-0.5, 0.5), scale=0.2), StateInfo("l", "m", (0.01, 0.02), scale=0.015),
              StateInfo("p", "kg*m**2/s", (-1e-3, 1e-3), scale=1e-5, kind="I"), StateInfo("Q", "C", (-1e-5, 1e-5), scale=1e-6)]
    return PHSystem("transmission", states, H, J, R, G, inputs=[InputInfo("U", "V", output="U.i", range=(-1e4, 1e4))],
                    params=list(P.values()), measured=[Measured("angle", th, "rad")])


def test_scalar_first_order_pde_solved_by_pdsolve():
    ctrl = design(_transmission_actuator(), {"angle": 0.1}, x0={"l": 0.015})
    assert ctrl.structure.kind == "electromechanical" and not ctrl.phi_implicit
    pde = next(p for p in ctrl.structure.pdes if p["variables"] == ["theta", "l"])
    assert pde["method"] == "sympy pdsolve"
    # Phi solves dPhi/dtheta + c dPhi/dl = v_theta: the law keeps the mechanical rows of the plant exactly
    rep = ctrl.certify(rays=8, simulations=2)
    assert rep.passed, rep.text()
    assert "integrability" not in [c.name for c in rep.items]  # H_d is explicit
    res = ctrl.simulate(np.linspace(0, 1.0, 501))
    assert abs(res.error()[-1]) < 1e-6 and res.max_increase("H_d") <= 1e-8 * res.H_d[0]


# -- your own structure: solved where it can be, reported where it cannot -------------------------------------------
def test_user_ansatz_coefficients_are_solved():
    s = mass_spring_damper()
    q, p = s.x[1], s.x[0]  # states: m.p, k.l
    c1, c2, c3 = sp.symbols("c1 c2 c3", real=True)
    # H_a = c1 (q - q*) + c2 (q - q*)^2 / 2 + c3 q p: the q row (q' = p/m) forbids any p in H_a, so c3 = 0,
    # and x* = 0.5 a critical point fixes c1 = -k q* = -2; c2 is free and set to zero
    ctrl = design(s, {"position": 0.5}, H_a=c1 * (q - 0.5) + c2 * (q - 0.5) ** 2 / 2 + c3 * q * p, unknowns=[c1, c2, c3])
    Ha = ctrl.structure.H_a
    assert not ctrl.structure.unsolved and ctrl.structure.symbolic
    assert float(Ha.coeff(q)) == pytest.approx(-2.0) and Ha.coeff(q * p) == 0
    assert ctrl.certify(rays=4, simulations=1).passed


def test_unmatched_interconnection_is_reported_as_unsolved():
    s = mass_spring_damper()
    q = s.x[1]
    J_a = sp.zeros(2, 2)
    # q' = (1 + q/2) dH_d/dp must equal p/m: the kinetic energy of H_d would have to be p**2 / (2 m (1 + q/2)),
    # which no quadratic H_a gives
    J_a[1, 0], J_a[0, 1] = q / 2, -q / 2
    ctrl = design(s, {"position": 0.5}, J_a=J_a)
    assert ctrl.structure.unsolved and "no solution in this ansatz" in ctrl.structure.unsolved[0]
    rep = ctrl.certify(rays=4, simulations=1)
    assert rep["matching"].verdict == "fail" and "unsolved" in rep["matching"].summary
    assert "unsolved" in ctrl.summary()


def test_target_on_a_segment_angle(hasel):
    ctrl = design(hasel, {"seg4.theta": 0.1}, x0=REST, neglect=["seg*.Q1"])
    assert ctrl.assignment.achieved["seg4.theta"] == pytest.approx(0.1, rel=1e-12)
    res = ctrl.simulate(np.linspace(0, 1.0, 201))
    assert abs(res["seg4.theta"][-1] - 0.1) < 1e-6


def test_saturated_inputs_stay_in_range(msd):
    ctrl = design(msd, {"displacement": 0.5e-3}, inputs=["V"], stiffness={"x": 5000.0}, damping={"p": 30.0})
    t = np.linspace(0.0, 0.3, 601)
    free = ctrl.simulate(t, x0={"x": 0.0})
    assert free.info["input_ranges"]["V"]["exceeded"] and free["V"].min() < 0  # the law asks for a negative voltage
    clipped = ctrl.simulate(t, x0={"x": 0.0}, saturate=True)
    assert not clipped.info["input_ranges"]["V"]["exceeded"] and clipped["V"].min() >= 0.0
    assert abs(clipped.error()[-1]) < 1e-6
