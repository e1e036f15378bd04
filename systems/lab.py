"""Models of three laboratory set-ups with public recordings (``../shared/data``), written as a user
would write them for a first fit: the textbook physics, nothing about the effects the recordings are
known to contain.  They are the nominal models of the diagnosis demonstrations
(``docs/studies/diagnosis.md``); each is a port-Hamiltonian system given by its matrices.

- :func:`cascaded_tanks`: two water tanks, the upper draining into the lower, Torricelli outflow
  (Schoukens, Mattsson, Wigren, Noël, 2016 benchmark).
- :func:`air_chamber`: a closed, charged compressed-air chamber (isothermal, rigid).
- :func:`seal_friction_rig`: a pneumatic piston pushed through its stroke by a drive while the
  chamber pressure acts on it and a load cell measures the rod force; viscous seal friction.
- :func:`emps_stage` and :func:`emps_stage_matrices`: an electro-mechanical positioning stage (a carriage on a
  ball screw) in its cascaded position and velocity loop (EMPS benchmark, Janot, Gautier, Brunot),
  mass and viscous friction; built from components, and the same model written by hand.
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

    States ``V1``, ``V2``: stored volumes [m³] of tanks of cross-section ``A = 1 m²`` (the level
    ``V/A`` equals the volume in number); the levels are in the units of the benchmark's level
    sensor (volts read as metres).  Energy ``H = ρg (V1²/(2A) + h0 V1 + V2²/(2A))``: the upper
    tank's outlet lies ``h0`` above the lower tank's bottom, so the water falling between them gives
    up potential energy, which is the power the first orifice dissipates.  Outflows
    ``q1 = k1 √(V1/A)`` (into the lower tank) and ``q2 = k2 √(V2/A)`` (to the reservoir), written with
    the smoothed root of :func:`_smooth_sqrt`; the pump delivers ``k4 u`` for a pump voltage ``u``
    [V].  Measured: ``level2 = V2/A`` (the lower tank).  ``A`` is a parameter so that every term
    has its unit (it was once a bare 1, so that volumes in m³ were read as levels in m).

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
    pA = Param("A", 1.0, "m**2", "cross-section of each tank (levels in the sensor's units)", range=(0.5, 2.0))
    a, b, c, h, w, A = pk1.symbol, pk2.symbol, pk4.symbol, ph0.symbol, rg.symbol, pA.symbol
    L1, L2 = V1 / A, V2 / A  # the levels
    q1 = a * _smooth_sqrt(L1, eps)  # the lower outflow q2 = b √L2 enters through g2 = q2 / e2 below
    head = L1 + h - L2  # (e1 - e2) / (rho g): the drop across the first orifice
    g1 = q1 / (w * head)  # conductance of the first orifice
    g2 = b / (w * (L2**2 + eps**2) ** sp.Rational(1, 4))  # q2 / e2
    R = sp.Matrix([[g1, -g1], [-g1, g1 + g2]])
    states = [StateInfo("V1", "m**3", (-0.5, 40.0), "water in the upper tank (level, sensor units)", "C", 5.0, "tank1"),
              StateInfo("V2", "m**3", (-0.5, 40.0), "water in the lower tank (level, sensor units)", "C", 5.0, "tank2")]
    H = [EnergyTerm("tank1", w * (V1**2 / (2 * A) + h * V1)), EnergyTerm("tank2", w * V2**2 / (2 * A))]
    return PHSystem(
        "cascaded_tanks", states, H, sp.zeros(2, 2), R, sp.Matrix([[c], [0]]),
        inputs=[InputInfo("u", "V", "u.y", "m**3*Pa/(s*V)", "effort", "pump voltage", (0.0, 10.0))],
        params=[pk1, pk2, pk4, ph0, rg, pA],
        measured=[Measured("level2", L2, "m", "level of the lower tank (sensor units)")],
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


EMPS_LOOP = {"kp": 160.18, "kv": 243.45, "gtau": 35.15065188248547}
"""The EMPS stage's loop: position gain ``kp`` [1/s], velocity gain ``kv`` [V s/m] and the drive's force per
volt ``gtau`` [N/V]; the controller's voltage is ``vir = kv (kp (qg − qm) − dqm/dt)``."""


def _emps_params(M: float, Fv: float) -> tuple[Param, Param]:
    return (Param("cart.m", M, "kg", "moving mass (carriage, screw and motor, as seen at the carriage)", range=(10.0, 1000.0)),
            Param("fv.b", Fv, "N*s/m", "viscous friction", range=(1.0, 5000.0)))


def emps_stage(M: float = 95.0, Fv: float = 200.0) -> PHSystem:
    """The EMPS positioning stage in its loop, built from components: a carriage (:class:`~components.Mass`)
    with viscous friction (:class:`~components.Damper`) under the rig's cascaded loop, which is a PD
    position loop (:class:`~components.PositionLoop`, ``K_p = gtau·kv·kp``, ``K_d = gtau·kv``,
    :data:`EMPS_LOOP`).

    Inputs: ``qg`` [m] the reference position, ``pulses_N`` [V] a test signal added to the controller's
    voltage after the control law (recorded with it; zero in the estimation run).  Measured: ``qm`` [m]
    the carriage position and ``force`` [N] the drive force ``gtau·vir`` (the recorded ``vir`` times
    ``gtau``: ``--map vir=force --scale vir=35.15065188248547``).

    Examples
    --------
    >>> s = emps_stage()
    >>> s.state_names, s.input_names, s.measured_names
    (['cart.p', 'pl.x'], ['qg', 'pulses_N'], ['force', 'qm'])
    """
    from components import Damper, Mass, PositionLoop
    from phs import Measured, interconnect, series, symbol_of_state

    g = EMPS_LOOP
    pm, pb = _emps_params(M, Fv)
    return interconnect(
        "emps",
        [Mass("cart", m=pm), Damper("fv", b=pb),
         PositionLoop("pl", K_p=g["gtau"] * g["kv"] * g["kp"], K_d=g["gtau"] * g["kv"], reference="qg", effort="force",
                      range=(-0.5, 0.5), feedforward="pulses_N", feedforward_gain=g["gtau"], feedforward_unit="V")],
        [series("cart", "fv", "pl")],
        measured=[Measured("qm", symbol_of_state("pl.x"), "m", "carriage position (motor encoder)")],
        description="EMPS positioning stage in its position loop; mass and viscous friction",
    )


def emps_stage_matrices(M: float = 95.0, Fv: float = 200.0) -> PHSystem:
    """:func:`emps_stage` written by hand as one port-Hamiltonian system.

    States ``q`` [m] (carriage position) and ``p`` [kg m/s] (momentum).  The loop is a virtual spring
    ``K = gtau·kv·kp`` to the origin with the reference acting as the force ``K qg``, and a virtual damper
    ``D = gtau·kv`` beside the viscous friction: ``ṗ = −K q − (Fv + D) p/M + K qg + gtau·pulses_N``,
    ``q̇ = p/M``.  Measured: ``qm = q`` and the drive force
    ``force = K (qg − q) − D p/M + gtau·pulses_N`` (the controller's command, recorded as ``gtau·vir``).

    Examples
    --------
    >>> s = emps_stage_matrices()
    >>> s.state_names, s.input_names, s.measured_names
    (['q', 'p'], ['qg', 'pulses_N'], ['qm', 'force'])
    >>> s.check().ok
    True
    """
    g = EMPS_LOOP
    known = [Param("loop.K", g["gtau"] * g["kv"] * g["kp"], "N/m", "the loop's virtual stiffness gtau*kv*kp", range=(1e3, 1e8)),
             Param("loop.D", g["gtau"] * g["kv"], "N*s/m", "the loop's virtual damping gtau*kv", range=(1.0, 1e6)),
             Param("gtau", g["gtau"], "N/V", "drive force per volt", range=(1.0, 1e3))]
    K, D, gt = (k.symbol for k in known)
    q, p = sp.symbols("q p", real=True)
    pm, pb = _emps_params(M, Fv)
    Ms, Fvs = pm.symbol, pb.symbol
    qg, pul = sp.Symbol("qg", real=True), sp.Symbol("pulses_N", real=True)
    states = [StateInfo("q", "m", (-0.5, 0.5), "carriage position", "C", 0.1, "loop"),
              StateInfo("p", "kg*m/s", (-100.0, 100.0), "carriage momentum", "I", 10.0, "cart")]
    H = [EnergyTerm("loop", K * q**2 / 2), EnergyTerm("cart", p**2 / (2 * Ms))]
    return PHSystem(
        "emps", states, H, sp.Matrix([[0, 1], [-1, 0]]), sp.Matrix([[0, 0], [0, Fvs + D]]), sp.Matrix([[0, 0], [K, gt]]),
        inputs=[InputInfo("qg", "m", "qg.y", "N/s", "effort", "reference position", (-0.5, 0.5)),
                InputInfo("pulses_N", "V", "pulses_N.v", "W/V", "effort", "test signal added to the controller's voltage")],
        params=[pm, pb, *known],
        measured=[Measured("qm", q, "m", "carriage position (motor encoder)"),
                  Measured("force", K * (qg - q) - D * p / Ms + gt * pul, "N", "drive force gtau*vir (controller command)",
                           command=True)],
        dissipators=[("friction", {(1, 1): Fvs}), ("loop", {(1, 1): D})],
        description="EMPS positioning stage in its position loop, written by hand; mass and viscous friction",
    )
