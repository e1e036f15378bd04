"""A rigid-soft swimmer driven by an antagonistic pair of Peano-HASELs.

Source: Michelis, Gravert, Katzschmann, "Modeling and simulation of rigid-soft hybrid
HASEL-actuated robotic swimmers" (eqs. 1-3, Figs. 1-5, Discussion).  Built only from
:mod:`components` and :func:`phs.interconnect`.  The paper models the swimmer with FEM
(DiffPD, COMSOL); this is a reduced model with the same actuation law: a rigid head that
moves forward, a rigid tail fin hinged to it by a compliant spine, and two Peano-HASELs
spanning the hinge on either side.

Symbols (paper -> model): ``F(eps)`` the force-strain law (eq. 3, component
:class:`components.PeanoHasel`), the bending angle ``theta`` of the paper's markers ->
tail angle ``phi`` (state, rad); head forward velocity ``U`` (measured output).

Equations as implemented (states ``phi``, ``tail.p``, ``body.p``, ``left.Q``, ``right.Q``;
inputs ``V_L``, ``V_R`` [V])::

    s_L = s_n + r phi / L0,  s_R = s_n - r phi / L0          contraction strains of the pair
    H = p_t**2 / (2 I) + p_x**2 / (2 M) + K_s phi**2 / 2
        + Q_L**2 / (2 C(s_L)) + Q_R**2 / (2 C(s_R))          (eq. 3 through C(s), see PeanoHasel)
        + H_film(-L0 s_L) + H_film(-L0 s_R)                  (resistance of the stretched actuator)
    I = I_t + m_a L_t**3 / 3,  M = m_b + m_ax,  m_a = pi rho h**2 / 4     (added mass of the fin)
    omega = p_t / I,  U = p_x / M
    phi'  = omega
    p_t'  = -dH/dphi - (b_s + b_v + b_w) omega - k_T omega U
    p_x'  = k_T omega**2 - (b_D + b_L) U
    Q_k'  = (V_k - Q_k / C(s_k)) / R_s

with the dissipation coefficients (all >= 0, so R is positive semidefinite)::

    b_v = r**2 c_v ((Q_L / Q_ref)**2 + (Q_R / Q_ref)**2)     velocity-dependent actuator force,
                                                            Q_ref = C(s_n) V_ref (full activation at rest)
    b_w = rho C_n h L_t**4 |omega|~ / 8                      quadratic normal drag on the fin
    b_D = rho C_D A_f |U|~ / 2                               quadratic drag on the head
    b_L = m_a phi**2 |U|~ / 2                                Lighthill's -m_a U**2 h_x**2 / 2
    |v|~ = sqrt(v**2 + v0**2)                                (smooth absolute value)

and the reactive (Lighthill) thrust ``k_T omega**2``, ``k_T = m_a L_t**2 / 2``: the
momentum the fin's added mass sheds at its trailing edge, ``m_a w**2 / 2`` with the tip's
lateral velocity ``w = L_t omega``.  It is a gyrator between the fin's rotation and the head's
surge with modulus ``k_T omega``: the power ``k_T omega**2 U`` it gives the head is taken
from the fin's rotation (torque ``-k_T omega U``), so it adds nothing to dH/dt (a skew,
state-modulated entry of J).

Choices (the paper prints no swimmer dimensions, no speeds and no units for eq. 3; each
choice is discussed in ``docs/systems/peano_swimmer.md``):

* eq. 3 is read with the strain in percent and the force in N (the only reading in which the
  fit falls to near zero, 0.63 N at 4.44 %, as eqs. 1-2 do at the end of the stroke);
* the actuators are not taut at rest (``s_n = 2.2 %``, as the authors observe); the
  stretched actuator resists only once it is longer than its flat length (film taut);
* the velocity dependence is a damping of the actuator's contraction proportional to its
  activation (zero when unactuated), the simplest passive form of "less force at higher
  velocity" that the authors name as missing;
* the fluid is reduced to added mass, quadratic drag and Lighthill's reactive thrust of a
  rigid pitching fin, without recoil (the head does not heave or yaw);
* ``law="eq12"`` drives the pair by the alpha-parametric eqs. 1-2 instead of eq. 3, with
  coefficients ``a1, a2, a3`` fitted to eq. 3 (the paper prints none; within 16.5 % of eq. 3
  over 0.25-4 % strain, see :class:`components.PeanoHasel`).
"""

from __future__ import annotations

import math

import sympy as sp

from components import (
    Damper,
    Geometry,
    Gyrator,
    Mass,
    PeanoHasel,
    Resistor,
    RotationalDamper,
    RotationalInertia,
    TorsionalSpring,
    VoltageSource,
    geometric_symbol,
)
from components.peano import EQ12, LAWS, eq12_angle, eq12_force
from phs import Measured, Param, PHSystem, interconnect, series, symbol_of_state
from phs.errors import ModelError
from phs.signals import Signal, square


def default_parameters() -> dict[str, Param]:
    """Parameters of :func:`peano_swimmer`: eq. 3's printed coefficients and the documented choices.

    Returns
    -------
    dict of str -> Param

    Examples
    --------
    >>> P = default_parameters()
    >>> P["b2"].value, P["L0"].unit
    (21.71, 'm')
    """
    P = [
        Param("b1", 1.0, "N", "eq. 3: linear coefficient (strain in percent)"),
        Param("b2", 21.71, "N", "eq. 3: hyperbolic coefficient"),
        Param("b3", 0.22, "1", "eq. 3: pole offset (percent strain)"),
        Param("b4", 0.39, "1", "eq. 3: offset of the hyperbola"),
        Param("a1", EQ12["a1"], "N", "eqs. 1-2: force scale (law='eq12'; fitted to eq. 3, not printed)"),
        Param("a2", EQ12["a2"], "1", "eqs. 1-2: length ratio, flat pouch at strain 1 - a2 (law='eq12'; fitted)"),
        Param("a3", EQ12["a3"], "1", "eqs. 1-2: pouch geometry 2 sqrt(A)/L (law='eq12'; fitted to eq. 3)"),
        Param("V_ref", 6000.0, "V", "voltage at which eq. 3 holds (chosen; not printed)", (1000.0, 10000.0)),
        Param("L0", 0.05, "m", "flat length of each Peano-HASEL (chosen)", (0.01, 0.2)),
        Param("C0", 1.5e-9, "F", "capacitance of an actuator at zero strain (chosen)", (1e-11, 1e-8)),
        Param("k_f", 1e5, "N/m", "stiffness of a taut actuator film in stretch (chosen)", (100.0, 1e5)),
        Param("d0", 2e-5, "m", "smoothing length of the one-sided film spring (chosen)", (1e-6, 1e-3)),
        Param("s_n", 0.025, "1", "contraction strain of both actuators at rest: not taut (chosen)", (0.0, 0.044)),
        Param("r", 0.004, "m", "moment arm of each actuator about the spine hinge (chosen)", (0.001, 0.02)),
        Param("c_v", 20.0, "N*s/m", "velocity-dependent force: damping of the contraction at full activation "
                                    "(chosen)", (0.0, 200.0)),
        Param("Q_ref", _reference_charge(), "C", "charge of an actuator at V_ref and the rest strain s_n: "
                                                "full activation of the velocity-dependent force"),
        Param("R_s", 1e6, "Ohm", "series resistance of each actuator's drive (chosen)", (1e3, 1e8)),
        Param("K_s", 0.05, "N*m/rad", "bending stiffness of the spine hinge (chosen)", (0.001, 1.0)),
        Param("b_s", 2e-4, "N*m*s/rad", "structural damping of the spine hinge (chosen)", (0.0, 1e-2)),
        Param("I_t", 6e-6, "kg*m**2", "moment of inertia of the fin about the hinge (chosen)", (1e-7, 1e-3)),
        Param("L_t", 0.06, "m", "length of the fin from the hinge to the trailing edge (chosen)", (0.01, 0.2)),
        Param("h", 0.04, "m", "height of the fin (chosen)", (0.01, 0.2)),
        Param("m_b", 0.05, "kg", "mass of the swimmer (chosen)", (0.005, 1.0)),
        Param("m_ax", 0.005, "kg", "added mass of the swimmer in surge (chosen: 10 % of m_b)", (0.0, 0.1)),
        Param("A_f", 2e-3, "m**2", "frontal area of the head (chosen)", (1e-5, 1e-2)),
        Param("C_D", 0.5, "1", "drag coefficient of the head (chosen)", (0.05, 2.0)),
        Param("C_n", 2.0, "1", "normal drag coefficient of the fin (chosen)", (0.1, 3.0)),
        Param("rho", 1000.0, "kg/m**3", "density of water", (990.0, 1030.0)),
        Param("v0", 1e-3, "m/s", "smoothing speed of |U| (chosen)", (1e-6, 1e-2)),
        Param("w0", 1e-2, "rad/s", "smoothing rate of |omega| (chosen)", (1e-6, 1e-1)),
    ]
    return {p.name: p for p in P}


def _reference_charge(s_n: float = 0.025, L0: float = 0.05, V_ref: float = 6000.0, C0: float = 1.5e-9) -> float:
    """``C(s_n) V_ref`` [C] at the default geometry (eq. 3 integrated, see :class:`components.PeanoHasel`)."""
    e = 100 * s_n
    integral = e**2 / 2 + 21.71 * math.log(1 + e / 0.22) - 21.71 * 0.39 * e
    return (C0 + 2 * L0 / (100 * V_ref**2) * integral) * V_ref


def swimmer_drive(amplitude: float, frequency: float) -> dict[str, Signal]:
    """Alternating drive of the pair: ``V_L`` on in the first half of each period, ``V_R`` in the second.

    Examples
    --------
    >>> d = swimmer_drive(6000.0, 2.0)
    >>> float(d["V_L"](0.1)), float(d["V_R"](0.1)), float(d["V_R"](0.3))
    (6000.0, 0.0, 6000.0)
    """
    return {"V_L": square(amplitude, frequency, bipolar=False),
            "V_R": square(amplitude, frequency, bipolar=False, start=0.5 / frequency)}


def peano_swimmer(*, law: str = "eq3", **overrides: float) -> PHSystem:
    """The Peano-HASEL swimmer: an antagonistic pair bending a fin that propels a head (see module docstring).

    Parameters
    ----------
    law : {"eq3", "eq12"}
        The actuators' force-strain law: eq. 3 (default) or the alpha-parametric eqs. 1-2
        (:class:`components.PeanoHasel`; the model is then named ``peano_swimmer_eq12``).
    **overrides : float
        Parameter values by name (see :func:`default_parameters`).

    Returns
    -------
    PHSystem
        States ``phi``, ``tail.p``, ``body.p``, ``left.Q``, ``right.Q``; inputs ``V_L``, ``V_R``;
        measured outputs ``U`` (forward speed, m/s), ``tip`` (lateral tip displacement, m),
        ``strain_L``, ``strain_R`` (contraction strain, %), ``force_L``, ``force_R`` (contraction
        force of each actuator, N) and ``thrust`` (reactive thrust, N).

    Raises
    ------
    ModelError
        If an override names an unknown parameter, or ``law`` is not ``"eq3"`` or ``"eq12"``.

    Examples
    --------
    >>> s = peano_swimmer()
    >>> s.state_names, s.input_names
    (['left.Q', 'right.Q', 'phi', 'tail.p', 'body.p'], ['V_L', 'V_R'])
    """
    if law not in LAWS:
        raise ModelError(f"peano_swimmer: law must be 'eq3' or 'eq12', got {law!r}")
    P = default_parameters()
    unknown = sorted(set(overrides) - set(P))
    if unknown:
        raise ModelError(f"peano_swimmer: unknown parameter(s) {unknown}; known: {sorted(P)}")
    P = {k: (p.with_value(overrides[k]) if k in overrides else p) for k, p in P.items()}
    S = {k: p.symbol for k, p in P.items()}
    phi = symbol_of_state("phi")
    p_t, p_x = symbol_of_state("tail.p"), symbol_of_state("body.p")
    m_a = sp.pi * S["rho"] * S["h"] ** 2 / 4
    inertia = S["I_t"] + m_a * S["L_t"] ** 3 / 3
    mass = S["m_b"] + S["m_ax"]
    omega, U = p_t / inertia, p_x / mass
    absU = sp.sqrt(U**2 + S["v0"] ** 2)
    absw = sp.sqrt(omega**2 + S["w0"] ** 2)
    k_T = m_a * S["L_t"] ** 2 / 2
    coefficients = {"eq3": ("b1", "b2", "b3", "b4"), "eq12": ("a1", "a2", "a3")}
    act = {k: P[k] for k in ("L0", "V_ref", "C0", "k_f", "d0") + coefficients[law]}
    arm = S["r"] * phi / S["L0"]
    pair = {"left": PeanoHasel("left", strain=S["s_n"] + arm, law=law, **act),
            "right": PeanoHasel("right", strain=S["s_n"] - arm, law=law, **act)}
    shared = pair["left"].symbols()[0]
    volts = {k: symbol_of_state(f"{k}.Q") / a.capacitance(shared) for k, a in pair.items()}
    activation = sum((symbol_of_state(f"{k}.Q") / S["Q_ref"]) ** 2 for k in pair)
    comps = [
        VoltageSource("V_L", range=(0.0, 10000.0)), VoltageSource("V_R", range=(0.0, 10000.0)),
        Resistor("R_L", R=P["R_s"]), Resistor("R_R", R=P["R_s"]), *pair.values(),
        TorsionalSpring("spine", K=P["K_s"], state="phi", range=(-0.5, 0.5)),
        RotationalInertia("tail", I=inertia, state="tail.p", range=(-1e-3, 1e-3), scale=1e-5),
        RotationalDamper("spine_damping", b=P["b_s"]),
        RotationalDamper("actuator_velocity", b=geometric_symbol("b_v")),
        RotationalDamper("fin_drag", b=geometric_symbol("b_w")),
        Mass("body", m=mass, state="body.p", range=(-0.03, 0.03), scale=1e-3),
        Damper("head_drag", b=geometric_symbol("b_D")),
        # port a on the fin's rotation, port b on the head's surge: torque -n U on the fin, force n omega on the head
        Gyrator("thrust", geometric_symbol("n_T"), domains=("rotational", "translational")),
        # state-modulated coefficients as named definitions: the junction solve keeps them atomic
        Geometry("hydro", {"b_v": S["r"] ** 2 * S["c_v"] * activation,
                           "b_w": S["rho"] * S["C_n"] * S["h"] * S["L_t"] ** 4 * absw / 8,
                           "b_D": S["rho"] * S["C_D"] * S["A_f"] * absU / 2 + m_a * phi**2 * absU / 2,
                           "n_T": k_T * omega},
                 units={"b_v": "N*m*s/rad", "b_w": "N*m*s/rad", "b_D": "N*s/m", "n_T": "N*s"}),
    ]
    conns = [series("V_L", "R_L", "left"), series("V_R", "R_R", "right"),
             series("tail", "spine", "spine_damping", "actuator_velocity", "fin_drag", "thrust.a"),
             series("body", "head_drag", "thrust.b")]
    e_L, e_R = 100 * (S["s_n"] + arm), 100 * (S["s_n"] - arm)
    if law == "eq3":
        law_force = {k: S["b1"] * e + S["b2"] * (1 / (e + S["b3"]) - S["b4"]) for k, e in (("left", e_L), ("right", e_R))}
    else:  # eq. 1 at the angle of eq. 2, zero beyond the end of the stroke (alpha = pi/2)
        law_force = {k: sp.Piecewise((eq12_force(eq12_angle(e / 100, S["a2"], S["a3"]), S["a1"]),
                                      eq12_angle(e / 100, S["a2"], S["a3"]) <= sp.pi / 2), (0, True))
                     for k, e in (("left", e_L), ("right", e_R))}
    force = {k: (volts[k] / S["V_ref"]) ** 2 * law_force[k] for k in pair}
    measured = [Measured("U", U, "m/s", "forward speed of the swimmer"),
                Measured("tip", S["L_t"] * sp.sin(phi), "m", "lateral displacement of the fin's trailing edge"),
                Measured("strain_L", e_L, "1", "contraction strain of the left actuator [%]"),
                Measured("strain_R", e_R, "1", "contraction strain of the right actuator [%]"),
                Measured("force_L", force["left"], "N", f"contraction force of the left actuator, {law} x (V/V_ref)**2"),
                Measured("force_R", force["right"], "N", f"contraction force of the right actuator, {law} x (V/V_ref)**2"),
                Measured("thrust", k_T * omega**2, "N", "reactive thrust of the fin")]
    laws = coefficients["eq3"] + coefficients["eq12"]
    used = [p for k, p in P.items() if k not in act and k not in laws and k not in ("R_s", "K_s", "b_s")]
    return interconnect("peano_swimmer" + ("" if law == "eq3" else "_eq12"), comps, conns, params=used, measured=measured,
                        description="rigid-soft swimmer driven by an antagonistic Peano-HASEL pair "
                                    "(Michelis, Gravert, Katzschmann, eq. 3), reduced hydrodynamics")
