"""A one-degree-of-freedom electrostatic (parallel-plate) actuator.

A movable electrode of mass ``m`` hangs on a spring ``k`` with damping
``b`` above a fixed electrode; the gap closes by ``x``.  The capacitor is a
multi-port storage ``H_e = Q**2 / (2 C(x))`` with ``C(x) = eps A / (g0 - x)``:
its energy depends on the mechanical state, so the electrostatic force
``-dH_e/dx = -Q**2 / (2 eps A)`` comes out of the gradient of H without any
hand-written coupling.  The source drives the capacitor through a series
resistor ``R_s`` (feedthrough: the port output is the source current).

States ``x`` [m] (spring elongation = gap closure), ``m.p`` [kg m/s],
``Q`` [C]; input ``U`` [V]; port output ``U.i`` [A]; measured outputs
``position`` and ``current``.  Validity: the gap stays open
(``x < g0``).  Under voltage control the static equilibrium exists only up
to the pull-in voltage ``V_pi = sqrt(8 k g0**3 / (27 eps A))`` at ``x = g0/3``.

This is the actuator built step by step in ``docs/tutorials/new_actuator.md``.
"""

from __future__ import annotations

from components import Damper, LinearSpring, Mass, Resistor, VariableCapacitor, VoltageSource
from phs import Condition, Measured, Param, PHSystem, interconnect, series, symbol_of_output, symbol_of_state


def electrostatic_actuator(**overrides) -> PHSystem:
    """Parallel-plate electrostatic actuator: mass-spring-damper with a gap-dependent capacitor.

    Parameters
    ----------
    **overrides : float
        Values of ``m``, ``k``, ``b``, ``eps``, ``A``, ``g0``, ``R_s``.

    Examples
    --------
    >>> s = electrostatic_actuator()
    >>> s.state_names, s.measured_names
    (['x', 'm.p', 'Q'], ['position', 'current'])
    """
    P = {q.name: q for q in [
        Param("m", 1e-3, "kg", "mass of the movable electrode", (1e-4, 1e-2)),
        Param("k", 50.0, "N/m", "suspension stiffness", (5.0, 500.0)),
        Param("b", 0.02, "N*s/m", "damping", (1e-3, 1.0)),
        Param("eps", 8.854e-12 * 3.0, "F/m", "permittivity of the gap", (8.8e-12, 1e-10)),
        Param("A", 4e-4, "m**2", "electrode area", (1e-5, 1e-2)),
        Param("g0", 1e-4, "m", "rest gap", (1e-5, 1e-3)),
        Param("R_s", 1e4, "Ohm", "series resistance of the source", (1e2, 1e6)),
    ]}
    unknown = [k for k in overrides if k not in P]
    if unknown:
        from phs.errors import ModelError

        raise ModelError(f"electrostatic_actuator: unknown parameter(s) {unknown}; known: {sorted(P)}")
    for k, v in overrides.items():
        P[k] = P[k].with_value(v)
    x = symbol_of_state("x")
    eps, A, g0 = P["eps"].symbol, P["A"].symbol, P["g0"].symbol
    return interconnect(
        "electrostatic_actuator",
        [
            LinearSpring("k", K=P["k"], state="x", range=(-5e-5, 9e-5), scale=3e-5),
            Mass("m", m=P["m"], scale=1e-5),
            VariableCapacitor("C", C=eps * A / (g0 - x), C_typical=1e-10, state="Q", scale=1e-8),
            Damper("b", b=P["b"]),
            VoltageSource("U", range=(-200.0, 200.0)),
            Resistor("Rs", R=P["R_s"]),
        ],
        # one velocity for the plate: its inertia, the spring and the damper share it; the electrode
        # capacitor's force enters through dH/dx of the spring's state x
        [series("U", "Rs", "C"), series("m", "k", "b")],
        params=list(P.values()),
        measured=[Measured("position", x, "m", "gap closure"),
                  Measured("current", symbol_of_output("U.i"), "A", "source current")],
        conditions=[Condition("gap open (x < g0)", g0 - x, "the electrodes must not touch")],
        description="parallel-plate electrostatic actuator (mass-spring-damper with gap-dependent capacitor)",
    )
