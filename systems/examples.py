"""Small reference models with analytic solutions (used in docs, tests and benchmarks).

Each is built from :mod:`components` through :func:`phs.interconnect`.
"""

from __future__ import annotations

import sympy as sp

from components import (
    Capacitor,
    Damper,
    ForceSource,
    Inductor,
    LinearSpring,
    Mass,
    NonlinearSpring,
    PositionLoop,
    Resistor,
    VoltageSource,
)
from phs import Measured, PHSystem, interconnect, series, symbol_of_state


def rc_circuit(R: float = 1e3, C: float = 1e-6) -> PHSystem:
    """Voltage source, resistor and capacitor in series (time constant R C).

    States: ``C.Q``; input ``U`` [V]; port output ``U.i`` [A] (the source
    current, with feedthrough 1/R); measured output ``v_C`` [V].

    Examples
    --------
    >>> s = rc_circuit()
    >>> s.state_names, s.input_names, s.output_names
    (['C.Q'], ['U'], ['U.i'])
    """
    q = symbol_of_state("C.Q")
    return interconnect(
        "rc",
        [VoltageSource("U"), Resistor("R", R=R), Capacitor("C", C=C, range=(-10 * C, 10 * C))],
        [series("U", "R", "C")],
        measured=[Measured("v_C", q / sp.Symbol("C.C", positive=True), "V", "capacitor voltage")],
        description="RC low-pass: U -> R -> C",
    )


def rlc_circuit(R: float = 10.0, L: float = 1e-3, C: float = 1e-6) -> PHSystem:
    """Series RLC circuit driven by a voltage source.

    Examples
    --------
    >>> rlc_circuit().state_names
    ['L.phi', 'C.Q']
    """
    return interconnect(
        "rlc",
        [VoltageSource("U"), Resistor("R", R=R), Inductor("L", L=L, range=(-0.1 * L, 0.1 * L)),
         Capacitor("C", C=C, range=(-10 * C, 10 * C))],
        [series("U", "R", "L", "C")],
        description="series RLC: U -> R -> L -> C",
    )


def mass_spring_damper(m: float = 1.0, k: float = 4.0, b: float = 0.4) -> PHSystem:
    """Mass on a linear spring and damper, driven by a force ``F``.

    States ``k.l`` (elongation) and ``m.p`` (momentum); output ``F.v``.

    Examples
    --------
    >>> mass_spring_damper().state_names
    ['m.p', 'k.l']
    """
    return interconnect(
        "msd",
        [ForceSource("F"), Mass("m", m=m), LinearSpring("k", K=k), Damper("b", b=b)],
        [series("F", "m", "k", "b")],
        measured=[Measured("position", symbol_of_state("k.l"), "m", "spring elongation")],
        description="mass-spring-damper under a force",
    )


def duffing_oscillator(m: float = 1.0, k: float = 1.0, k3: float = 0.5, b: float = 0.0) -> PHSystem:
    """Mass on a hardening spring ``F = k q + k3 q**3`` (undamped by default).

    Examples
    --------
    >>> duffing_oscillator().H.has(sp.Symbol("k3"))
    False
    """
    q = sp.Symbol("q", real=True)
    from phs import Param

    kp, k3p = Param("k", k, "N/m", "linear stiffness"), Param("k3", k3, "N/m**3", "cubic stiffness")
    comps = [Mass("m", m=m), NonlinearSpring("s", force=kp.symbol * q + k3p.symbol * q**3, variable=q, params=[kp, k3p])]
    members = ["m", "s"]
    if b > 0:
        comps.append(Damper("b", b=b))
        members.append("b")
    return interconnect("duffing", comps, [series(*members)], description="Duffing oscillator")


def pd_servo(m: float = 0.5, k: float = 40.0, b: float = 1.0, K_p: float = 400.0, K_d: float = 6.0, tau: float | None = 0.01) -> PHSystem:
    """A mass on a spring and damper under PD position control on a filtered reference (time constant
    ``tau``): input the reference ``r`` [m], measured the controller's force ``u_c`` [N] (a computed
    command, ``Measured.command``) and the position [m].  Linear: the closed loop has
    ``ω_n² = (k + K_p)/m`` (see ``docs/workflows/closed_loop.md``).

    Examples
    --------
    >>> s = pd_servo()
    >>> s.input_names, s.measured_names, [m.command for m in s.measured]
    (['r'], ['u_c', 'position'], [True, False])
    """
    return interconnect(
        "servo",
        [Mass("m", m=m), LinearSpring("k", K=k), Damper("b", b=b),
         PositionLoop("pd", K_p=K_p, K_d=K_d, tau=tau, position="k.l", effort="u_c")],
        [series("m", "k", "b", "pd")],
        measured=[Measured("position", symbol_of_state("k.l"), "m", "position of the mass")],
        description="mass-spring-damper under PD position control",
    )
