"""Linearisation of a PHSystem at an operating point, as a python-control ``StateSpace``.

The matrices are the Jacobians of the generated functions (:mod:`codegen.functions`) at
``(x_eq, u_eq)``, in physical coordinates (the model's states and units, no scaling):

    dx' = A dx + B du,    dy = C dx + D du

with the states, inputs and outputs named as in the model (python-control reserves ``.`` in input
and output names for ``subsystem.signal``, so there a dot is written ``__``, as in the generated C
identifiers: the port output ``U.i`` is ``U__i``).  The directions in which the
structure ``[J - R, G - P]`` has a left null space at ``x_eq`` (Casimirs: quantities no input and
no energy change can move, such as the curling HASEL's top-film length tied to its angle) are
reported with the result (``ss.casimirs``): along them the linearisation has eigenvalues at zero
that no controller can move.  The operating point may be an :class:`~phs.equilibria.EquilibriumResult`
(``linearize(s, equilibrium(s, u=...))``): its state and its input are used.  The result is a
:class:`~codegen._linearization.LinearizationResult`, a ``control.StateSpace`` with a one-line ``repr``,
``plot()`` (its poles) and ``to_pandas()``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from phs.errors import InputDataError
from phs.params import c_identifier

if TYPE_CHECKING:
    from codegen._linearization import LinearizationResult

_OUTPUTS = ("measured", "port", "all")


def _input_vector(system, u_eq) -> np.ndarray:
    if u_eq is None:
        return np.zeros(len(system.inputs))
    if isinstance(u_eq, dict):
        unknown = [k for k in u_eq if k not in system.input_names]
        if unknown:
            raise InputDataError(f"u_eq: system {system.name!r} has no input {unknown[0]!r} "
                                 f"(inputs: {', '.join(system.input_names) or 'none'})")
        return np.array([float(u_eq.get(n, 0.0)) for n in system.input_names])
    u = np.asarray(u_eq, dtype=float).ravel()
    if u.shape != (len(system.inputs),):
        raise InputDataError(f"u_eq: expected {len(system.inputs)} values (one per input), got {u.size}")
    return u


def _operating_point(system, x_eq, u_eq):
    """``(x_eq, u_eq)`` with an :class:`~phs.equilibria.EquilibriumResult` unpacked into its state and input
    (checked to be one of ``system``'s; a ``u_eq`` given as well must be the equilibrium's)."""
    from phs.equilibria import EquilibriumResult

    if not isinstance(x_eq, EquilibriumResult):
        return x_eq, u_eq
    eq = x_eq
    if tuple(eq.state_names) != tuple(system.state_names):
        raise InputDataError(f"x_eq: the equilibrium of {eq.system_name!r} has states {', '.join(eq.state_names)}; "
                             f"{system.name!r} has {', '.join(system.state_names)}")
    u = np.asarray(eq.u, dtype=float).reshape(-1)
    if u_eq is not None:
        given = _input_vector(system, u_eq)
        if given.shape != u.shape or not np.allclose(given, u, rtol=1e-12, atol=0.0):
            raise InputDataError(f"u_eq {dict(zip(system.input_names, map(float, given)))} differs from the input of the "
                                 f"equilibrium given as x_eq ({dict(zip(system.input_names, map(float, u)))}): give one of them")
    return np.asarray(eq.x, dtype=float), u


def _output_parts(system, outputs: str):
    if outputs not in _OUTPUTS:
        raise InputDataError(f"outputs={outputs!r}: expected one of {', '.join(_OUTPUTS)}")
    if outputs == "measured" and not system.measured:
        outputs = "port"
    port = outputs in ("port", "all")
    measured = outputs in ("measured", "all")
    names = ([i.output for i in system.inputs] if port else []) + (system.measured_names if measured else [])
    return port, measured, names


def casimir_directions(system, x_eq=None, params=None) -> np.ndarray:
    """Rows spanning the left null space of ``[J - R, G - P]`` at ``x_eq`` (conserved directions).

    Each row ``w`` (unit length in the states scaled by their typical values, expressed back in
    physical states) satisfies ``w^T x' = 0`` at ``x_eq`` for every input: a structurally constant
    combination of the states.

    Parameters
    ----------
    system : PHSystem
    x_eq : dict, array or EquilibriumResult, optional
        State (default: the declared rest state).
    params : dict, optional
        Parameter overrides by name.

    Returns
    -------
    numpy.ndarray
        Shape ``(k, n)``: one row per conserved direction (``k`` may be 0).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> casimir_directions(mass_spring_damper()).shape
    (0, 2)
    """
    from codegen.functions import generate
    from codegen.idapbc.model import state_vector
    from codegen.passivity.local import _conserved

    f = generate(system)
    sx = f.sx
    x = state_vector(system, _operating_point(system, x_eq, None)[0], "x_eq")
    p = system.param_vector(params)
    M = ca.Function("M", [sx["x"], sx["p"]], [ca.horzcat(sx["J"] - sx["R"], sx["G"] - sx["P"])])
    Mv = np.asarray(M(x, p), dtype=float).reshape(len(x), -1)
    s = np.array([st.typical for st in system.states])
    W = _conserved(Mv, s)  # orthonormal columns in scaled states
    rows = (W / s[:, None]).T  # w^T x' = (W/s)^T x' in physical states
    if not rows.size:
        return rows.reshape(0, len(x))
    rows = rows / np.linalg.norm(rows, axis=1, keepdims=True)
    rows[np.abs(rows) < 1e-12] = 0.0  # round-off of the null-space basis
    return rows


def linearize(system, x_eq=None, u_eq=None, params=None, outputs: str = "measured") -> LinearizationResult:
    """The linearisation of ``system`` at ``(x_eq, u_eq)`` as a named ``control.StateSpace``.

    Parameters
    ----------
    system : PHSystem
        The model.
    x_eq : dict, array or EquilibriumResult, optional
        Operating state, ``{name: value}`` (other states at their rest value) or one value per
        state; default: the declared rest state.  It need not be an equilibrium (the constant
        term ``x'(x_eq, u_eq)`` is then dropped, as in ``control.linearize``).  An
        :class:`~phs.equilibria.EquilibriumResult` (from :func:`phs.equilibrium`) gives the state and the input.
    u_eq : dict or array, optional
        Operating input (default 0, or the input of an equilibrium given as ``x_eq``; given with one, it
        must be the same).
    params : dict, optional
        Parameter overrides by name.
    outputs : {"measured", "port", "all"}
        The outputs of the linearisation: the measured outputs (default; the port outputs when
        the model has none), the power-conjugate port outputs ``y``, or both (port first).

    Returns
    -------
    LinearizationResult
        A ``control.StateSpace`` with named states (``ss.state_labels``), inputs and outputs (a ``.`` written ``__``),
        in physical units; its attribute ``casimirs`` holds :func:`casimir_directions` at ``x_eq`` (rows over the
        states), ``x_eq`` and ``u_eq`` the operating point by name.

    Raises
    ------
    InputDataError
        For an unknown state or input, a vector of the wrong length, an unknown ``outputs``, an equilibrium of
        another system or a ``u_eq`` that differs from the equilibrium's input.
    ParameterError
        For an unknown parameter or a value of the wrong sign.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> ss = linearize(mass_spring_damper())
    >>> ss.state_labels, ss.input_labels, ss.output_labels
    (['m.p', 'k.l'], ['F'], ['position'])
    >>> ss.A
    array([[-0.4, -4. ],
           [ 1. ,  0. ]])
    >>> ss.casimirs.shape
    (0, 2)

    At an equilibrium found by :func:`phs.equilibrium` (its input is used):

    >>> from phs import equilibrium
    >>> msd = mass_spring_damper()
    >>> linearize(msd, equilibrium(msd, u={"F": 2.0})).u_eq
    {'F': 2.0}
    """
    from codegen._linearization import LinearizationResult
    from codegen.functions import generate
    from codegen.idapbc.model import state_vector

    x_eq, u_eq = _operating_point(system, x_eq, u_eq)
    f = generate(system)
    sx = f.sx
    x = state_vector(system, x_eq, "x_eq")
    u = _input_vector(system, u_eq)
    p = system.param_vector(params)
    port, measured, out_names = _output_parts(system, outputs)
    ys = ca.vertcat(*([sx["y"]] if port else []), *([sx["measured"]] if measured else []))
    if ys.shape[1] == 0:
        ys = ca.SX(0, 1)
    jac = ca.Function("lin", [sx["x"], sx["u"], sx["p"]],
                      [ca.jacobian(sx["xdot"], sx["x"]), ca.jacobian(sx["xdot"], sx["u"]),
                       ca.jacobian(ys, sx["x"]), ca.jacobian(ys, sx["u"])])
    n, m, q = len(x), len(u), len(out_names)
    A, B, C, D = (np.asarray(v, dtype=float) for v in jac(x, u, p))
    A, B, C, D = A.reshape(n, n), B.reshape(n, m), C.reshape(q, n), D.reshape(q, m)
    if not all(np.all(np.isfinite(M)) for M in (A, B, C, D)):
        raise InputDataError(f"linearize: the Jacobians of {system.name!r} are not finite at x_eq "
                             f"({dict(zip(system.state_names, map(float, x)))})")
    ss = LinearizationResult(A, B, C, D, states=list(system.state_names), inputs=[c_identifier(n) for n in system.input_names],
                             outputs=[c_identifier(n) for n in out_names], name=system.name)
    ss.casimirs = casimir_directions(system, x, params)
    ss.x_eq = dict(zip(system.state_names, map(float, x)))
    ss.u_eq = dict(zip(system.input_names, map(float, u)))
    return ss
