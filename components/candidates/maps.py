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
    A conductance ``g`` on a state's effort ``e`` that rises with the heat it releases:
    ``G = g (1 + u)``, ``u = s z / E``, with one new state ``z`` (the heat released and not yet relaxed,
    [J]) obeying ``ż = G e² − z/τ`` — the structure of a resistor whose conductance rises with its
    temperature, ``z = C_th ΔT``.  Written port-Hamiltonian: ``R[i, i] += g`` (the base loss ``g e²``
    leaves the model at once), ``J[z, i] = g (1 + a) e = −J[i, z]`` (a power-conserving coupling),
    ``R[z, z] = E (1 + a) / (s τ)`` and the storage ``H_z = (E/s) (a − ln(1 + a) − c₀)`` with
    ``a = √(u² + δ²)`` (``δ`` = 1e-6, ``c₀`` making ``H_z(0) = 0``): its effort is
    ``∂H_z/∂z = u / (1 + a)``, so the state loses ``g (1 + a) e · u/(1 + a) = g u e²`` — the
    conductance's rise — into the heat store, and ``ż = g (1 + a) e² − z/τ``.  ``J`` stays skew, ``R``
    positive semi-definite (``a ≥ 0``), ``H_z ≥ 0`` (``a − ln(1 + a)`` grows from its minimum at
    ``a = δ``): passive by construction.  From ``z(0) = 0``, ``z ≥ 0``: the conductance only rises.

Examples
--------
>>> import sympy as sp
>>> from systems.examples import rc_circuit
>>> s = scale_input(rc_circuit(), "U", sp.Float(0.5), [], "half")
>>> s.check().ok, s.G.T * 2 == rc_circuit().G.T
(True, True)
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import sympy as sp

from components.candidates.base import _add_states, _rebuild
from phs.params import EnergyTerm, Param, StateInfo

if TYPE_CHECKING:
    from phs.system import PHSystem


DELTA = 1e-6
"""Smoothing of ``|u|`` in a heat store (``a = √(u² + δ²)``): the conductance's rise is exact, the heat's
drive ``g (1 + a) e²`` exceeds ``g (1 + u) e²`` by at most ``δ g e²``."""


def scale_input(system, input_name: str, gain: sp.Expr, params, effect: str) -> PHSystem:
    """``system`` whose input ``input_name`` reaches the model through the gain ``gain`` (an expression of
    the states and parameters): a modulated transformer between the source and the port (see the module).

    Examples
    --------
    >>> import sympy as sp
    >>> from systems.examples import mass_spring_damper
    >>> s = mass_spring_damper()
    >>> q = s.states[s.state_names.index("k.l")].symbol
    >>> gain = 1 - (q / 0.1)**2  # falls with the spring's extension (0.1 m: a scale without a declared unit)
    >>> t = scale_input(s, "F", gain, [], "gain")
    >>> sp.simplify(t.G[1, 0] - gain * s.G[1, 0])
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


def correct_measured(system, output: str, correction: sp.Expr, params, effect: str) -> PHSystem:
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
    measured[k] = replace(mo, expr=mo.expr + correction)
    return _rebuild(system, measured=measured, params=params, effect=effect)


def add_heated_dissipation(system, state: str, conductance: sp.Expr, heat: StateInfo, sensitivity: Param, tau: Param, energy: sp.Expr,
                           params, effect: str, label: str = "") -> PHSystem:
    """``system`` with a dissipation ``conductance`` (``g``) on ``state``'s effort that rises with the heat
    it releases: the new state ``heat`` (see the module), of sensitivity ``sensitivity`` (``s``),
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
    s_, E = sensitivity.symbol, energy
    u = s_ * heat.symbol / E
    a = sp.sqrt(u**2 + sp.Float(DELTA) ** 2)
    c0 = sp.Float(DELTA - math.log1p(DELTA))
    J = sp.zeros(n + 1, n + 1)
    R = sp.zeros(n + 1, n + 1)
    J[n, i], J[i, n] = conductance * (1 + a) * e, -conductance * (1 + a) * e
    R[i, i] = conductance
    relax = E * (1 + a) / (s_ * tau.symbol)
    R[n, n] = relax
    H = EnergyTerm(f"{label}:heat", E / s_ * (a - sp.log(1 + a) - c0))
    diss = [(label, {(i, i): conductance}), (f"{label}:heat", {(n, n): relax})]
    return _add_states(system, [heat], [H], J, R, params, diss, effect)
