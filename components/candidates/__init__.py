"""Candidate physics: effects a model may have left out, each attachable to a named part of a PHSystem.

Diagnosis (:func:`phs.diagnose`) tries each candidate on the fitted model and keeps the ones the
recording asks for.  A candidate is one small class with one idea (:class:`Candidate`):

* :meth:`Candidate.attach_points` lists where it can go in a given system (a state, an input or a
  measured output, by name);
* :meth:`Candidate.augment` returns an :class:`Augmentation`: the augmented system (still a
  port-Hamiltonian system: J skew, R symmetric positive semi-definite, H bounded below), its new
  parameters with starting values, bounds and scales, and the initial values of new states.

Three ways an effect enters a model:

``structure``
    New energy, new dissipation or new states added to J, R, H (friction, creep, hysteresis,
    stiffness, added mass, leakage, charge retention) or a resistor inserted at an input port
    (series resistance).  Elements in series with a storage are inserted by the congruence
    ``J' = TᵀJT``, ``R' = TᵀRT + diag(0, R_new)`` with ``T = [I, E]``: the storage's co-energy is
    replaced by the sum of its own and the new element's, which is what "in series" means.
``input``
    A transformation of an input signal before it reaches the model (saturation, slew-rate limit,
    delay): the amplifier or the actuator's drive, outside the port-Hamiltonian part; in a closed
    loop also between the controller's command and the plant.  Such an
    element has a numeric :meth:`InputElement.transform` and its parameters are fitted by a bounded
    search on the simulated output.
``measured``
    A change of a measured output (a sensor offset).

Register a new candidate by subclassing :class:`Candidate` (or :class:`InputElement`) and passing an
instance to ``diagnose(..., candidates=[...])``; :data:`LIBRARY` holds the built-in ones.

The modules, one physical domain each (imports run downward: the effects import :mod:`.base`,
:mod:`.library` imports the effects):

:mod:`components.candidates.base`
    The interface (:class:`Candidate`, :class:`Augmentation`, :class:`Scales`) and the machinery every
    candidate shares: where it can attach, and how it changes J, R, H while keeping them
    port-Hamiltonian.
:mod:`components.candidates.elements`
    :class:`InputElement`, the form of drive elements, on a model input or, inside a feedback loop,
    between a controller's recorded command and the plant (:class:`InLoop`: the element's deviation
    from the command enters as a force on the driven body).
:mod:`components.candidates.electrical`
    Charge retention, leakage, series resistance.  :class:`Leakage` drains any conserved quantity a
    storage holds (charge, fluid volume, gas mass or amount) through a conductance across the storage,
    a flow proportional to its effort (voltage, pressure): one element for every domain, the circuit's
    conductance, so it sits with the electrical candidates rather than in a module of its own.
:mod:`components.candidates.mechanical`
    Coulomb friction, viscoelastic creep, cubic stiffness, hysteresis, quadratic drag, added mass:
    effects on a body's momentum or a displacement.
:mod:`components.candidates.drive`
    Input saturation, slew-rate limit, time delay: the drive elements between the recorded command and
    the port-Hamiltonian input.
:mod:`components.candidates.sensor`
    Offset: effects on a measured output.
:mod:`components.candidates.maps`
    Building blocks that keep a model port-Hamiltonian while changing an input's gain with the state
    (a modulated transformer), correcting a measured output, or giving a dissipation its own heat
    state: what discovered corrections are made of.
:mod:`components.candidates.library`
    :data:`LIBRARY` (the built-in candidates in the order diagnosis tries them), :data:`EFFECTS` and
    :func:`lookup` by effect name.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> s = mass_spring_damper()
>>> CoulombFriction().attach_points(s)
['m.p']
>>> aug = CoulombFriction().augment(s, "m.p", Scales.of(s))
>>> aug.free, aug.system.check().ok
(['coulomb_friction.F_c'], True)
"""

from components.candidates.base import (
    Augmentation,
    Candidate,
    Scales,
    add_damping,
    add_energy,
    charge_states,
    displacement_states,
    momentum_states,
    stored_quantity_states,
    with_groups,
)
from components.candidates.drive import InputSaturation, SlewRateLimit, TimeDelay
from components.candidates.electrical import ChargeRetention, Leakage, SeriesResistance
from components.candidates.elements import InLoop, InputElement, command_channels
from components.candidates.library import EFFECTS, LIBRARY, lookup
from components.candidates.mechanical import AddedMass, CoulombFriction, CubicStiffness, Hysteresis, QuadraticDrag, ViscoelasticCreep
from components.candidates.sensor import Offset

__all__ = [
    "Scales", "Augmentation", "Candidate", "InputElement", "InLoop", "command_channels", "LIBRARY", "EFFECTS", "lookup",
    "momentum_states", "displacement_states",
    "charge_states", "stored_quantity_states", "add_damping", "add_energy", "with_groups", "ChargeRetention", "Leakage", "SeriesResistance",
    "CoulombFriction", "ViscoelasticCreep",
    "CubicStiffness", "Hysteresis", "QuadraticDrag", "AddedMass", "InputSaturation", "SlewRateLimit", "TimeDelay", "Offset",
]
