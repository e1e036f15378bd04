"""The component interface: what every building block returns.

A component declares its port-Hamiltonian piece (:class:`Piece`): the states
it owns and the energy it stores (which may depend on states owned by other
components, like a variable capacitor's energy on the angle of a spring), its
ports (effort/flow pairs), the constitutive relations of its resistive,
transforming and source ports (equations linear in port variables whose
coefficients may depend on states), its parameters, measured outputs,
geometric definitions and validity conditions.  :func:`phs.interconnect`
joins pieces through junctions and eliminates everything into an explicit
:class:`phs.PHSystem`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field, fields
from numbers import Real

import sympy as sp

from phs.errors import ModelError
from phs.params import (
    Condition,
    EnergyTerm,
    InputInfo,
    Measured,
    Param,
    StateInfo,
    check_name,
    input_symbol,
    state_symbol,
)

DOMAINS = ("electrical", "translational", "rotational", "hydraulic", "any")


@dataclass(frozen=True)
class Port:
    """An effort/flow pair through which power enters a component.

    ``supplies`` is True for ports whose positive power flows out of the
    component into the network (sources); for all others positive power
    ``effort * flow`` flows into the component.
    """

    name: str
    effort: sp.Symbol
    flow: sp.Symbol
    domain: str = "any"
    supplies: bool = False
    component: str = ""
    causality: str | None = None  # "effort"/"flow": which variable is the input of a subsystem port


def make_port(component: str, local: str, domain: str = "any", supplies: bool = False) -> Port:
    """Create a port named ``component.local`` with fresh effort/flow symbols.

    Examples
    --------
    >>> make_port("R0", "p", "electrical").name
    'R0.p'
    """
    if domain not in DOMAINS:
        raise ModelError(f"component {component!r}: unknown port domain {domain!r}; use one of {DOMAINS}")
    full = f"{component}.{local}"
    return Port(full, sp.Symbol(f"e[{full}]", real=True), sp.Symbol(f"f[{full}]", real=True), domain, supplies, component)


@dataclass(frozen=True)
class Storage:
    """A state owned by a component, with the port through which it exchanges power."""

    state: StateInfo
    port: Port

    @property
    def rate(self) -> sp.Symbol:
        """Port variable equal to the state's time derivative."""
        return self.port.flow if self.state.kind == "C" else self.port.effort

    @property
    def coenergy(self) -> sp.Symbol:
        """Port variable equal to dH/dx of the state."""
        return self.port.effort if self.state.kind == "C" else self.port.flow


@dataclass(frozen=True)
class Relation:
    """A constitutive equation ``expr == 0``, linear in port variables."""

    expr: sp.Expr
    component: str
    kind: str = "other"


@dataclass(frozen=True)
class Source:
    """An input imposing one variable of a port; the other is the conjugate output."""

    info: InputInfo
    port: Port

    @property
    def imposed(self) -> sp.Symbol:
        return self.port.effort if self.info.kind == "effort" else self.port.flow

    @property
    def conjugate(self) -> sp.Symbol:
        return self.port.flow if self.info.kind == "effort" else self.port.effort


@dataclass(frozen=True)
class Dissipator:
    """A resistive element: the power it dissipates is the sum of e*f over its ports,
    or ``power`` (an expression in port variables) when given."""

    label: str
    ports: tuple[Port, ...]
    power: sp.Expr | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "ports", tuple(self.ports))


@dataclass(frozen=True)
class Definition:
    """A geometric variable defined as an expression of states and parameters."""

    symbol: sp.Symbol
    expr: sp.Expr
    label: str
    unit: str = "1"


@dataclass(frozen=True)
class Piece:
    """The port-Hamiltonian contribution of one component."""

    name: str
    storages: tuple[Storage, ...] = ()
    energy: tuple[EnergyTerm, ...] = ()
    ports: tuple[Port, ...] = ()
    internal: tuple[Port, ...] = ()
    relations: tuple[Relation, ...] = ()
    sources: tuple[Source, ...] = ()
    dissipators: tuple[Dissipator, ...] = ()
    params: tuple[Param, ...] = ()
    measured: tuple[Measured, ...] = ()
    definitions: tuple[Definition, ...] = ()
    conditions: tuple[Condition, ...] = ()
    references: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        # a list given by a component becomes a tuple: the piece, like the system built from it, is a value
        for f in fields(self):
            if isinstance(getattr(self, f.name), list):
                object.__setattr__(self, f.name, tuple(getattr(self, f.name)))


class Component(ABC):
    """Base of every building block.

    Subclasses implement :meth:`piece`.  The helpers :meth:`_param`,
    :meth:`_state`, :meth:`_port` keep names and units consistent.

    Parameters
    ----------
    name : str
        Dotted name, unique in a model (``"seg2.C2"``).

    Examples
    --------
    A one-port linear damper written as a custom component:

    >>> from phs.component import Dissipator, Relation
    >>> class MyDamper(Component):
    ...     def __init__(self, name, b):
    ...         super().__init__(name)
    ...         self.b = b
    ...     def piece(self):
    ...         port = self._port("p", "translational")
    ...         b, params = self._param("b", self.b, "N*s/m", "damping")
    ...         return Piece(self.name, ports=(port,), relations=(Relation(port.effort - b * port.flow, self.name, "resistive"),),
    ...                      dissipators=(Dissipator(self.name, (port,)),), params=params)
    >>> from phs import interconnect, series
    >>> from components import Mass
    >>> interconnect("m", [Mass("m"), MyDamper("d", 0.3)], [series("m", "d")]).R
    Matrix([[d.b]])
    """

    def __init__(self, name: str):
        self.name = check_name(name, "component")

    @abstractmethod
    def piece(self) -> Piece:
        """Return this component's port-Hamiltonian piece."""

    # -- helpers for subclasses -------------------------------------------------
    def _param(self, key: str, value, unit: str, description: str, range=None) -> tuple[sp.Expr, tuple[Param, ...]]:
        """Resolve a parameter argument into (expression, params declared).

        ``value`` may be a number (a local parameter ``{name}.{key}`` is
        created), a :class:`Param` (shared), or a sympy expression of shared
        parameters' symbols (declared elsewhere, e.g. ``interconnect(params=)``).
        """
        if isinstance(value, Param):
            return value.symbol, (value,)
        if isinstance(value, Real) and not isinstance(value, bool):
            p = Param(f"{self.name}.{key}", float(value), unit, description, range)
            return p.symbol, (p,)
        if isinstance(value, sp.Expr):
            return value, ()
        raise ModelError(
            f"component {self.name!r}: parameter {key!r} must be a number, a Param or a sympy "
            f"expression of parameters, not {type(value).__name__}"
        )

    def _state(self, local: str, given: str | None, unit: str, range, description: str, kind: str, domain: str, scale=None,
               rest=None) -> Storage:
        name = check_name(given or f"{self.name}.{local}", "state")
        rest = None if rest is None else float(rest)
        info = StateInfo(name, unit, tuple(float(r) for r in range), description, kind, scale, self.name, rest)
        return Storage(info, make_port(self.name, local, domain))

    def _port(self, local: str, domain: str, supplies: bool = False) -> Port:
        return make_port(self.name, local, domain, supplies)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def symbol_of_state(name: str) -> sp.Symbol:
    """Symbol to use in expressions that refer to another component's state.

    Examples
    --------
    >>> symbol_of_state("seg1.theta")
    seg1.theta
    """
    return state_symbol(check_name(name, "state"))


def symbol_of_output(name: str) -> sp.Symbol:
    """Symbol of a port output (``"U.i"``) for use in measured outputs.

    Examples
    --------
    >>> symbol_of_output("U.i")
    U.i
    """
    return sp.Symbol(check_name(name, "output"), real=True)


def symbol_of_input(name: str) -> sp.Symbol:
    """Symbol to use in measured outputs that refer to an input.

    Examples
    --------
    >>> symbol_of_input("U")
    U
    """
    return input_symbol(check_name(name, "input"))
