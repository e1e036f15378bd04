"""PHSystem: construction, immutability, derived quantities, and the invalid-input table.

The table follows sympy's ``test_system_class.py``: every bad input raises the
project's own error type (a :class:`phs.PHSError`), the message names the
culprit, and nothing is written to disk or changed in the objects involved.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import sympy as sp

import phs
from codegen import simulate, simulator
from components import (
    Capacitor,
    Damper,
    ForceSource,
    GeometricConstraint,
    Gravity,
    LinearSpring,
    Mass,
    Resistor,
    VoltageSource,
    geometric_symbol,
)
from phs import (
    DomainError,
    InputDataError,
    InterconnectionError,
    ModelError,
    Param,
    ParameterError,
    PHSError,
    PHSystem,
    StateInfo,
    UnitError,
    equilibrium,
    interconnect,
    parallel,
    series,
    signals,
    symbol_of_state,
)
from phs.units import parse_unit

q, p = sp.symbols("q p", real=True)
T_GRID = np.linspace(0.0, 1e-3, 11)


def _oscillator(**kw):
    k, m = Param("k", 2.0, "N/m"), Param("m", 1.0, "kg")
    args = dict(states=[StateInfo("q", "m"), StateInfo("p", "kg*m/s", kind="I")],
                H=k.symbol * q**2 / 2 + p**2 / (2 * m.symbol), J=[[0, 1], [-1, 0]], R=sp.zeros(2, 2), params=[k, m])
    args.update(kw)
    return PHSystem("osc", **args)


def _rc_parts(C=1e-6, R=1e3):
    return [VoltageSource("U"), Resistor("R", R=R), Capacitor("C", C=C)]


# -- construction and immutability ------------------------------------------------------------------------
def test_matrices_dynamics_and_outputs_of_the_rc_circuit(rc):
    R, C, Q, U = sp.Symbol("R.R", positive=True), sp.Symbol("C.C", positive=True), rc.x[0], rc.u[0]
    assert sp.simplify(rc.dynamics[0] - (U - Q / C) / R) == 0
    assert sp.simplify(rc.port_output[0] - (U - Q / C) / R) == 0  # source current
    assert rc.J == sp.zeros(1, 1)
    assert sp.simplify(rc.R[0, 0] - 1 / R) == 0 and sp.simplify(rc.S[0, 0] - 1 / R) == 0


@pytest.mark.parametrize("name", ["rc", "rlc", "msd", "duffing"])
def test_power_balance_is_an_identity(examples, name):
    s = examples[name]
    pb = s.power_balance
    assert sp.simplify(pb["dHdt"] - (pb["supplied"] - pb["dissipated"])) == 0
    total = sum(s.dissipator_powers().values(), sp.Integer(0))
    assert sp.simplify(total - pb["dissipated"]) == 0


def test_system_is_immutable_and_with_params_returns_a_new_system(rc):
    before = (rc.model_hash(), rc.param_values())
    with pytest.raises(AttributeError, match="immutable"):
        rc.name = "other"
    other = rc.with_params({"C.C": 2e-6})
    assert other is not rc
    assert other.param("C.C").value == 2e-6
    assert (rc.model_hash(), rc.param_values()) == before
    assert other.model_hash() == rc.model_hash()  # structure and names only
    assert rc.renamed("rc2").name == "rc2" and rc.name == "rc"


def test_param_vector_applies_checked_overrides(rc):
    np.testing.assert_array_equal(rc.param_vector({"R.R": 5.0}), [5.0, 1e-6])
    with pytest.raises(ParameterError, match="R.R"):
        rc.param_vector({"R.R": float("nan")})


def test_every_problem_is_reported_at_once():
    with pytest.raises(ModelError) as err:
        _oscillator(J=[[0, 1]], params=[Param("k", None, "N/m", positive=True), Param("m", 1.0, "kg")])
    assert len(err.value.problems) == 2
    assert "J has shape (1, 2)" in str(err.value) and "'k' has no value" in str(err.value)


def test_unknown_symbol_is_named():
    z = sp.Symbol("z", real=True)
    with pytest.raises(ModelError, match="unknown symbol 'z'"):
        _oscillator(H=q**2 + z)


def test_domain_conditions_are_added_for_asin_sqrt_and_log():
    L = Param("L", 2.0, "m")
    s = _oscillator(H=q**2 / 2 + p**2 / 2 + sp.asin(q / L.symbol) + sp.log(2 + q), params=[L])
    labels = " ".join(c.label for c in s.conditions)
    assert "asin argument <= 1" in labels and "asin argument >= -1" in labels and "log argument" in labels


def test_check_report_of_the_examples(examples):
    for s in examples.values():
        rep = s.check(samples=20)
        assert rep.ok, str(rep)
        assert rep["units"].verdict == "pass"
        assert rep["R positive semidefinite"].verdict == "pass"


def test_repr_is_short(rc):
    assert repr(rc) == "PHSystem('rc', states=1, inputs=1, params=2, measured=1)"


def test_lambdify_evaluates_at_the_parameter_values(rc):
    # H = Q^2 / (2 C) with C = 1 uF: Q = 1 uC stores 0.5 uJ
    assert float(rc.lambdify(rc.H)([1e-6], [0.0], rc.param_vector())) == pytest.approx(5e-7, rel=1e-15)


# -- invalid-input table ---------------------------------------------------------------------------------------
def _domain_asin_system():
    """An arm angle phi = asin(l / L) from a constraint; gravity on phi. A large force pushes l past L."""
    l = symbol_of_state("k.l")  # noqa: E741
    phi = geometric_symbol("phi")
    L = Param("L", 1.0, "m", "arm length")
    geo = GeometricConstraint("geo", "phi", sp.Eq(sp.sin(phi), l / L.symbol), params=[L])
    return interconnect("arm", [ForceSource("F"), Mass("m"), LinearSpring("k", K=1.0), Damper("b", b=2.0), geo,
                                Gravity("g", height=0.01 * phi, m=0.1)], [series("F", "m", "k", "b")])


def _domain_condition_system():
    """A zipped length l_e = L - l with the declared condition l_e >= 0 (the rhs stays finite beyond it)."""
    l = symbol_of_state("k.l")  # noqa: E741
    le = geometric_symbol("l_e")
    L = Param("L", 1.0, "m", "electrode length")
    con = GeometricConstraint("vol", "l_e", sp.Eq(L.symbol, le + l), params=[L],
                              conditions=[("zipped length l_e >= 0", le)])
    return interconnect("zip", [ForceSource("F"), Mass("m"), LinearSpring("k", K=1.0), Damper("b", b=2.0), con,
                                Gravity("g", height=0.01 * le, m=0.1)], [series("F", "m", "k", "b")])



CASES = [
    # id, action(examples), error type, substrings the message must contain
    ("with_params unknown parameter", lambda S: S["rc"].with_params({"C.Cx": 1.0}), ParameterError, ["C.Cx"]),
    ("simulate params unknown parameter", lambda S: simulate(S["rc"], T_GRID, params={"R.Rx": 2.0}),
     ParameterError, ["R.Rx"]),
    ("parameter without value", lambda S: interconnect(
        "rc0", [VoltageSource("U"), Resistor("R", R=1.0), Capacitor("C", C=Param("C0", None, "F"))],
        [series("U", "R", "C")]), ModelError, ["C0", "no value"]),
    ("matrix of the wrong shape", lambda S: _oscillator(G=[[1, 0, 0]]), ModelError, ["G", "(1, 3)", "(2, 0)"]),
    ("R not PSD", lambda S: PHSystem("neg", ["q"], q**2 / 2, J=[[0]], R=[[-1]]), ModelError,
     ["R is not positive semidefinite"]),
    ("negative resistor", lambda S: Resistor("R1", R=-5.0), ModelError, ["R1", "'R'", "positive"]),
    pytest.param("negative resistor parameter", lambda S: interconnect(
        "neg", [VoltageSource("U"), Resistor("R1", R=Param("R1.R", -5.0, "Ohm")), Capacitor("C")],
        [series("U", "R1", "C")]), ModelError, ["R1"], id="negative resistor parameter"),
    ("J not skew", lambda S: _oscillator(J=[[0, 1], [1, 0]]), ModelError, ["skew", "q", "p"]),
    ("unconnected port", lambda S: interconnect("open", _rc_parts(), [series("U", "C")]),
     InterconnectionError, ["R.p", "not connected"]),
    ("unknown port", lambda S: interconnect("typo", _rc_parts(), [series("U", "R", "Cx")]),
     InterconnectionError, ["Cx"]),
    ("two capacitors in parallel", lambda S: interconnect(
        "cc", [VoltageSource("U"), Resistor("R", R=1.0), Capacitor("C1"), Capacitor("C2")],
        [series("U", "R", parallel("C1", "C2"))]), InterconnectionError, ["C1.Q", "C2.Q", "dependent"]),
    ("two masses in series", lambda S: interconnect(
        "mm", [ForceSource("F"), Mass("m1"), Mass("m2"), LinearSpring("k")], [series("F", "m1", "m2", "k")]),
     InterconnectionError, ["m1.p", "m2.p", "dependent"]),
    pytest.param("asin domain left during simulation", lambda S: simulator(_domain_asin_system(), max_steps=500).run(
        np.linspace(0.0, 20.0, 201), u={"F": 5.0}), DomainError, ["t=", "asin"],
        id="asin domain left during simulation"),
    ("declared condition left during simulation", lambda S: simulate(
        _domain_condition_system(), np.linspace(0.0, 20.0, 201), u={"F": 5.0}), DomainError,
     ["t=0.8", "l_e >= 0"]),  # the first point outside, within the output interval 0.8-0.9 (t=0.825)
    ("time grid not increasing", lambda S: simulate(S["rc"], [0.0, 1e-3, 1e-3, 2e-3]), InputDataError,
     ["index 2"]),
    ("time grid of one point", lambda S: simulate(S["rc"], [0.0]), InputDataError, ["time grid"]),
    ("time grid not finite", lambda S: simulate(S["rc"], [0.0, np.nan, 1.0]), InputDataError, ["index 1"]),
    ("x0 with unknown state", lambda S: simulate(S["rc"], T_GRID, x0={"C.q": 1e-6}), InputDataError, ["C.q"]),
    ("x0 of the wrong length", lambda S: simulate(S["rlc"], T_GRID, x0=[0.0]), InputDataError, ["1 values", "2"]),
    ("input with unknown name", lambda S: simulate(S["rc"], T_GRID, u={"V": 1.0}), InputDataError, ["'V'"]),
    ("input array of the wrong shape", lambda S: simulate(S["rc"], T_GRID, u={"U": np.ones(3)}), InputDataError,
     ["'U'", "(3,)"]),
    ("equilibrium with unknown input", lambda S: equilibrium(S["rc"], u={"V": 1.0}), InputDataError, ["'V'"]),
    ("unknown unit", lambda S: parse_unit("furlong/s"), UnitError, ["furlong"]),
    ("sampled signal not increasing", lambda S: signals.Sampled((0.0, 2.0, 1.0), (0.0, 1.0, 2.0)),
     InputDataError, ["index 2"]),
    ("unknown simulation method", lambda S: simulate(S["rc"], T_GRID, method="euler"), InputDataError, ["euler"]),
]


def _ids(case):
    return case[0] if isinstance(case, tuple) else None


@pytest.mark.parametrize(("what", "action", "error", "culprits"), CASES, ids=[_ids(c) for c in CASES])
def test_invalid_input(what, action, error, culprits, examples, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = {k: (s.model_hash(), s.param_values(), s.state_names, s.input_names) for k, s in examples.items()}
    with pytest.raises(PHSError) as err:
        action(examples)
    assert type(err.value) is error, f"{what}: raised {type(err.value).__name__}: {err.value}"
    msg = str(err.value)
    for c in culprits:
        assert c in msg, f"{what}: {c!r} not named in {msg!r}"
    assert os.listdir(tmp_path) == [], "nothing may be written"
    after = {k: (s.model_hash(), s.param_values(), s.state_names, s.input_names) for k, s in examples.items()}
    assert after == before, "nothing may be changed"


def test_errors_are_catchable_by_their_builtin_bases():
    assert issubclass(ParameterError, KeyError) and issubclass(InputDataError, ValueError)
    assert issubclass(DomainError, ArithmeticError) and issubclass(phs.SimulationError, RuntimeError)
    err = ParameterError("system 'rc' has no parameter 'x'")
    assert str(err) == "system 'rc' has no parameter 'x'"  # not quoted like a KeyError


@pytest.mark.parametrize("field", ["H", "J", "measured"])
def test_strings_are_refused_not_parsed(field):
    # sympy parses strings with eval; a PHSystem takes sympy expressions or numbers (files go through phs.safe_parse)
    from phs import Measured

    q = sp.Symbol("q", real=True)
    kw = {"H": q**2 / 2, "J": [[0]], "R": [[1]]}
    measured = [Measured("y", q)]
    if field == "H":
        kw["H"] = "__import__('os').getcwd()"
    elif field == "J":
        kw["J"] = [["__import__('os').getcwd()"]]
    else:
        measured = [Measured("y", "__import__('os').getcwd()")]
    with pytest.raises(ModelError) as info:
        PHSystem("s", ["q"], measured=measured, **kw)
    assert "string" in str(info.value) or "str," in str(info.value)
    # the same system with expressions is accepted
    assert PHSystem("s", ["q"], H=q**2 / 2, J=[[0]], R=[[1]], measured=[Measured("y", q)]).H == q**2 / 2
