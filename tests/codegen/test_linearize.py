"""``linearize``: the Jacobians of the generated functions as a named ``control.StateSpace``, checked
against finite differences and against python-control's own ``control.linearize``."""

from __future__ import annotations

import control
import numpy as np
import pytest

import phs
from codegen.functions import generate
from codegen.idapbc.model import state_vector
from codegen.linearize import casimir_directions, linearize
from phs.errors import InputDataError
from phs.params import c_identifier
from systems.curling_hasel import curling_hasel
from systems.electrostatic_actuator import electrostatic_actuator
from systems.examples import duffing_oscillator, mass_spring_damper, rc_circuit

# bent (theta = 0.2): at theta = 0 and l_p = 0.015 the state is on the edge of the validity domain
CURLING_X = {**{f"seg{i}.l_p": 0.015 for i in (1, 2)}, **{f"seg{i}.theta": 0.2 for i in (1, 2)}}
CASES = [
    (rc_circuit, {"C.Q": 2e-7}, {"U": 0.5}),
    (mass_spring_damper, {"k.l": 0.02, "m.p": 0.1}, {"F": 0.3}),
    (duffing_oscillator, None, None),
    (electrostatic_actuator, None, None),
    (lambda: curling_hasel(2), CURLING_X, {"U": 1000.0}),
]


def _functions(system):
    f = generate(system)
    p = system.param_vector()

    def rhs(x, u):
        return np.asarray(f.rhs(x, u, p), dtype=float).ravel()

    def meas(x, u):
        y, mo = f.output(x, u, p)
        return np.asarray(mo if system.measured else y, dtype=float).ravel()

    return rhs, meas


def _fd(fun, x, u, wrt, scale):
    """Central differences of ``fun`` with a step relative to each variable's typical size."""
    base = x if wrt == "x" else u
    cols = []
    for k in range(len(base)):
        h = 1e-6 * scale[k]
        e = np.zeros(len(base))
        e[k] = h
        if wrt == "x":
            cols.append((fun(x + e, u) - fun(x - e, u)) / (2 * h))
        else:
            cols.append((fun(x, u + e) - fun(x, u - e)) / (2 * h))
    return np.column_stack(cols) if cols else np.zeros((len(fun(x, u)), 0))


def _point(system, x_eq, u_eq):
    x = state_vector(system, x_eq)
    u = np.array([float((u_eq or {}).get(n, 0.0)) for n in system.input_names])
    return x, u


@pytest.mark.parametrize("build, x_eq, u_eq", CASES, ids=["rc", "msd", "duffing", "electrostatic", "curling2"])
def test_matrices_agree_with_finite_differences(build, x_eq, u_eq):
    system = build()
    ss = linearize(system, x_eq, u_eq)
    rhs, meas = _functions(system)
    x, u = _point(system, x_eq, u_eq)
    sx = np.array([max(abs(v), st.typical) for v, st in zip(x, system.states)])
    su = np.array([max(abs(v), 1.0) for v in u])
    for M, fd in ((ss.A, _fd(rhs, x, u, "x", sx)), (ss.B, _fd(rhs, x, u, "u", su)),
                  (ss.C, _fd(meas, x, u, "x", sx)), (ss.D, _fd(meas, x, u, "u", su))):
        scale = np.maximum(np.abs(fd), 1e-300).max(axis=0, keepdims=True) if fd.size else 1.0
        np.testing.assert_allclose(M / scale, fd / scale, atol=1e-5)


@pytest.mark.parametrize("build, x_eq, u_eq", CASES, ids=["rc", "msd", "duffing", "electrostatic", "curling2"])
def test_agrees_with_python_control_linearize(build, x_eq, u_eq):
    """python-control differentiates with an absolute step (1e-6), so its nonlinear system is written in
    states and inputs scaled by their typical sizes (charges are ~1e-9 C), and the result scaled back."""
    system = build()
    rhs, meas = _functions(system)
    x, u = _point(system, x_eq, u_eq)
    s = np.array([st.typical for st in system.states])
    su = np.array([max(abs(v), 1.0) for v in u])
    nl = control.nlsys(lambda t, z, v, params: rhs(s * z, su * np.atleast_1d(v)) / s,
                       lambda t, z, v, params: meas(s * z, su * np.atleast_1d(v)),
                       states=len(x), inputs=len(u), outputs=len(meas(x, u)))
    ref = control.linearize(nl, x / s, u / su)
    A, B = ref.A * s[:, None] / s[None, :], ref.B * s[:, None] / su[None, :]
    C, D = ref.C / s[None, :], ref.D / su[None, :]
    ss = linearize(system, x_eq, u_eq)
    for mine, theirs in ((ss.A, A), (ss.B, B), (ss.C, C), (ss.D, D)):
        scale = np.maximum(np.abs(mine).max(axis=0, keepdims=True), 1e-300) if mine.size else 1.0
        np.testing.assert_allclose(theirs / scale, mine / scale, atol=1e-4)


def test_signals_are_named_as_in_the_model():
    system = curling_hasel(2)
    ss = linearize(system, CURLING_X, outputs="all")
    assert ss.state_labels == system.state_names
    assert ss.input_labels == system.input_names
    # python-control keeps '.' for subsystem.signal: a dotted input or output name is written with '__'
    assert ss.output_labels == [c_identifier(i.output) for i in system.inputs] + system.measured_names
    assert linearize(system, CURLING_X, outputs="port").output_labels == ["U__i"]
    assert ss.name == system.name


def test_a_linear_model_gives_its_own_matrices():
    ss = linearize(rc_circuit(), {"C.Q": 1e-6}, {"U": 3.0})
    R, C = 1e3, 1e-6
    np.testing.assert_allclose(ss.A, [[-1 / (R * C)]])
    np.testing.assert_allclose(ss.B, [[1 / R]])
    np.testing.assert_allclose(ss.C, [[1 / C]])
    np.testing.assert_allclose(ss.D, [[0.0]])


def test_casimirs_of_the_curling_hasel_are_its_top_film_lengths():
    system = curling_hasel(2)
    W = casimir_directions(system, CURLING_X)
    assert W.shape == (2, len(system.state_names))
    ss = linearize(system, CURLING_X, {"U": 1000.0})
    np.testing.assert_allclose(W, ss.casimirs)
    # structurally constant: no state change and no input moves them in the linearisation
    assert np.abs(W @ ss.A).max() < 1e-9 * np.abs(ss.A).max()
    assert np.abs(W @ ss.B).max() < 1e-9 * max(np.abs(ss.B).max(), 1.0)
    # each one ties a segment's l_p to its theta and nothing else
    for w in W:
        used = {system.state_names[k].split(".")[1] for k in np.flatnonzero(w)}
        assert used == {"theta", "l_p"}
    assert casimir_directions(mass_spring_damper()).shape == (0, 2)


def test_exposed_lazily_through_phs():
    assert "linearize" in dir(phs)
    assert phs.linearize is linearize


@pytest.mark.parametrize("kwargs, words", [
    ({"x_eq": {"nope": 1.0}}, ["nope"]),
    ({"u_eq": {"V": 1.0}}, ["'V'", "F"]),
    ({"u_eq": [1.0, 2.0]}, ["one per input"]),
    ({"outputs": "states"}, ["'states'", "measured"]),
])
def test_bad_operating_points_are_refused_naming_them(kwargs, words):
    with pytest.raises(InputDataError) as exc:
        linearize(mass_spring_damper(), **kwargs)
    for w in words:
        assert w in str(exc.value)
