"""Shared building blocks of the library's components."""

from __future__ import annotations

import sympy as sp

from phs.component import Component, Dissipator, Piece, Relation, Source, Storage
from phs.errors import ModelError
from phs.params import EnergyTerm, InputInfo


class QuadraticStorage(Component):
    """A one-state storage with energy ``expr(x)``; subclasses fill the details."""

    kind = "C"
    domain = "any"
    state_local = "q"
    state_unit = "1"
    state_description = ""

    def __init__(self, name: str, *, state: str | None = None, range=None, scale=None, rest=None):
        super().__init__(name)
        self._state_name = state
        self._range = range
        self._scale = scale
        self._rest = rest

    def default_range(self, values: dict) -> tuple[float, float]:
        return (-1.0, 1.0)

    def default_rest(self, values: dict) -> float | None:
        """The state's value at rest (the default initial state), or None for 0 moved into the range."""
        return None

    def energy(self, x: sp.Symbol) -> sp.Expr:  # pragma: no cover - abstract in practice
        raise NotImplementedError

    def parameters(self) -> list:
        """List of (key, value, unit, description) for :meth:`_param`."""
        return []

    def piece(self) -> Piece:
        syms, params, values = {}, [], {}
        for key, value, unit, desc in self.parameters():
            sym, decl = self._param(key, value, unit, desc)
            syms[key] = sym
            params.extend(decl)
            values[key] = decl[0].value if decl else None
        self._syms = syms
        rng = self._range if self._range is not None else self.default_range(values)
        rest = self._rest if self._rest is not None else self.default_rest(values)
        st = self._state(self.state_local, self._state_name, self.state_unit, rng, self.state_description,
                         self.kind, self.domain, self._scale, rest)
        e = self.energy(st.state.symbol)
        return Piece(self.name, storages=(st,), energy=(EnergyTerm(self.name, e),), ports=(st.port,), params=tuple(params))


def linear_resistor_piece(comp: Component, port, coef, conductive: bool, params) -> Piece:
    """Piece of a (possibly state-modulated) linear resistor on ``port``."""
    rel = port.flow - coef * port.effort if conductive else port.effort - coef * port.flow
    return Piece(
        comp.name,
        ports=(port,),
        relations=(Relation(rel, comp.name, "resistive"),),
        dissipators=(Dissipator(comp.name, (port,)),),
        params=tuple(params),
    )


def source_piece(comp: Component, port, kind: str, unit: str, out_name: str, out_unit: str, description: str, range=None) -> Piece:
    info = InputInfo(comp.name, unit, out_name, out_unit, kind, description, range)
    return Piece(comp.name, ports=(port,), sources=(Source(info, port),))


def require_positive(comp: str, key: str, value) -> None:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value <= 0:
        raise ModelError(f"component {comp!r}: parameter {key!r} must be positive, got {value}")


__all__ = ["QuadraticStorage", "linear_resistor_piece", "source_piece", "require_positive", "Storage"]
