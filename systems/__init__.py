"""Ready-made models built only from components and the public interconnection API."""

from systems.catheter_bender import catheter_bender, volume_chirp
from systems.curling_hasel import curling_hasel
from systems.electrostatic_actuator import electrostatic_actuator
from systems.examples import duffing_oscillator, mass_spring_damper, rc_circuit, rlc_circuit
from systems.hydrogel_arm import hydrogel_arm
from systems.manta_ray_fin import manta_ray_fin
from systems.msd_hasel import hasel_platform, msd_hasel
from systems.peano_swimmer import peano_swimmer, swimmer_drive

__all__ = ["rc_circuit", "rlc_circuit", "mass_spring_damper", "duffing_oscillator", "curling_hasel", "manta_ray_fin",
           "electrostatic_actuator", "msd_hasel", "hasel_platform", "hydrogel_arm", "peano_swimmer", "swimmer_drive",
           "catheter_bender", "volume_chirp"]

#: the functions above that build a PHSystem (the others build its inputs: drives, chirps)
MODELS = tuple(n for n in __all__ if n not in ("swimmer_drive", "volume_chirp"))
