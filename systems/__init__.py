"""Ready-made models built only from components and the public interconnection API."""

from systems.examples import duffing_oscillator, mass_spring_damper, rc_circuit, rlc_circuit

__all__ = ["rc_circuit", "rlc_circuit", "mass_spring_damper", "duffing_oscillator"]
