"""Hydraulic components: a flow source, a compliant chamber and a pressure-to-force transducer.

Hydraulic ports are (pressure [Pa], volume flow [m**3/s]) pairs; volumes are in m**3.
"""

from __future__ import annotations

import sympy as sp

from components._base import QuadraticStorage, require_positive, source_piece
from phs.component import Component, Piece, Relation


class FlowSource(Component):
    """Imposed volume flow ``{name}`` [m**3/s] (a displacement pump) with conjugate output pressure ``{name}.P``.

    A volume-controlled drive (a syringe or cylinder whose piston position is set) is this
    source with the flow equal to the rate of the commanded volume.

    Examples
    --------
    >>> FlowSource("q").piece().sources[0].info.output
    'q.P'
    """

    def __init__(self, name: str, range=None):
        super().__init__(name)
        self.range = range

    def piece(self) -> Piece:
        return source_piece(self, self._port("p", "hydraulic", supplies=True), "flow", "m**3/s",
                            f"{self.name}.P", "Pa", "imposed volume flow", self.range)


class Chamber(QuadraticStorage):
    """Compliant chamber with a polynomial pressure-volume law ``P(V) = k1 V + k2 V**2 + k3 V**3``.

    ``H = k1 V**2/2 + k2 V**3/3 + k3 V**4/4``; state ``{name}.V`` (fluid volume stored by
    the wall's compliance, m**3), port (pressure, flow into the chamber).  ``k2 = k3 = 0`` is a
    linear hydraulic capacitance ``1/k1``.

    Parameters
    ----------
    name : str
    k1 : float, Param or expression
        Linear stiffness [Pa/m**3] (positive).
    k2, k3 : float, Param or expression
        Quadratic [Pa/m**6] and cubic [Pa/m**9] stiffening (zero by default: not declared).

    Examples
    --------
    >>> Chamber("ch", k1=1e9, k3=2e19).piece().energy[0].expr
    ch.V**4*ch.k3/4 + ch.V**2*ch.k1/2
    """

    domain = "hydraulic"
    state_local = "V"
    state_unit = "m**3"
    state_description = "stored fluid volume"

    def __init__(self, name: str, k1=1e9, k2=0.0, k3=0.0, **kw):
        require_positive(name, "k1", k1)
        super().__init__(name, **kw)
        self.k = (k1, k2, k3)

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        units = ("Pa/m**3", "Pa/m**6", "Pa/m**9")
        words = ("linear", "quadratic", "cubic")
        return [(f"k{i + 1}", k, units[i], f"{words[i]} coefficient of the pressure-volume law")
                for i, k in enumerate(self.k) if not (isinstance(k, (int, float)) and k == 0)]

    def default_range(self, values) -> tuple[float, float]:
        return (-2e-5, 2e-5)

    def energy(self, x) -> sp.Expr:
        e = sp.Integer(0)
        for i in (1, 2, 3):
            if f"k{i}" in self._syms:
                e += self._syms[f"k{i}"] * x ** (i + 1) / (i + 1)
        return e


class PressureTransducer(Component):
    """Pressure acting on an effective area: force ``F = A P`` on port b, flow ``q = A v`` drawn at port a.

    A power-conserving hydraulic-to-mechanical transformer (a piston, or the bending wall
    of a soft actuator reduced to its tip coordinate); ``A`` may depend on states.

    Parameters
    ----------
    name : str
    A : float, Param or expression
        Effective area [m**2].

    Examples
    --------
    >>> pc = PressureTransducer("wall", A=2e-5).piece()
    >>> [p.domain for p in pc.ports]
    ['hydraulic', 'translational']
    """

    def __init__(self, name: str, A=1e-4):
        super().__init__(name)
        self.area = A

    def piece(self) -> Piece:
        n, decl = self._param("A", self.area, "m**2", "effective area")
        a = self._port("a", "hydraulic")
        b = self._port("b", "translational", supplies=True)
        # port a absorbs P q, port b gives back F v: equal when q = A v and F = A P
        rels = (Relation(a.flow - n * b.flow, self.name, "transformer"),
                Relation(b.effort - n * a.effort, self.name, "transformer"))
        return Piece(self.name, ports=(a, b), relations=rels, params=decl)


__all__ = ["FlowSource", "Chamber", "PressureTransducer"]
