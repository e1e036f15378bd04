"""The parameter vector of one integrator, declared where the integrator is built and checked where it is filled.

An integrator of :class:`codegen.simulator.Simulator` takes ``P = [p, a, h, <inputs>]``: the model's
parameters, the run's time origin and output step, then, per input that enters as a template, a weight
and the template's constants for each of its slots (a sampled input baked into an interpolant adds
nothing).  Integrators of different kinds (a line segment, an interpolated stretch, a segment of a
``phs.signals`` expression) take vectors of different sizes: each carries its :class:`ParamLayout`, and
every vector handed to one is checked against it (:meth:`ParamLayout.check`), so a vector sized for
another kind of segment is refused by name instead of read past or cut short by CasADi's call buffer.

Examples
--------
>>> lay = ParamLayout(3, (("slots", (2,)), ("sampled", ())))
>>> lay.size, lay.tail_size
(8, 5)
>>> lay.check(np.zeros(7), "segment 2")
Traceback (most recent call last):
...
phs.errors.SimulationError: segment 2: the integrator takes 8 parameters (3 of the model, 5 of the run and its inputs), got 7
"""

from __future__ import annotations

import dataclasses

import numpy as np

from phs.errors import SimulationError


@dataclasses.dataclass(frozen=True)
class ParamLayout:
    """The layout of an integrator's parameter vector: ``n_model`` model parameters, ``a`` and ``h``, then
    per input ``("slots", (n_constants, ...))`` (a weight and the constants of each slot) or
    ``("sampled", ())`` (baked into an interpolant: no entries)."""

    n_model: int
    inputs: tuple

    @property
    def tail_size(self) -> int:
        """Entries after the model's parameters: ``a``, ``h`` and the inputs' weights and constants."""
        return 2 + sum(1 + nc for kind, ncs in self.inputs if kind == "slots" for nc in ncs)

    @property
    def size(self) -> int:
        """Length of the whole parameter vector."""
        return self.n_model + self.tail_size

    def check(self, P, where: str) -> None:
        """Raise a :class:`~phs.errors.SimulationError` naming ``where`` unless ``P`` has this layout's size."""
        n = int(np.size(P))
        if n != self.size:
            raise SimulationError(f"{where}: the integrator takes {self.size} parameters ({self.n_model} of the model, "
                                  f"{self.tail_size} of the run and its inputs), got {n}")
