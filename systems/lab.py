"""Models of three laboratory set-ups with public recordings (``../shared/data``), written as a user
would write them for a first fit: the textbook physics, nothing about the effects the recordings are
known to contain.  They are the nominal models of the diagnosis demonstrations
(``docs/workflows/diagnose.md``); each is a port-Hamiltonian system given by its matrices.

- :func:`cascaded_tanks`: two water tanks, the upper draining into the lower, Torricelli outflow
  (Schoukens, Mattsson, Wigren, Noël, 2016 benchmark).
- :func:`air_chamber`: a closed, charged compressed-air chamber (isothermal, rigid).
- :func:`seal_friction_rig`: a pneumatic piston pushed through its stroke by a drive while the
  chamber pressure acts on it and a load cell measures the rod force; viscous seal friction.
"""

from __future__ import annotations

import sympy as sp

from phs import Condition, InputInfo, Measured, Param, PHSystem, StateInfo
from phs.params import EnergyTerm


def _smooth_sqrt(level: sp.Expr, eps: float) -> sp.Expr:
    """``sqrt(level)`` for ``level >> eps``, linear through zero (``level / sqrt(eps)``) near it: the
    Torricelli law without the infinite slope of the square root at an empty tank."""
    return level / (level**2 + eps**2) ** sp.Rational(1, 4)


def cascaded_tanks(k1: float = 0.05, k2: float = 0.05, k4: float = 0.05, h0: float = 20.0, eps: float = 0.05) -> PHSystem:
    """Two tanks, the upper one draining into the lower one, filled by a pump (Torricelli outflow).

    States ``V1``, ``V2``: stored volumes [m³] of tanks of unit cross-section (the level equals the
    volume); the levels are in the units of the benchmark's level sensor (volts read as metres).
    Energy ``H = ρg (V1²/2 + h0 V1 + V2²/2)``: the upper tank's outlet lies ``h0`` above the lower
    tank's bottom, so the water falling between them gives up potential energy, which is the power
    the first orifice dissipates.  Outflows ``q1 = k1 √V1`` (into the lower tank) and
    ``q2 = k2 √V2`` (to the reservoir), written with the smoothed root of :func:`_smooth_sqrt`; the
    pump delivers ``k4 u`` for a pump voltage ``u`` [V].  Measured: ``level2`` (the lower tank).

    ``(J − R) ∇H`` reproduces ``V̇1 = −q1 + k4 u``, ``V̇2 = q1 − q2`` with ``R`` symmetric positive
    semidefinite while the lower tank's level stays below ``h0`` above the upper one's (a validity
    condition of the model).  No level limit: the tanks never overflow.

    Examples
    --------
    >>> s = cascaded_tanks()
    >>> s.state_names, s.input_names, [m.name for m in s.measured]
    (['V1', 'V2'], ['u'], ['level2'])
    >>> import sympy as sp
    >>> at = {s.states[0].symbol: 4.0, s.states[1].symbol: 2.0, s.inputs[0].symbol: 0.0}
    >>> at.update({p.symbol: p.value for p in s.params})
    >>> round(float(s.dynamics.subs(at)[1]), 4)   # q1 - q2 = 0.05 (2 - sqrt 2), smoothed
    0.0293
    """
    V1, V2 = sp.symbols("V1 V2", real=True)
    pk1 = Param("k1", k1, "m**2.5/s", "upper tank's outflow coefficient (Torricelli)", range=(1e-4, 1.0))
    pk2 = Param("k2", k2, "m**2.5/s", "lower tank's outflow coefficient (Torricelli)", range=(1e-4, 1.0))
    pk4 = Param("k4", k4, "m**3/(s*V)", "pump flow per volt", range=(1e-4, 1.0))
    ph0 = Param("h0", h0, "m", "height of the upper tank's outlet above the lower tank's bottom", range=(1.0, 100.0))
    rg = Param("rho_g", 9810.0, "N/m**3", "specific weight of water", range=(9000.0, 11000.0))
    a, b, c, h, w = pk1.symbol, pk2.symbol, pk4.symbol, ph0.symbol, rg.symbol
    q1 = a * _smooth_sqrt(V1, eps)  # the lower outflow q2 = b √V2 enters through g2 = q2 / e2 below
    head = V1 + h - V2  # (e1 - e2) / (rho g): the drop across the first orifice
    g1 = q1 / (w * head)  # conductance of the first orifice
    g2 = b / (w * (V2**2 + eps**2) ** sp.Rational(1, 4))  # q2 / e2
    R = sp.Matrix([[g1, -g1], [-g1, g1 + g2]])
    states = [StateInfo("V1", "m**3", (-0.5, 40.0), "water in the upper tank (level, sensor units)", "C", 5.0, "tank1"),
              StateInfo("V2", "m**3", (-0.5, 40.0), "water in the lower tank (level, sensor units)", "C", 5.0, "tank2")]
    H = [EnergyTerm("tank1", w * (V1**2 / 2 + h * V1)), EnergyTerm("tank2", w * V2**2 / 2)]
    return PHSystem(
        "cascaded_tanks", states, H, sp.zeros(2, 2), R, sp.Matrix([[c], [0]]),
        inputs=[InputInfo("u", "V", "u.y", "m**3*Pa/(s*V)", "effort", "pump voltage", (0.0, 10.0))],
        params=[pk1, pk2, pk4, ph0, rg],
        measured=[Measured("level2", V2, "m", "level of the lower tank (sensor units)")],
        conditions=[Condition("lower tank below the upper outlet", head - 0.5,
                              "the lower tank's level stays below the upper tank's outlet")],
        dissipators=[("orifice1", {(0, 0): g1, (0, 1): -g1, (1, 1): g1}), ("orifice2", {(1, 1): g2})],
        description="cascaded tanks with Torricelli outflow, no overflow",
    )


def air_chamber(C: float = 5e-7) -> PHSystem:
    """A closed compressed-air chamber (rigid, isothermal), linearised about atmospheric pressure.

    State ``V_a`` [m³]: the air it holds beyond atmospheric content, as a volume at atmospheric
    pressure; gauge pressure ``p = V_a / C`` with the pneumatic capacitance ``C = V / p_atm``
    (isothermal ideal gas in the chamber volume ``V``); energy ``H = V_a² / (2 C)``.  A supply port
    ``q`` [m³/s] (a flow input, zero while the chamber is held).  Measured: ``pressure`` [Pa gauge].
    Nominal: no leak — the pressure holds.

    Examples
    --------
    >>> s = air_chamber()
    >>> s.state_names, s.input_names, s.R
    (['V_a'], ['q'], Matrix([[0]]))
    """
    Va = sp.Symbol("V_a", real=True)
    pc = Param("C", C, "m**3/Pa", "pneumatic capacitance V / p_atm", range=(1e-10, 1e-3))
    # gauge pressures from -1 to 20 bar
    st = StateInfo("V_a", "m**3", (-C * 1e5, C * 2e6), "air held beyond atmospheric content (volume at p_atm)", "C",
                   C * 7e5, "chamber")
    return PHSystem(
        "air_chamber", [st], [EnergyTerm("chamber", Va**2 / (2 * pc.symbol))], sp.zeros(1, 1), sp.zeros(1, 1),
        sp.Matrix([[1]]), inputs=[InputInfo("q", "m**3/s", "q.p", "Pa", "flow", "supply flow", (-1e-3, 1e-3))],
        params=[pc], measured=[Measured("pressure", Va / pc.symbol, "Pa", "gauge pressure")],
        description="closed air chamber, no leak",
    )


def seal_friction_rig(m: float = 0.5, A: float = 5.3e-4, k: float = 2e5, b: float = 1500.0) -> PHSystem:
    """A pneumatic piston driven through its stroke by a position-controlled drive, with the chamber
    pressure acting on it and a load cell between drive and rod (viscous seal friction).

    States: ``q`` [m] the load cell's (coupling's) compression, ``p`` [kg m/s] the piston's momentum.
    Inputs: ``P`` [Pa] the chamber pressure (force ``A P`` on the piston) and ``v`` [m/s] the drive's
    velocity, both positive in the direction of extension.  ``q̇ = p/m − v``,
    ``ṗ = A P − k q − b p/m``: a mass between an effort source and a stiff spring, with a viscous
    seal (``b``).  Measured: ``force = k q`` [N] (the rod force the load cell reads).  Quasi-static
    at the drive's speeds: ``force ≈ A P − b v``.

    Examples
    --------
    >>> s = seal_friction_rig()
    >>> s.state_names, s.input_names
    (['q', 'p'], ['P', 'v'])
    """
    q, p = sp.symbols("q p", real=True)
    pm = Param("m", m, "kg", "moving mass (piston and rod)", range=(0.01, 10.0))
    pA = Param("A", A, "m**2", "piston area", range=(1e-5, 1e-2))
    pk = Param("k", k, "N/m", "load cell and coupling stiffness", range=(1e3, 1e8))
    pb = Param("b", b, "N*s/m", "viscous seal friction", range=(1.0, 1e5))
    M, Ar, K, B = pm.symbol, pA.symbol, pk.symbol, pb.symbol
    states = [StateInfo("q", "m", (-5e-3, 5e-3), "compression of the load cell and coupling", "C", 2e-3, "cell"),
              StateInfo("p", "kg*m/s", (-1.0, 1.0), "momentum of piston and rod", "I", 0.01, "piston")]
    H = [EnergyTerm("cell", K * q**2 / 2), EnergyTerm("piston", p**2 / (2 * M))]
    return PHSystem(
        "seal_friction_rig", states, H, sp.Matrix([[0, 1], [-1, 0]]), sp.Matrix([[0, 0], [0, B]]),
        sp.Matrix([[0, -1], [Ar, 0]]),
        inputs=[InputInfo("P", "Pa", "P.Q", "m**3/s", "effort", "chamber pressure", (-1e6, 2e6)),
                InputInfo("v", "m/s", "v.F", "N", "flow", "drive velocity", (-1.0, 1.0))],
        params=[pm, pA, pk, pb], measured=[Measured("force", K * q, "N", "rod force (load cell)")],
        dissipators=[("seal", {(1, 1): B})],
        description="pneumatic piston, drive and load cell; viscous seal",
    )
