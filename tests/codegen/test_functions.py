"""Generated CasADi functions agree with sympy-lambdified expressions.

Two independent codes evaluate every quantity: the CasADi functions of
:func:`codegen.generate` (sympy -> SX translation, gradient of H by CasADi's
automatic differentiation) and numpy functions lambdified from the sympy
expressions of the PHSystem (gradient by sympy's symbolic differentiation).
At seeded hypothesis points inside the states' ranges, with random inputs and
parameters within their ranges, they must agree to ``|a - b| <= 1e-12 (1 + |a|)``.
The quantities are O(1e-3 .. 1e3) sums of a few terms, so both codes round to
~1e-15 relative to their terms; 1e-12 leaves three orders for cancellation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import sympy as sp
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from codegen import GeneratedFunctions, generate
from codegen.translate import Translator
from phs import ModelError

TOL = 1e-12
POINTS = settings(max_examples=20, deadline=None, database=None, derandomize=True)
SYSTEMS = ["rc", "rlc", "msd", "duffing", "electromechanical", "arm"]


@pytest.fixture(scope="module")
def systems(examples, electromechanical, arm):
    return {**examples, "electromechanical": electromechanical, "arm": arm}


def _close(a, b, what):
    a = np.asarray(a, dtype=float).reshape(-1)
    b = np.asarray(b, dtype=float).reshape(-1)
    assert a.shape == b.shape, f"{what}: shapes {a.shape} vs {b.shape}"
    assert np.all(np.isfinite(a)) and np.all(np.isfinite(b)), f"{what}: not finite: {a} vs {b}"
    bad = np.abs(a - b) > TOL * (1.0 + np.abs(a))
    assert not np.any(bad), f"{what}: CasADi {a[bad]} vs sympy {b[bad]}"


_SYMPY_CACHE: dict = {}


def _sympy_functions(s):
    """Lambdified sympy expressions of ``s`` (built once per system)."""
    key = id(s)
    if key not in _SYMPY_CACHE:
        pb = s.power_balance
        u = sp.Matrix(s.u) if s.inputs else sp.zeros(0, 1)
        _SYMPY_CACHE[key] = (s, {
            "xdot": s.lambdify(s.dynamics),
            "H": s.lambdify(s.H),
            "dH": s.lambdify(s.grad_H),
            "y": s.lambdify(s.port_output) if s.inputs else None,
            "measured": s.lambdify([m.expr for m in s.measured]) if s.measured else None,
            "power": s.lambdify([pb["dHdt"], pb["dissipated"], pb["supplied"]]),
            "A": s.lambdify(s.dynamics.jacobian(s.x)),
            "B": s.lambdify(s.dynamics.jacobian(u)) if s.inputs else None,
            "conditions": s.lambdify([c.expr for c in s.conditions]) if s.conditions else None,
            "terms": s.lambdify([t.expr for t in s.energy_terms]),
            "parts": s.lambdify(list(s.dissipator_powers().values())) if s.dissipators else None,
        })
    return _SYMPY_CACHE[key][1]


def _draw(data, s):
    x = np.array([data.draw(st.floats(*st_.range), label=st_.name) for st_ in s.states])
    u = np.array([data.draw(st.floats(-10.0, 10.0), label=i.name) for i in s.inputs])
    p = np.array([data.draw(st.floats(*q.range), label=q.name) for q in s.params])
    return x, u, p


@pytest.mark.parametrize("name", SYSTEMS)
@POINTS
@given(data=st.data())
def test_casadi_agrees_with_sympy(systems, name, data):
    s = systems[name]
    f, g = generate(s), _sympy_functions(s)
    x, u, p = _draw(data, s)
    if s.conditions:  # stay inside the validity domain (e.g. |l / L| <= 1 under asin) where both are finite
        assume(np.all(np.asarray(g["conditions"](x, u, p), dtype=float) > 1e-9))
    _close(f.rhs(x, u, p), g["xdot"](x, u, p), "rhs")
    _close(f.hamiltonian(x, u, p), g["H"](x, u, p), "H")
    _close(f.grad_hamiltonian(x, u, p), g["dH"](x, u, p), "grad_H (AD vs symbolic)")
    y, meas = f.output(x, u, p)
    if s.inputs:
        _close(y, g["y"](x, u, p), "port outputs")
    if s.measured:
        _close(meas, g["measured"](x, u, p), "measured outputs (output function)")
        _close(f.measured(x, u, p), g["measured"](x, u, p), "measured outputs")
    _close(np.concatenate([np.asarray(v).reshape(-1) for v in f.power_balance(x, u, p)]), g["power"](x, u, p),
           "power balance")
    A, B = f.jac_rhs(x, u, p)
    _close(A, g["A"](x, u, p), "jacobian wrt x")
    if s.inputs:
        _close(B, g["B"](x, u, p), "jacobian wrt u")
    if s.conditions:
        _close(f.conditions(x, u, p), g["conditions"](x, u, p), "conditions")
    _close(f.energy_terms(x, u, p), g["terms"](x, u, p), "energy terms")
    if s.dissipators:
        _close(f.dissipators(x, u, p), g["parts"](x, u, p), "dissipators")


@pytest.mark.parametrize("name", SYSTEMS)
def test_functions_have_named_inputs_outputs_and_c_safe_names(systems, name):
    s = systems[name]
    f = generate(s)
    assert isinstance(f, GeneratedFunctions)
    kinds = ["rhs", "output", "hamiltonian", "grad_hamiltonian", "jac_rhs", "power_balance", "measured",
             "conditions", "dissipators", "energy_terms"]
    assert [fn.name() for fn in f.all()] == [f"{s.name}_{k}" for k in kinds]
    for fn in f.all():
        assert fn.name_in() == ["x", "u", "p"]
    assert f.rhs.name_out() == ["xdot"]
    assert f.output.name_out() == ["y", "measured"]
    assert f.power_balance.name_out() == ["dHdt", "dissipated", "supplied"]
    assert f.rhs.size1_in(0) == len(s.states) and f.rhs.size1_in(2) == len(s.params)


def test_dotted_system_names_become_c_identifiers(rc):
    f = generate(rc.renamed("lab.rc"))
    assert f.rhs.name() == "lab_rc_rhs"  # CasADi refuses '__' in function names; state identifiers keep it
    assert f.rhs.name().isidentifier()


def test_generation_is_cached_per_structure(rc, rlc):
    assert generate(rc) is generate(rc)
    # parameter values are inputs: a variant differing only in values shares the functions
    assert generate(rc.with_params({"R.R": 2e3})) is generate(rc)
    assert generate(rlc) is not generate(rc)


def test_parameters_are_inputs_of_the_generated_functions(rc):
    """Changing a parameter needs no regeneration: Q' = (U - Q/C) / R at two resistances."""
    f = generate(rc)
    for R in (1e3, 4e3):
        assert float(f.rhs([1e-6], [3.0], [R, 1e-6])) == pytest.approx((3.0 - 1.0) / R, rel=1e-15)


def test_translator_shares_subexpressions_and_rejects_unknown_symbols():
    x = sp.Symbol("x")
    X = ca.SX.sym("x")
    tr = Translator({x: X})
    e = tr(sp.sin(x) ** 2 + sp.sin(x) + sp.Heaviside(x) + sp.Max(x, 1) + sp.Piecewise((x, x > 0), (-x, True)))
    fn = ca.Function("f", [X], [e])
    for v in (-0.7, 0.3, 2.0):
        ref = np.sin(v) ** 2 + np.sin(v) + (v > 0) + max(v, 1.0) + abs(v)
        assert float(fn(v)) == pytest.approx(ref, rel=1e-15)
    with pytest.raises(ModelError, match="symbol y"):
        tr(x + sp.Symbol("y"))
