"""Passivity certificates (codegen.passivity).

Proofs of the certificate, each checked against an independent computation:

* the three seed systems (4-segment curling HASEL, MSD HASEL, 4-shell manta-ray fin) are certified passive
  at their default parameters over their declared (physical) state ranges;
* a negative resistor and a user-supplied R that loses definiteness in part of the state box are detected,
  and the reported worst point lies where R has a negative eigenvalue by numpy's ``eigvalsh`` of the
  sympy-lambdified matrix;
* the dissipation inequality along a simulated curling HASEL trajectory holds, and the per-element split
  of the dissipated energy sums to the total to 1e-6 relative;
* the local passivity indices of linear RLC, RC, RC-with-leak and mass-spring-damper models equal their
  closed forms (input index ``inf Re Y(jω)``, output index ``inf Re Z(jω)``);
* invalid specifications (a box with lower > upper bound, an unknown name, an equilibrium that is not
  one) raise the project's errors naming the culprit.

Reduced sizes: the seed systems are certified with 400 sample points and 3 ``nlpsol`` starts instead of
2000 and 8.  That suffices for the proof because their dissipation matrices are proved PSD symbolically
(principal minors, or per-element forms for the curling HASEL) and the margin they report comes from the
state block R, which is constant for all three (the numerical search only confirms it); the storage
minimum is a smooth interior minimum (springs at rest, charges and momenta zero) that IPOPT reaches from
any start, and ``test_reduced_settings_agree_with_defaults`` (slow) checks that the defaults give the same
numbers.
"""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen import simulate
from codegen.passivity import (
    EIGENVALUE_TOL,
    PassivityReport,
    certify,
    dissipation_inequality,
    dissipation_margin,
    local_passivity,
)
from phs import EquilibriumError, InputDataError, InputInfo, Param, ParameterError, PHSystem, StateInfo
from phs.signals import square
from systems.examples import rc_circuit

QUICK = {"samples": 400, "starts": 3}


# -- models built here -----------------------------------------------------------------------------------
def fitted_damper(vc: float = 0.8):
    """A mass on a spring with a damper law fitted on |v| <= 0.5 m/s: b(v) = b0 (1 - (v / v_c)^2).

    Passive over the declared momentum range (|v| <= 0.5 m/s), active (negative damping) for |v| > v_c.
    """
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    m, k, b0, v_c = (Param("m", 0.1, "kg", "mass"), Param("k", 40.0, "N/m", "stiffness"),
                     Param("b0", 0.05, "N*s/m", "damping at rest"), Param("v_c", vc, "m/s", "velocity of zero damping"))
    b = b0.symbol * (1 - (p / m.symbol / v_c.symbol) ** 2)
    return PHSystem("fitted_damper", [StateInfo("q", "m", (-0.05, 0.05)), StateInfo("p", "kg*m/s", (-0.05, 0.05), kind="I")],
                    H=k.symbol * q**2 / 2 + p**2 / (2 * m.symbol), J=[[0, 1], [-1, 0]], R=[[0, 0], [0, b]], G=[[0], [1]],
                    inputs=[InputInfo("F", "N", output="F.v", output_unit="m/s")], params=[m, k, b0, v_c],
                    dissipators=[("damper", {(1, 1): b})])


def coupled_losses():
    """Two states with a coupled dissipation matrix [[a, c x], [c x, a]]: indefinite where |c x| > a."""
    x, y = sp.Symbol("x", real=True), sp.Symbol("y", real=True)
    a, c = Param("a", 1.0, "1", "diagonal loss"), Param("c", 2.0, "1", "coupling gain")
    R = sp.Matrix([[a.symbol, c.symbol * x], [c.symbol * x, a.symbol]])
    return PHSystem("coupled", [StateInfo("x", "1", (-0.4, 0.4)), StateInfo("y", "1", (-1.0, 1.0))],
                    H=(x**2 + y**2) / 2, J=[[0, 1], [-1, 0]], R=R, G=[[1], [0]], inputs=["u"], params=[a, c])


def rc_leak(R=100.0, R2=900.0, C=1e-4):
    """Voltage source -> R -> (C || R2): admittance with input index 1/(R + R2) and output index R."""
    from components import DriftBranch, Resistor, VoltageSource
    from phs import interconnect, series

    return interconnect("rc_leak", [VoltageSource("U"), Resistor("R", R=R), DriftBranch("D", C1=C, R1=R2)],
                        [series("U", "R", "D")])


def _eig_min_at(system, point, params=None):
    """Independent check: numpy's smallest eigenvalue of the sympy-lambdified [[R, P], [P^T, S]] at a point."""
    x = [point[n] for n in system.state_names]
    p = system.param_vector(params, signs=False)  # the what-if values the certificate was given
    D = np.asarray(system.lambdify(system.dissipation_matrix)(x, [0.0] * len(system.inputs), p), dtype=float)
    return float(np.linalg.eigvalsh(D)[0])


# -- seed systems ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def seeds():
    from systems.curling_hasel import curling_hasel
    from systems.manta_ray_fin import manta_ray_fin
    from systems.msd_hasel import msd_hasel

    return {"curling_hasel": curling_hasel(4), "msd_hasel": msd_hasel(), "manta_ray_fin": manta_ray_fin(4)}


@pytest.mark.parametrize("name", ["curling_hasel", "msd_hasel", "manta_ray_fin"])
def test_seed_systems_are_certified_passive_over_their_physical_ranges(seeds, name):
    system = seeds[name]
    report = certify(system, **QUICK)
    assert report.passive, report.text()
    for test in ("interconnection", "dissipation", "feedthrough", "storage"):
        assert report[test].verdict == "pass", report[test].line()
    diss = report["dissipation"]
    assert diss.numbers["symbolic"] == "proved"
    assert report.margin > 0
    assert diss.numbers["full_form_min_eigenvalue"] >= -EIGENVALUE_TOL
    assert diss.numbers["valid_samples"] == QUICK["samples"]
    # the box is the declared ranges and the tightest point of the full form lies in it
    for st_ in system.states:
        assert report.box[st_.name] == st_.range
        assert st_.range[0] <= diss.numbers["full_form_point"][st_.name] <= st_.range[1]
    assert diss.worst == {} and "R is constant over the box" in diss.summary  # R of the seeds has no state in it
    # independent check of the full form at the reported tightest point
    assert _eig_min_at(system, diss.numbers["full_form_point"]) >= -1e-12 * np.max(np.abs(system.param_vector()))
    storage = report["storage"]
    assert np.isfinite(storage.numbers["H_min"])
    H = float(system.lambdify(system.H)([storage.worst[n] for n in system.state_names], [0.0] * len(system.inputs)))
    # sympy/numpy and the generated CasADi function agree to ~1e-6 here: the MSD HASEL's H is a difference of
    # erf terms with amplitudes up to 2e9 N, whose rounding differs between the two evaluations
    assert H == pytest.approx(storage.numbers["H_min"], rel=1e-5, abs=1e-12)
    assert storage.numbers["H_min"] <= storage.numbers["H_max_sampled"]
    doc = report.to_dict()
    json.dumps(doc, allow_nan=False)
    assert doc["passive"] is True and set(doc["tests"]) == {"interconnection", "dissipation", "feedthrough", "storage"}


def test_curling_hasel_margin_is_its_weakest_resistive_direction(seeds):
    """The curling HASEL's R block per segment is [[1/R0 + 1/R1, 1/R0], [1/R0, 1/R0 + 1/R2]] (and b on the
    momentum): the margin is the smallest eigenvalue of that block scaled by its diagonal, computed here by hand."""
    system = seeds["curling_hasel"]
    P = system.param_values()
    g0, g1, g2 = 1 / P["R0"], 1 / P["R1"], 1 / P["R2"]
    M = np.array([[g0 + g1, g0], [g0, g0 + g2]])
    d = np.sqrt(np.diag(M))
    expected = np.linalg.eigvalsh(M / np.outer(d, d))[0]
    assert dissipation_margin(system, samples=64) == pytest.approx(expected, rel=1e-9)
    # the full form [[R, P], [P^T, S]] becomes singular where every input map cos(gamma2 theta_i) vanishes, at
    # the validity boundary |gamma2 theta| = pi / 2: the optimiser finds it, the margin (R) is unaffected
    rep = certify(system, **QUICK)
    assert rep["dissipation"].numbers["full_form_min_eigenvalue"] < 1e-6
    assert rep.margin == pytest.approx(expected, rel=1e-9)


# -- non-passive models ----------------------------------------------------------------------------------
@pytest.mark.parametrize("R", [-5.0, -0.1])
def test_negative_resistor_is_detected_with_the_element_responsible(rlc, R):
    report = certify(rlc, params={"R.R": R}, samples=64, starts=2)
    assert not report.passive
    diss = report["dissipation"]
    assert diss.verdict == "fail"
    assert diss.element.startswith("R") and f"R.R = {R:g}" in diss.element
    assert "not applicable" in diss.method  # the symbolic proof assumes R.R > 0
    assert report.margin < 0
    assert _eig_min_at(rlc, diss.worst, {"R.R": R}) < 0
    assert diss.numbers["shares"]["R"] < 0
    assert dissipation_margin(rlc, params={"R.R": R}) < 0


def test_state_dependent_R_losing_definiteness_is_found_where_it_is_negative():
    system = fitted_damper(vc=0.8)
    assert certify(system, samples=128, starts=2).passive  # over its declared (fitted) range
    report = certify(system, box={"p": (-0.12, 0.12)}, samples=128, starts=3)  # up to 1.2 m/s
    diss = report["dissipation"]
    assert diss.verdict == "fail" and not report.passive
    assert diss.element == "damper"
    v = diss.worst["p"] / 0.1
    assert abs(v) > 0.8  # negative damping region, from the law itself
    assert _eig_min_at(system, diss.worst) < 0  # independently: numpy on the lambdified matrix
    # the optimiser goes to the box edge, where b(v) is most negative: b0 (1 - (1.2 / 0.8)^2) = -1.25 b0
    assert abs(v) == pytest.approx(1.2, rel=1e-6)
    assert diss.numbers["min_eigenvalue_unscaled"] == pytest.approx(0.05 * (1 - 1.5**2), rel=1e-6)


def test_dissipation_over_the_symbolic_budget_finishes_and_is_not_a_pass():
    """R = (Q+R+2)**120 - (Q+R+1)**120 (positive, ~1e359: inf - inf = nan in floating point): the certificate
    once hung in the symbolic minors; now it refuses them as over the budget, cannot sample D in floats, and says
    both instead of passing (measured 0.3 s; bound 20 s for a loaded machine).  The charge's unit is left
    undeclared: the entry adds a charge to a resistance, which the constructor's unit check would refuse."""
    from dataclasses import replace

    rc = rc_circuit()
    s = sp.Symbol("C.Q", real=True) + sp.Symbol("R.R", positive=True)
    entry = (s + 2) ** 120 - (s + 1) ** 120
    system = rc._replace(R=sp.Matrix([[entry]]), dissipators=(("R", {(0, 0): entry, (0, 1): rc.P[0, 0],
                                                                     (1, 1): rc.S[0, 0]}),),
                         states=[replace(rc.states[0], unit="1")])
    t = time.perf_counter()
    report = certify(system, samples=64, starts=1)
    assert time.perf_counter() - t < 20.0
    diss = report["dissipation"]
    assert not report.passive and diss.verdict == "undecided"
    assert "not finite" in diss.summary and "over the symbolic budget" in diss.summary


def test_damper_without_its_unit_is_not_certified(msd):
    """The certificate used to say PASSIVE for a damper whose coefficient is declared in N (such a model is now
    refused when built).  One whose unit is left at the default "1" builds, and check() takes it as
    dimensionless: the structure's units disagree (R[0,0] is 1 where kg/s is needed), no physical power balance."""
    from dataclasses import replace

    bad = msd._replace(params=[replace(q, unit="1") if q.name == "b.b" else q for q in msd.params])
    report = certify(bad, samples=32, starts=1)
    assert not report.passive and report["units"].verdict == "fail"
    assert "R[0,0] (element 'b') is 1, expected kg/s" in report["units"].summary
    assert [t.name for t in certify(msd, samples=32, starts=1).tests if t.name == "units"] == []


def test_coupled_R_is_indefinite_only_off_its_diagonal():
    """R = [[a, c x], [c x, a]] has PSD diagonal everywhere but a negative eigenvalue a - |c x| for |x| > a / c."""
    system = coupled_losses()
    assert certify(system, samples=128, starts=2).passive  # |x| <= 0.4 < a / c = 0.5
    report = certify(system, box={"x": (-1.0, 1.0)}, samples=256, starts=3)
    diss = report["dissipation"]
    assert diss.verdict == "fail"
    x = diss.worst["x"]
    assert abs(x) > 0.5 and _eig_min_at(system, diss.worst) < 0
    assert abs(x) == pytest.approx(1.0, rel=1e-6)  # most negative at the edge: 1 - 2 = -1
    assert diss.element == "R as given (no resistive element declared for it)"
    assert set(diss.numbers["direction"]) == {"x", "y"}


def test_parameter_box_finds_the_negative_corner(msd):
    """Varying a parameter over a box that crosses zero is a failure at the negative end."""
    report = certify(msd, box={"b.b": (-0.1, 1.0)}, samples=64, starts=2)
    diss = report["dissipation"]
    assert diss.verdict == "fail"
    assert diss.worst["b.b"] == pytest.approx(-0.1, rel=1e-6)
    assert report.box["b.b"] == (-0.1, 1.0)


# -- the margin ------------------------------------------------------------------------------------------
def test_margin_scales_with_the_damping_and_matches_the_certificate(msd):
    assert dissipation_margin(msd) == pytest.approx(1.0, rel=1e-12)
    assert dissipation_margin(msd, params={"b.b": 0.1}) == pytest.approx(0.25, rel=1e-12)
    assert certify(msd, params={"b.b": 0.1}, samples=64, starts=1).margin == pytest.approx(0.25, rel=1e-12)


def test_margin_scale_is_the_systems_own_values(rlc):
    """Overrides are measured against the system's declared values; a system built with other values is its own
    reference (generated functions and caches are shared by structure, the scale is not)."""
    assert dissipation_margin(rlc, params={"R.R": 20.0}) == pytest.approx(2.0, rel=1e-12)
    other = rlc.with_params({"R.R": 20.0})
    assert dissipation_margin(other) == pytest.approx(1.0, rel=1e-12)
    assert certify(other, samples=16, starts=0).margin == pytest.approx(1.0, rel=1e-12)
    assert dissipation_margin(rlc) == pytest.approx(1.0, rel=1e-12)


@settings(max_examples=25, deadline=None)
@given(a=st.floats(0.05, 20.0), b=st.floats(0.05, 20.0), c=st.floats(-20.0, 20.0))
def test_margin_of_a_constant_R_is_its_scaled_smallest_eigenvalue(a, b, c):
    """Structural law: for R = [[a, c], [c, b]] the margin is λ_min of R scaled by the nominal diagonal (1, 1)."""
    system = _constant_r()
    margin = dissipation_margin(system, params={"a": a, "b": b, "c": c}, samples=8)
    expected = np.linalg.eigvalsh(np.array([[a, c], [c, b]]))[0]
    assert margin == pytest.approx(expected, rel=1e-9, abs=1e-12)
    scale = max(a, b, abs(c))
    if a * b >= c * c:
        assert margin >= -1e-12 * scale
    else:
        assert margin < 1e-12 * scale


_CONSTANT_R = []


def _constant_r():
    if not _CONSTANT_R:
        x, y = sp.Symbol("x", real=True), sp.Symbol("y", real=True)
        a, b, c = Param("a", 1.0), Param("b", 1.0), Param("c", 0.0)
        _CONSTANT_R.append(PHSystem("constant_r", ["x", "y"], H=(x**2 + y**2) / 2, J=[[0, 1], [-1, 0]],
                                    R=[[a.symbol, c.symbol], [c.symbol, b.symbol]], params=[a, b, c]))
    return _CONSTANT_R[0]


def test_margin_is_cheap_enough_for_a_sweep(seeds):
    system = seeds["curling_hasel"]
    dissipation_margin(system)  # first call: generates the function and draws the sample
    values = np.linspace(500.0, 2000.0, 20)
    wall = time.perf_counter()
    margins = [dissipation_margin(system, params={"R0": r}) for r in values]
    per_call = (time.perf_counter() - wall) / len(values)
    assert per_call < 0.1, f"{per_call:.3f} s per call"
    assert all(m > 0 for m in margins)
    assert margins[0] > margins[-1]  # monotone in R0 here: a sweep sees the trend


# -- trajectories ----------------------------------------------------------------------------------------
def test_dissipation_inequality_on_a_curling_hasel_trajectory(seeds):
    system = seeds["curling_hasel"]
    t = np.linspace(0.0, 0.6, 601)
    res = simulate(system, t, u={"U": square(5000.0, 4.0)}, x0={f"seg{i}.l_p": 0.015 for i in range(1, 5)})
    test = dissipation_inequality(res)
    n = test.numbers
    assert test.verdict == "pass", test.line()
    assert n["split_relative_error"] <= 1e-6
    # independent sum of the per-element accounts against the total quadrature
    parts = sum(res.quadratures[f"E_dissipated[{label}]"] for label, _ in system.dissipators)
    total = res.quadratures["E_dissipated"]
    assert np.max(np.abs(parts - total)) <= 1e-6 * np.max(np.abs(total))
    assert sum(n["dissipated_by"].values()) == pytest.approx(n["dissipated"], rel=1e-6)
    assert set(n["dissipated_by"]) == {label for label, _ in system.dissipators}
    assert all(v >= 0 for v in n["dissipated_by"].values())
    # the inequality, and the balance supplied = stored + dissipated
    assert n["min_slack_relative"] >= -1e-6
    # CVODES at rtol=1e-8 with a restart at every square-wave edge closes the balance to ~1e-6 (1.2e-6 measured)
    assert n["supplied"] == pytest.approx(n["stored"] + n["dissipated"], rel=1e-5)
    assert n["balance_error"] <= 1e-5
    assert np.all(test.series["supplied"] - test.series["stored"] >= -1e-6 * n["supplied"])


def test_dissipation_inequality_fails_for_an_active_damper():
    """Released at 1 m/s the fitted damper (negative above 0.8 m/s) gains energy with no input."""
    system = fitted_damper(vc=0.8)
    test = dissipation_inequality(system, np.linspace(0.0, 0.05, 51), x0={"p": 0.1})
    assert test.verdict == "fail"
    assert test.element == "damper"
    assert test.numbers["supplied"] == 0.0 and test.numbers["stored"] > 0
    assert test.numbers["dissipated_by"]["damper"] < 0


def test_dissipation_inequality_without_quadratures_uses_the_output_grid(rc):
    res = simulate(rc, np.linspace(0.0, 5e-3, 2001), u={"U": 1.0}, method="discrete_gradient")
    test = dissipation_inequality(res)
    assert test.verdict == "pass" and "trapezoidal" in test.method
    assert test.numbers["supplied"] == pytest.approx(test.numbers["stored"] + test.numbers["dissipated"], rel=1e-4)


def test_trajectory_in_the_certificate(rc):
    t = np.linspace(0.0, 5e-3, 101)
    report = certify(rc, trajectory={"t": t, "u": {"U": square(1.0, 500.0)}}, samples=32, starts=1)
    assert report["trajectory"].verdict == "pass"
    with pytest.raises(InputDataError, match="'tt'"):
        certify(rc, trajectory={"tt": t}, samples=32, starts=1)


# -- local passivity -------------------------------------------------------------------------------------
@pytest.mark.parametrize("R", [1.0, 10.0, 250.0])
def test_rlc_local_indices_match_closed_form(R):
    """Series RLC admittance Y = 1 / (R + j(ωL - 1/(ωC))): inf Re Y = 0 (ω -> 0, ∞), inf Re Z = R."""
    from systems.examples import rlc_circuit

    loc = local_passivity(rlc_circuit(R=R), cross_check=False)
    assert loc.verdict == "pass" and loc.stability == "stable"
    assert loc.input_index == pytest.approx(0.0, abs=1e-8 * loc.details["gain"])
    assert loc.output_index == pytest.approx(R, rel=1e-6)
    assert loc.units == ("A/V", "V/A")
    assert loc.details["hamiltonian_nu"]["verified"]


@pytest.mark.parametrize(("m", "k", "b"), [(1.0, 4.0, 0.4), (0.2, 50.0, 3.0)])
def test_msd_local_indices_match_closed_form(m, k, b):
    """Mobility of a mass-spring-damper: inf Re G = 0, inf Re 1/G = b; at any constant force."""
    from systems.examples import mass_spring_damper

    loc = local_passivity(mass_spring_damper(m=m, k=k, b=b), u_eq={"F": 2.0}, cross_check=False)
    assert loc.verdict == "pass"
    assert loc.x_eq["k.l"] == pytest.approx(2.0 / k, rel=1e-9)
    assert loc.input_index == pytest.approx(0.0, abs=1e-8 * loc.details["gain"])
    assert loc.output_index == pytest.approx(b, rel=1e-6)
    assert loc.details["storage_kyp"]["certifies"]  # V = 1/2 dx^T Hess(H) dx is a KYP storage


def test_rc_with_leak_has_a_positive_input_index():
    """Y(jω) = 1 / (R + R2 / (1 + jω R2 C)): Re Y rises from 1/(R + R2) at ω = 0 to 1/R; inf Re Z = R."""
    R, R2 = 100.0, 900.0
    loc = local_passivity(rc_leak(R=R, R2=R2), cross_check=False)
    assert loc.input_index == pytest.approx(1 / (R + R2), rel=1e-6)
    assert loc.output_index == pytest.approx(R, rel=1e-6)
    assert loc.details["nu_frequency"] == 0.0


def test_curling_hasel_casimirs_are_removed_before_linearising():
    from systems.curling_hasel import curling_hasel

    system = curling_hasel(2)
    x0 = {f"seg{i}.l_p": 0.015 for i in (1, 2)}
    loc = local_passivity(system, u_eq={"U": 0.0}, x0=x0, cross_check=False)
    assert loc.removed == 2  # one conserved top-film length per segment
    assert loc.T.shape == (10, 8)
    assert loc.stability == "stable" and loc.verdict == "pass"
    assert loc.details["conserved_leak"] < 1e-12
    # rho = R0 / (n gamma1^2): the source sees the segments' R0 in parallel through the input map at rest
    P = system.param_values()
    assert loc.output_index == pytest.approx(P["R0"] / (2 * P["gamma1"] ** 2), rel=1e-6)
    # without the reduction the Jacobian has two zero eigenvalues (up to rounding)
    from codegen import generate

    A = np.asarray(generate(system).jac_rhs(np.array(list(loc.x_eq.values())), [0.0], system.param_vector())[0])
    s = np.array([st.typical for st in system.states])
    ev = np.linalg.eigvals(A * s[None, :] / s[:, None])
    assert np.sum(np.abs(ev) < 1e-12 * np.max(np.abs(ev))) == 2  # the next smallest is the ~10 s drift, 1e-9 of it


def test_unstable_equilibrium_fails_the_local_test():
    """An inverted pendulum-like negative stiffness: the linearisation is unstable."""
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    system = PHSystem("saddle", ["q", StateInfo("p", kind="I")], H=-q**2 / 2 + p**2 / 2, J=[[0, 1], [-1, 0]],
                      R=[[0, 0], [0, 1]], G=[[0], [1]], inputs=["F"])
    loc = local_passivity(system, x_eq={"q": 0.0, "p": 0.0}, cross_check=False)
    assert loc.stability == "unstable" and loc.verdict == "fail"
    assert "q" in loc.element


def test_local_passivity_without_cvxopt(monkeypatch, rlc):
    import control.passivity

    monkeypatch.setattr(control.passivity, "cvx", None)
    loc = local_passivity(rlc)
    assert "lmi" not in loc.details and loc.verdict == "pass"
    with pytest.raises(InputDataError, match="cvxopt"):
        local_passivity(rlc, cross_check=True)


def test_lmi_cross_check_agrees_where_cvxopt_is_installed(msd):
    import cvxopt  # noqa: F401  (in the test extra: this cross-check always runs)
    loc = local_passivity(msd, u_eq={"F": 1.0}, cross_check=True)
    lmi = loc.details["lmi"]
    assert lmi["agree"], lmi
    assert lmi["output_index"] == pytest.approx(0.4, rel=1e-4)


def test_local_test_in_the_certificate(msd):
    report = certify(msd, u={"F": 1.0}, samples=32, starts=1)
    local = report["local"]
    assert local.verdict == "pass"
    assert local.numbers["output_index"] == pytest.approx(0.4, rel=1e-6)
    assert local.worst["k.l"] == pytest.approx(0.25, rel=1e-9)


# -- invalid specifications ------------------------------------------------------------------------------
@pytest.mark.parametrize(("box", "error", "words"), [
    ({"k.l": (0.1, -0.1)}, InputDataError, ["'k.l'", "lower bound 0.1 > upper bound -0.1"]),
    ({"nope": (0.0, 1.0)}, InputDataError, ["'nope'"]),
    ({"k.l": (0.0, float("inf"))}, InputDataError, ["'k.l'", "not finite"]),
    ({"b.b": (2.0, 1.0)}, InputDataError, ["'b.b'", "lower bound 2"]),
    ({"k.l": (1.0,)}, InputDataError, ["'k.l'", "(lower, upper)"]),
])
def test_invalid_box_is_refused_naming_it(msd, box, error, words):
    with pytest.raises(error) as exc:
        certify(msd, box=box, samples=16, starts=0)
    for w in words:
        assert w in str(exc.value)
    with pytest.raises(error):
        dissipation_margin(msd, box=box)


def test_unknown_parameter_override_is_refused(msd):
    with pytest.raises(ParameterError, match="'nope'"):
        certify(msd, params={"nope": 1.0}, samples=16)


def test_an_equilibrium_that_is_not_one_is_refused_naming_it(msd):
    with pytest.raises(EquilibriumError) as exc:
        certify(msd, equilibrium={"k.l": 0.3}, u={"F": 2.0}, samples=16, starts=0)
    msg = str(exc.value)
    assert "k.l=0.3" in msg and "m.p" in msg and "not an equilibrium" in msg
    # the true one passes the check
    report = certify(msd, equilibrium={"k.l": 0.5}, u={"F": 2.0}, samples=16, starts=0)
    assert report["local"].verdict == "pass"
    with pytest.raises(InputDataError, match="'nope'"):
        local_passivity(msd, x_eq={"nope": 1.0})
    with pytest.raises(InputDataError, match="'G'"):
        local_passivity(msd, u_eq={"G": 1.0})


def test_equilibrium_outside_the_validity_domain_is_refused():
    from systems.msd_hasel import msd_hasel

    system = msd_hasel()
    with pytest.raises(EquilibriumError, match="validity domain"):
        local_passivity(system, x_eq={"x": 0.03, "p": 0.0})  # beyond the input map's zero (17.85 mm, the fits read in cm)


@pytest.mark.parametrize("kw", [{"samples": 0}, {"starts": -1}, {"samples": 2.5}])
def test_invalid_sizes_are_refused(msd, kw):
    with pytest.raises(InputDataError):
        certify(msd, **kw)


# -- the report ------------------------------------------------------------------------------------------
def test_report_text_json_and_html(tmp_path, rc):
    report = certify(rc, params={"R.R": -1e3}, trajectory={"t": np.linspace(0, 1e-3, 21), "u": {"U": 1.0}},
                     u={"U": 0.0}, samples=32, starts=1)
    assert isinstance(report, PassivityReport)
    text = str(report)
    assert "NOT CERTIFIED PASSIVE" in text and "element responsible: R" in text
    doc = report.to_dict()
    s = json.dumps(doc, allow_nan=False)
    assert json.loads(s)["passive"] is False
    assert doc["tests"]["dissipation"]["verdict"] == "fail"
    assert {t["verdict"] for t in doc["tests"].values()} <= {"pass", "fail", "undecided"}
    assert doc["tests"]["dissipation"]["worst"]["C.Q"] == report["dissipation"].worst["C.Q"]
    out = tmp_path / "rep"
    paths = report.write_report(out)
    names = sorted(os.listdir(out))
    assert names == sorted(os.path.basename(p) for p in paths)
    assert {"report.html", "report.json", "report.txt", "dissipation.png", "trajectory.png"} <= set(names)
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") == len([n for n in names if n.endswith(".png")])
    assert json.loads((out / "report.json").read_text())["passive"] is False
    assert not [n for n in names if n.startswith(".tmp")]


def test_report_into_a_missing_parent_writes_nothing(tmp_path, msd):
    report = certify(msd, samples=16, starts=0)
    with pytest.raises(InputDataError, match="does not exist"):
        report.write_report(tmp_path / "missing" / "rep")
    assert not (tmp_path / "missing").exists()


@pytest.mark.slow
def test_reduced_settings_agree_with_defaults(seeds):
    """The reduced sizes of the seed proof give the defaults' verdicts, margins and storage minima."""
    for system in seeds.values():
        quick, full = certify(system, **QUICK), certify(system)
        assert full.passive and quick.passive
        assert quick.margin == pytest.approx(full.margin, rel=1e-6)
        # H_min to 1e-6 relative, or 1e-8 of the energy range over the box when it is ~0 (the manta-ray fin's rest
        # point sits at the regularised kink of its geometry, where IPOPT stops within ~1e-10 J)
        energy = full["storage"].numbers["H_max_sampled"]
        assert quick["storage"].numbers["H_min"] == pytest.approx(full["storage"].numbers["H_min"], rel=1e-6, abs=1e-8 * energy)


def test_hamiltonian_crossings_are_where_the_popov_function_vanishes():
    """The LMI-free KYP check: imaginary eigenvalues of the Popov Hamiltonian at the frequencies where
    Re Y(jω) = ν for the series RLC (ωL - 1/(ωC) = ±R when ν = 1/(2R)), written from the circuit."""
    from codegen.passivity import _hamiltonian_crossings
    from systems.examples import rlc_circuit

    R, L, C = 10.0, 1e-3, 1e-6
    ss = local_passivity(rlc_circuit(R=R, L=L, C=C), cross_check=False).statespace
    nu = 0.5 / R
    Mq = np.array([[0.0, 0.5], [0.5, -nu]])
    cross, info = _hamiltonian_crossings(ss.A, ss.B, ss.C, ss.D, Mq)
    expected = sorted((sign * R + np.sqrt(R**2 + 4 * L / C)) / (2 * L) for sign in (1.0, -1.0))
    assert sorted(cross[cross > 0]) == pytest.approx(expected, rel=1e-8)
    below, _ = _hamiltonian_crossings(ss.A, ss.B, ss.C, ss.D, np.array([[0.0, 0.5], [0.5, 1e-6]]))
    assert not np.any(below > 0)  # just below the index ν = 0: no crossing


@pytest.mark.parametrize("potential, verdict", [(lambda q: -q**4, "fail"), (lambda q: -q**2 / 2, "fail"),
                                                (lambda q: q**2 - q**4 / 100, "undecided"), (lambda q: -sp.tanh(q), "pass"),
                                                (lambda q: q**4 / 4 - q**2 / 2, "pass")])
def test_storage_test_agrees_with_the_structural_check(potential, verdict):
    """The certificate's storage test and ``PHSystem.check()`` reach the same verdict on H bounded below;
    an H unbounded below is never certified passive."""
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    H = potential(q) + p**2 / 2
    system = PHSystem("osc", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")], H=H, J=[[0, 1], [-1, 0]],
                      R=[[0, 0], [0, 1]], G=[[0], [1]], inputs=["F"])
    report = certify(system, samples=64, starts=2)
    assert report["storage"].verdict == verdict
    assert system.check()["H bounded below"].verdict == verdict
    assert report.passive == (verdict == "pass")
