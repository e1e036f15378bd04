"""The built-in candidates, in the order diagnosis tries them, and their lookup by effect name.

Examples
--------
>>> EFFECTS[:3]
('charge_retention', 'leakage', 'series_resistance')
>>> lookup("time_delay")
TimeDelay()
"""

from __future__ import annotations

from components.candidates.base import Candidate
from components.candidates.drive import InputSaturation, SlewRateLimit, TimeDelay
from components.candidates.electrical import ChargeRetention, Leakage, SeriesResistance
from components.candidates.mechanical import AddedMass, CoulombFriction, CubicStiffness, Hysteresis, QuadraticDrag, ViscoelasticCreep
from components.candidates.sensor import Offset
from phs.errors import ModelError

LIBRARY: tuple[Candidate, ...] = (
    ChargeRetention(), Leakage(), SeriesResistance(), CoulombFriction(), ViscoelasticCreep(), CubicStiffness(),
    Hysteresis(), QuadraticDrag(), AddedMass(), InputSaturation(), SlewRateLimit(), TimeDelay(), Offset(),
)
"""The built-in candidates, one per effect name."""

EFFECTS: tuple[str, ...] = tuple(c.effect for c in LIBRARY)


def lookup(effect: str) -> Candidate:
    """The built-in candidate of ``effect`` (one of :data:`EFFECTS`).

    Parameters
    ----------
    effect : str
        The candidate's effect name, e.g. ``"coulomb_friction"``.

    Returns
    -------
    Candidate
        The instance held by :data:`LIBRARY`.

    Raises
    ------
    ModelError
        For a name no built-in candidate has; the message lists the known ones.

    Examples
    --------
    >>> lookup("coulomb_friction").kind
    'structure'
    >>> lookup("stiction")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.ModelError: unknown effect 'stiction'; known: charge_retention, leakage, ...
    """
    for c in LIBRARY:
        if c.effect == effect:
            return c
    raise ModelError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
