"""The component library: storages, dissipators, sources, couplings and constraints.

Every component returns its port-Hamiltonian piece (:class:`phs.component.Piece`);
:func:`phs.interconnect` joins them.  Parameters given as numbers become local
parameters ``{component}.{name}``; give a :class:`phs.Param` to share one.
"""

from components.constraints import GeometricConstraint, Geometry, geometric_symbol
from components.control import PositionLoop, VelocityLoop
from components.coupling import Gyrator, Transformer
from components.electrical import (
    Capacitor,
    CurrentSource,
    DriftBranch,
    Inductor,
    Resistor,
    VariableCapacitor,
    VoltageSource,
)
from components.hydraulic import Chamber, FlowSource, PressureTransducer
from components.hydrogel import HydrogelActuator
from components.kinematics import ConfigurationInertia, KinematicChain
from components.mechanical import (
    Damper,
    ForceSource,
    Gravity,
    LinearSpring,
    Mass,
    NonlinearSpring,
    Potential,
    RotationalDamper,
    RotationalInertia,
    TorqueSource,
    TorsionalSpring,
)
from components.peano import PeanoHasel
from components.rod import CosseratRod

__all__ = [
    "Capacitor", "CurrentSource", "DriftBranch", "Inductor", "Resistor", "VariableCapacitor", "VoltageSource",
    "Damper", "ForceSource", "Gravity", "LinearSpring", "Mass", "NonlinearSpring", "RotationalDamper",
    "Potential", "RotationalInertia", "TorqueSource", "TorsionalSpring", "Gyrator", "Transformer",
    "GeometricConstraint", "Geometry", "geometric_symbol",
    "ConfigurationInertia", "KinematicChain", "PositionLoop", "VelocityLoop", "CosseratRod", "HydrogelActuator",
    "Chamber", "FlowSource", "PressureTransducer", "PeanoHasel",
]
