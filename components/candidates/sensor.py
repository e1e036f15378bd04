"""Measured-output candidates: effects of the sensor, not of the physics it records.

:class:`Offset` adds a constant to a measured output (a sensor's zero error); the port-Hamiltonian
part of the model is unchanged.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> from components.candidates.base import Scales
>>> s = mass_spring_damper()
>>> aug = Offset().augment(s, s.measured_names[0], Scales.of(s))
>>> aug.free == [f"offset.{s.measured_names[0]}"], aug.system.J == s.J
(True, True)
"""

from __future__ import annotations

from dataclasses import replace

from components.candidates.base import Augmentation, Candidate, _rebuild, _zero


class Offset(Candidate):
    """A constant offset on a measured output (sensor zero error): ``y_m → y_m + c``."""

    effect = "offset"
    summary = "a constant offset of the sensor reading"
    kind = "measured"

    def attach_points(self, system) -> list[str]:
        return list(system.measured_names)

    def augment(self, system, where, scales) -> Augmentation:
        self._check_where(system, where)
        k = system.measured_names.index(where)
        mo = system.measured[k]
        ref = max(scales.get("value", where, 1.0), 1e-12)
        c = self.param(f"{where}", 0.01 * ref, mo.unit, f"offset of the measured output {where}", (-100 * ref, 100 * ref))
        measured = list(system.measured)
        measured[k] = replace(mo, expr=mo.expr + c.symbol)
        s = _rebuild(system, measured=measured, params=[c], effect=self.effect)
        return Augmentation(self.effect, where, "constant added to the reading", s, [c.name], {c.name: c.range}, [],
                            neutral={c.name: _zero(c)})

