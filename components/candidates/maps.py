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


def add_mode(system, body: str, mass_ratio: sp.Expr, frequency: sp.Expr, damping_ratio: sp.Expr, mass: sp.Expr,
             deflection: StateInfo, momentum: StateInfo, params, effect: str, label: str = "") -> PHSystem:
    """``system`` with a second mass ``μ m`` joined to the body of momentum ``body`` by a spring and a
    damper: one more mechanical mode (a flexible part, a payload on a compliant mount).

    ``mass`` is the body's mass scale ``m``, ``mass_ratio`` ``μ``, ``frequency`` the mode's natural
    frequency ``f`` [Hz] and ``damping_ratio`` ``ζ``; ``ω = 2πf``.  Two new states: ``deflection`` ``δ``
    (the mode's position relative to the body) and ``momentum`` ``w = p_a/μ`` (the mode's momentum per unit
    mass ratio, so its scale is the body's own whatever ``μ``), with

    ``H += μ m ω² δ²/2 + μ w²/(2m)``, ``J[δ, w] = 1/μ``, ``J[δ, p] = −1`` (``δ̇ = v_a − v``),
    ``R = c vvᵀ`` on ``(p, w)`` with ``v = (1, −1/μ)`` and ``c = 2ζωμm`` (the damper on the relative
    velocity ``v_a − v``).  ``J`` stays skew and ``R`` positive semi-definite; the mode's energy is a
    positive quadratic: passive by construction.  ``μ → 0`` is the model without the mode (its force
    ``μ m (ω² δ + 2ζω(v_a − v))`` on the body vanishes while ``δ`` and ``w`` stay bounded).

    Returns
    -------
    PHSystem
        With ``deflection`` and ``momentum`` appended as the last two states (start them at 0: the mode at rest).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> from phs import Param
    >>> mu, f, z = Param("mu", 0.3, "1", "mass ratio"), Param("f", 5.0, "Hz", "frequency"), Param("z", 0.05, "1", "damping ratio")
    >>> d = StateInfo("mode.delta", "m", (-1.0, 1.0), "mode deflection", "C", 0.01)
    >>> w = StateInfo("mode.w", "kg*m/s", (-10.0, 10.0), "mode momentum per mass ratio", "I", 0.1)
    >>> m = Param("m_s", 1.0, "kg", "mass scale")
    >>> s = add_mode(mass_spring_damper(), "m.p", mu.symbol, f.symbol, z.symbol, m.symbol, d, w, [mu, f, z, m], "mode")
    >>> s.state_names[-2:], s.check().ok
    (['mode.delta', 'mode.w'], True)
    """
    n = len(system.states)
    i = system.state_names.index(body)
    label = label or f"{effect}@{body}"
    w_ = 2 * sp.pi * frequency
    c = 2 * damping_ratio * w_ * mass  # the damper's coefficient divided by μ
    J = sp.zeros(n + 2, n + 2)
    R = sp.zeros(n + 2, n + 2)
    J[n, n + 1], J[n + 1, n] = 1 / mass_ratio, -1 / mass_ratio
    J[n, i], J[i, n] = -1, 1
    R[i, i] = c * mass_ratio
    R[i, n + 1] = R[n + 1, i] = -c
    R[n + 1, n + 1] = c / mass_ratio
    d, w = deflection.symbol, momentum.symbol
    H = [EnergyTerm(f"{label}:spring", mass_ratio * mass * w_**2 * d**2 / 2), EnergyTerm(f"{label}:mass", mass_ratio * w**2 / (2 * mass))]
    diss = [(label, {(i, i): c * mass_ratio, (i, n + 1): -c, (n + 1, n + 1): c / mass_ratio})]
    return _add_states(system, [deflection, momentum], H, J, R, params, diss, effect)


def add_clock(system, clock: StateInfo, tau: sp.Expr, energy: sp.Expr, params, effect: str, label: str = "") -> PHSystem:
    """``system`` with a slow state ``s`` (``clock``) that relaxes from 0 towards 1 with time constant
    ``tau``: the drift of whatever the caller then scales by ``s`` (a stiffness heating up, a drive
    weakening), so a drifting parameter is a state of the model, not a function of time.

    ``H += E (s − 1)²/2`` with ``E`` = ``energy`` and ``R[s, s] = 1/(τ E)``: ``ṡ = (1 − s)/τ`` minus
    the derivative of whatever energy the caller makes depend on ``s``, over ``τE`` (negligible when
    ``E`` is large against it).  The clock releases the energy ``E/2`` it holds at ``s = 0``; ``R ⪰ 0`` and
    the energy is bounded below: passive by construction.

    Returns
    -------
    PHSystem
        With ``clock`` appended as the last state (start it at 0).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> from phs import Param
    >>> tau, E = Param("tau", 5.0, "s", "drift time constant"), Param("E", 1.0, "J", "energy scale")
    >>> clock = StateInfo("clock", "1", (-0.5, 1.5), "drift", "C", 1.0)
    >>> s = add_clock(rc_circuit(), clock, tau.symbol, E.symbol, [tau, E], "drift")
    >>> s.state_names[-1], s.check().ok
    ('clock', True)
    """
    n = len(system.states)
    label = label or f"{effect}@{clock.name}"
    J = sp.zeros(n + 1, n + 1)
    R = sp.zeros(n + 1, n + 1)
    R[n, n] = 1 / (tau * energy)
    H = [EnergyTerm(label, energy * (clock.symbol - 1) ** 2 / 2)]
    return _add_states(system, [clock], H, J, R, params, [(label, {(n, n): R[n, n]})], effect)


def limit_input_current(system, input_name: str, limit: sp.Expr, knee: sp.Expr, capacitance: sp.Expr, charge: StateInfo, params,
                        effect: str) -> PHSystem:
    """``system`` whose effort input ``input_name`` delivers at most ``limit`` of its conjugate flow (a
    drive's current limit): an element in series with the source whose conductance passes the flow
    ``i = I tanh(e/e_k)`` at the voltage ``e`` across it (``I`` = ``limit``, ``e_k`` = ``knee``), with a
    capacitance ``capacitance`` across it holding the charge ``charge`` (its voltage ``e = Q/C``).

    Below the limit the element is a resistance ``e_k / I`` (small when the knee is small); near it the
    voltage across it rises until the flow the model draws is the limit.  The conductance
    ``I tanh(e/e_k)/e`` is positive, so ``R ⪰ 0``: passive by construction; ``I → ∞`` shorts it (the model
    without the limit).  Built with the same series connection as a retention branch at an input
    (``Q̇ = y − G(e) e``, the model seeing ``u − e``).

    Returns
    -------
    PHSystem
        With ``charge`` appended as the last state (start it at 0).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> from phs import Param
    >>> I = Param("I_max", 1e-3, "A", "current limit")
    >>> q = StateInfo("lim.Q", "C", (-1.0, 1.0), "charge across the limiter", "C", 1e-9)
    >>> knee, C = Param("e_k", 0.01, "V", "knee voltage"), Param("C_l", 1e-7, "F", "capacitance across the limiter")
    >>> s = limit_input_current(rc_circuit(), "U", I.symbol, knee.symbol, C.symbol, q, [I, knee, C], "limit")
    >>> s.state_names[-1], s.check().ok
    ('lim.Q', True)
    """
    from components.candidates.electrical import _series_with_input

    j = system.input_names.index(input_name)
    e = charge.symbol / capacitance
    conductance = limit / knee * _tanh_over(e / knee)
    return _series_with_input(system, j, charge, charge.symbol**2 / (2 * capacitance), conductance, params, effect)


def _tanh_over(x: sp.Expr) -> sp.Expr:
    """``tanh(x)/x`` without its removable singularity at 0: ``(x tanh x + ε²)/(x² + ε²)`` (``ε`` = 1e-6),
    a ratio whose denominator never vanishes, equal to 1 at 0, positive everywhere, and within 1e-12 of
    ``tanh(x)/x`` for ``|x| ≥ 1e-3``."""
    eps2 = sp.Float(1e-12)
    return (sp.tanh(x) * x + eps2) / (x**2 + eps2)
