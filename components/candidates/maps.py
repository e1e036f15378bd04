"""Building blocks that change a model's ports, its sensors, or give a dissipation a memory — each keeping
it port-Hamiltonian.

:func:`scale_input`
    A state-dependent gain ``κ(x)`` on an input: the model receives ``κ(x) u``.  Written as a modulated
    transformer between the source and the port, ``G → κG``, ``P → κP``, ``S → κ²S``, ``N → κ²N``, so
    the port output becomes ``κ(x)`` times the old one and ``yᵀu`` is the power the old port received:
    the dissipation matrix ``[[R, P], [Pᵀ, S]]`` becomes ``D [[R, P], [Pᵀ, S]] D`` with
    ``D = diag(1, …, κ, …)`` — positive semi-definite whenever it was, for any ``κ``.
:func:`correct_measured`
    An additive correction ``y_m + h(x)`` of a measured output: a sensor's reading, not a power port;
    ``J``, ``R``, ``H`` and the port outputs are unchanged.
:func:`add_heated_dissipation`
    A conductance ``g`` on a state's effort ``e`` whose value rises with the heat it has dissipated: one
    new storage ``z`` (the heat, [J]) with ``H_z = s z² / (2 E)``, so its effort ``T = s z / E`` is the
    relative rise of the conductance.  ``R[i, i] += g`` (the base dissipation, ``g e²`` leaves the model),
    ``J[z, i] = g e = −J[i, z]`` (a power-conserving coupling: ``ż`` gains the base dissipated power
    ``g e²`` while the state loses ``g T e`` — the network sees the conductance ``g (1 + T)`` and the
    extra power ``g T e²`` is stored in ``z``, never created), ``R[z, z] = E / (s τ)`` (``z`` relaxes as
    ``ż = g e² − z/τ``).  ``J`` stays skew, ``R`` positive semi-definite, ``H_z ≥ 0``: passive by
    construction.  From ``z(0) = 0``, ``z ≥ 0`` and ``T ≥ 0``: the conductance can only rise.

Examples
--------
>>> import sympy as sp
>>> from systems.examples import rc_circuit
>>> s = scale_input(rc_circuit(), "U", sp.Float(0.5), [], "half")
>>> s.check().ok, s.G.T * 2 == rc_circuit().G.T
(True, True)
"""

from __future__ import annotations

import sympy as sp

from components.candidates.base import _add_states, _rebuild
from phs.params import EnergyTerm, Measured, Param, StateInfo


def scale_input(system, input_name: str, gain: sp.Expr, params, effect: str):
    """``system`` whose input ``input_name`` reaches the model through the gain ``gain`` (an expression of
    the states and parameters): a modulated transformer between the source and the port (see the module).

    Examples
    --------
    >>> import sympy as sp
    >>> from systems.examples import mass_spring_damper
    >>> s = mass_spring_damper()
    >>> q = s.states[s.state_names.index("k.l")].symbol
    >>> t = scale_input(s, "F", 1 - q**2, [], "gain")
    >>> sp.simplify(t.G[1, 0] - (1 - q**2) * s.G[1, 0])
    0
    """
    n, j = len(system.states), system.input_names.index(input_name)
    G, P, S, N = (sp.Matrix(M) for M in (system.G, system.P, system.S, system.N))
    G[:, j] = G[:, j] * gain
    P[:, j] = P[:, j] * gain
    for M in (S, N):
        M[:, j] = M[:, j] * gain
        M[j, :] = M[j, :] * gain
    col = n + j  # the input's index in the dissipators' variables [∇H; u]
    diss = [(lab, {(a, b): v * (gain if a == col else 1) * (gain if b == col else 1) for (a, b), v in ent.items()})
            for lab, ent in system.dissipators]
    return _rebuild(system, G=G, P=P, S=S, N=N, params=params, dissipators=diss, effect=effect)


def correct_measured(system, output: str, correction: sp.Expr, params, effect: str):
    """``system`` whose measured output ``output`` reads ``y_m + correction`` (a sensor's error; the
    power ports are unchanged).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> s = mass_spring_damper()
    >>> q = s.states[s.state_names.index("k.l")].symbol
    >>> correct_measured(s, "position", 0.1 * q**2, [], "curvature").measured[0].expr == s.measured[0].expr + 0.1 * q**2
    True
    """
    k = system.measured_names.index(output)
    measured = list(system.measured)
    mo = measured[k]
    measured[k] = Measured(mo.name, mo.expr + correction, mo.unit, mo.description)
    return _rebuild(system, measured=measured, params=params, effect=effect)


def add_heated_dissipation(system, state: str, conductance: sp.Expr, heat: StateInfo, sensitivity: Param, tau: Param, energy: sp.Expr,
                           params, effect: str, label: str = ""):
    """``system`` with a dissipation ``conductance`` on ``state``'s effort that rises with the heat it
    dissipates: the new storage ``heat`` (see the module), of sensitivity ``sensitivity`` (``s``),
    relaxation time ``tau`` and energy scale ``energy`` (``E``); ``params`` are the new parameters.

    Returns
    -------
    PHSystem
        With the heat appended as the last state (start it at 0).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> from phs import Param
    >>> s_, tau = Param("s", 1.0, "1", "sensitivity"), Param("tau", 0.1, "s", "relaxation time")
    >>> g, E = Param("g", 1e-6, "S", "conductance"), Param("E", 1e-3, "J", "energy scale")
    >>> z = StateInfo("heat", "J", (-1.0, 1.0), "heat of the leak", scale=1e-3)
    >>> h = add_heated_dissipation(rc_circuit(), "C.Q", g.symbol, z, s_, tau, E.symbol, [g, E, s_, tau], "heat")
    >>> h.state_names[-1], h.check().ok
    ('heat', True)
    """
    n = len(system.states)
    i = system.state_names.index(state)
    e = system.grad_H[i]
    label = label or f"{effect}@{state}"
    J = sp.zeros(n + 1, n + 1)
    R = sp.zeros(n + 1, n + 1)
    J[n, i], J[i, n] = conductance * e, -conductance * e
    R[i, i] = conductance
    relax = energy / (sensitivity.symbol * tau.symbol)
    R[n, n] = relax
    H = EnergyTerm(f"{label}:heat", sensitivity.symbol * heat.symbol**2 / (2 * energy))
    diss = [(label, {(i, i): conductance}), (f"{label}:heat", {(n, n): relax})]
    return _add_states(system, [heat], [H], J, R, params, diss, effect)
