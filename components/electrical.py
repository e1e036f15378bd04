"""Electrical components: capacitors, inductor, resistor, sources and the drift branch.

Ports are (voltage [V], current [A]) pairs; charges are in coulombs.
"""

from __future__ import annotations

import sympy as sp

from components._base import QuadraticStorage, linear_resistor_piece, require_positive, source_piece
from phs.component import Component, Dissipator, Piece, Relation
from phs.errors import ModelError
from phs.params import EnergyTerm


class Capacitor(QuadraticStorage):
    """Linear capacitor, ``H = Q**2 / (2 C)``, effort ``V = Q / C``, flow ``i = Q'``.

    Parameters
    ----------
    name : str
    C : float, Param or expression
        Capacitance [F].
    **kw
        ``state`` (str): name of the charge state (default ``{name}.Q``); ``range`` ((float, float)):
        physical range of the charge (default: the charge at +-10 kV).

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import Capacitor, Resistor
    >>> s = interconnect("rc_free", [Capacitor("C", C=1e-6), Resistor("R", R=1e3)], [series("C", "R")])
    >>> s.R[0, 0]
    1/R.R
    """

    domain = "electrical"
    state_local = "Q"
    state_unit = "C"
    state_description = "charge"

    def __init__(self, name: str, C=1e-6, **kw):
        require_positive(name, "C", C)
        super().__init__(name, **kw)
        self.C = C

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return [("C", self.C, "F", "capacitance")]

    def default_range(self, values) -> tuple[float, float]:
        c = values.get("C") or 1e-6
        return (-1e4 * c, 1e4 * c)

    def energy(self, x) -> sp.Expr:
        return x**2 / (2 * self._syms["C"])


class VariableCapacitor(Capacitor):
    """Capacitor whose capacitance is any expression of other states or geometric variables.

    ``H = Q**2 / (2 C(x))``; the electrostatic forces ``-dH/dtheta`` appear in
    the gradient of H without hand-written coupling (a multi-port storage).

    Parameters
    ----------
    name : str
    C : sympy expression
        Capacitance [F] in terms of parameters, other states
        (:func:`phs.component.symbol_of_state`) and geometric variables
        (:func:`components.geometric_symbol`).
    C_typical : float
        A typical value used for the default charge range.

    Examples
    --------
    >>> import sympy as sp
    >>> from phs import Param
    >>> from phs.component import symbol_of_state
    >>> eps = Param("eps", 1e-11, "F/m")
    >>> gap = symbol_of_state("gap.x")
    >>> VariableCapacitor("Cv", C=eps.symbol * 1e-2 / gap).name
    'Cv'
    """

    def __init__(self, name: str, C, C_typical: float = 1e-9, **kw):
        if not isinstance(C, (sp.Expr, int, float)):
            raise ModelError(f"component {name!r}: C must be a sympy expression or number")
        super().__init__(name, C=C if isinstance(C, sp.Expr) else float(C), **kw)
        self.C_typical = C_typical

    def default_range(self, values) -> tuple[float, float]:
        return (-1e4 * self.C_typical, 1e4 * self.C_typical)


class Inductor(QuadraticStorage):
    """Linear inductor, ``H = phi**2 / (2 L)`` with flux linkage ``phi`` [Wb].

    Examples
    --------
    >>> Inductor("L", L=1e-3).piece().storages[0].state.name
    'L.phi'
    """

    kind = "I"
    domain = "electrical"
    state_local = "phi"
    state_unit = "Wb"
    state_description = "flux linkage"

    def __init__(self, name: str, L=1e-3, **kw):
        require_positive(name, "L", L)
        super().__init__(name, **kw)
        self.L = L

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return [("L", self.L, "H", "inductance")]

    def default_range(self, values) -> tuple[float, float]:
        return (-10 * (values.get("L") or 1e-3), 10 * (values.get("L") or 1e-3))

    def energy(self, x) -> sp.Expr:
        return x**2 / (2 * self._syms["L"])


class Resistor(Component):
    """Linear resistor ``V = R i`` (or conductance ``i = G V``); R may depend on states.

    Parameters
    ----------
    name : str
    R : float, Param or expression, optional
        Resistance [Ohm].
    G : float, Param or expression, optional
        Conductance [S] (give exactly one of R and G).

    Examples
    --------
    >>> Resistor("R0", R=1e3).piece().relations[0].kind
    'resistive'
    """

    def __init__(self, name: str, R=None, G=None):
        super().__init__(name)
        if (R is None) == (G is None):
            raise ModelError(f"component {name!r}: give exactly one of R (resistance) or G (conductance)")
        require_positive(name, "R" if R is not None else "G", R if R is not None else G)
        self.R, self.G = R, G

    def piece(self) -> Piece:
        port = self._port("p", "electrical")
        if self.R is not None:
            sym, decl = self._param("R", self.R, "Ohm", "resistance")
            return linear_resistor_piece(self, port, sym, False, decl)
        sym, decl = self._param("G", self.G, "S", "conductance")
        return linear_resistor_piece(self, port, sym, True, decl)


class VoltageSource(Component):
    """Ideal voltage source: input ``{name}`` [V], conjugate output ``{name}.i`` [A].

    Examples
    --------
    >>> VoltageSource("U").piece().sources[0].info.output
    'U.i'
    """

    def __init__(self, name: str, range=None):
        super().__init__(name)
        self.range = range

    def piece(self) -> Piece:
        return source_piece(self, self._port("p", "electrical", supplies=True), "effort", "V", f"{self.name}.i", "A",
                            "source voltage", self.range)


class CurrentSource(Component):
    """Ideal current source: input ``{name}`` [A], conjugate output ``{name}.v`` [V].

    Examples
    --------
    >>> CurrentSource("I").piece().sources[0].info.kind
    'flow'
    """

    def __init__(self, name: str, range=None):
        super().__init__(name)
        self.range = range

    def piece(self) -> Piece:
        return source_piece(self, self._port("p", "electrical", supplies=True), "flow", "A", f"{self.name}.v", "V",
                            "source current", self.range)


class DriftBranch(Component):
    """Charge-retention element: capacitor C1 in parallel with resistor R1 (one port).

    In the curling HASEL model this branch sits in series with the electrode
    capacitor; charge trapped on C1 leaks through R1, which slowly changes the
    voltage across the electrodes (drift).  Equations at the port (V, i):
    ``V = Q1 / C1``, ``Q1' = i - V / R1``.  State ``{name}.Q`` (or ``state=``).

    Parameters
    ----------
    name : str
    C1 : float, Param or expression
        Retention capacitance [F].
    R1 : float, Param or expression
        Leakage resistance [Ohm].

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import VoltageSource, Resistor
    >>> s = interconnect("drift", [VoltageSource("U"), Resistor("R0", R=1e3), DriftBranch("D", C1=1e-5, R1=1e6)],
    ...                  [series("U", "R0", "D")])
    >>> sp.simplify(s.R[0, 0] - (1/s.param("R0.R").symbol + 1/s.param("D.R1").symbol))
    0
    """

    def __init__(self, name: str, C1=1.75e-5, R1=1e6, *, state: str | None = None, range=None):
        super().__init__(name)
        require_positive(name, "C1", C1)
        require_positive(name, "R1", R1)
        self.C1, self.R1, self._state_name, self._range = C1, R1, state, range

    def piece(self) -> Piece:
        c1, d1 = self._param("C1", self.C1, "F", "charge-retention capacitance")
        r1, d2 = self._param("R1", self.R1, "Ohm", "charge-leakage resistance")
        cval = d1[0].value if d1 else 1e-5
        rng = self._range or (-1e4 * cval, 1e4 * cval)
        st = self._state("Q", self._state_name, "C", rng, "retained charge", "C", "electrical")
        outer = self._port("p", "electrical")
        res = self._port("R1", "electrical")
        q = st.port
        rels = (
            Relation(q.effort - outer.effort, self.name, "junction"),
            Relation(res.effort - outer.effort, self.name, "junction"),
            Relation(outer.flow - q.flow - res.flow, self.name, "junction"),
            Relation(res.effort - r1 * res.flow, self.name, "resistive"),
        )
        return Piece(
            self.name,
            storages=(st,),
            energy=(EnergyTerm(self.name, st.state.symbol**2 / (2 * c1)),),
            ports=(outer,),
            internal=(res,),
            relations=rels,
            dissipators=(Dissipator(f"{self.name}.R1", (res,)),),
            params=d1 + d2,
        )
