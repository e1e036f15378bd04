"""PHSystems as components: a system used as one component of a larger one (hierarchical models)."""

from __future__ import annotations

import sympy as sp

from phs.component import Component, Dissipator, Piece, Port, Relation, Source, Storage
from phs.params import InputInfo


def subsystem_piece(system) -> Piece:
    """The piece of a PHSystem used as a component.

    Its states keep their names; each input becomes an absorbing port
    ``{system}.{input}`` whose input variable is the effort (voltage, force)
    or the flow (current, velocity) according to the input's kind.
    """
    n = system.name
    storages = []
    for st in system.states:
        full = f"{n}.{st.name}"
        storages.append(Storage(st, Port(full, sp.Symbol(f"e[{full}]", real=True), sp.Symbol(f"f[{full}]", real=True),
                                         "any", False, n)))
    ports = []
    for inp in system.inputs:
        full = f"{n}.{inp.name}"
        ports.append(Port(full, sp.Symbol(f"e[{full}]", real=True), sp.Symbol(f"f[{full}]", real=True), "any", False, n,
                          inp.kind))
    c = sp.Matrix(len(storages), 1, [s.coenergy for s in storages])
    uimp = sp.Matrix(len(ports), 1, [p.effort if p.causality == "effort" else p.flow for p in ports])
    ucon = [p.flow if p.causality == "effort" else p.effort for p in ports]
    rates = (system.J - system.R) * c + ((system.G - system.P) * uimp if ports else sp.zeros(len(storages), 1))
    outs = (system.G + system.P).T * c + (system.S + system.N) * uimp if ports else sp.zeros(0, 1)
    rels = [Relation(s.rate - rates[i], n, "subsystem") for i, s in enumerate(storages)]
    rels += [Relation(ucon[j] - outs[j], n, "subsystem") for j in range(len(ports))]
    z = list(c) + list(uimp)
    diss = []
    for label, entries in system.dissipators:
        power = sum(((1 if i == j else 2) * v * z[i] * z[j] for (i, j), v in entries.items()), sp.Integer(0))
        diss.append(Dissipator(f"{n}.{label}", (), power))
    return Piece(
        n, storages=tuple(storages), energy=tuple(system.energy_terms), ports=tuple(ports), relations=tuple(rels),
        dissipators=tuple(diss), params=tuple(system.params), measured=_state_measured(system),
        conditions=tuple(system.conditions),
    )


def _state_measured(system) -> tuple:
    """Measured outputs that depend on states and parameters only (those that depend on the
    subsystem's inputs or port outputs have no meaning once its inputs become internal ports)."""
    allowed = set(system.x) | set(system.p)
    return tuple(m for m in system.measured if sp.sympify(m.expr).free_symbols <= allowed)


class _ExternalInput(Component):
    """An input of a subsystem kept as an input of the enclosing system."""

    def __init__(self, name: str, info: InputInfo):
        super().__init__(name)
        self.info = info

    def piece(self) -> Piece:
        port = self._port("p", "any", supplies=True)
        info = InputInfo(self.name, self.info.unit, f"{self.name}.y" if "." not in self.info.output else
                         self.name + "." + self.info.output.split(".")[-1], self.info.output_unit, self.info.kind,
                         self.info.description, self.info.range)
        return Piece(self.name, ports=(port,), sources=(Source(info, port),))
