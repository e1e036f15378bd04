"""Power-conserving two-ports: (modulated) transformer and gyrator.

Port ``a`` takes power from the network, port ``b`` gives it back:
``a.effort * a.flow == b.effort * b.flow``.
"""

from __future__ import annotations

import sympy as sp

from phs.component import Component, Piece, Relation


class Transformer(Component):
    """Transformer ``f_b = n f_a``, ``e_a = n e_b``; ``n`` may depend on states (modulated).

    The curling HASEL's geometric coupling ``l_p' = (2 A_s / l_p) theta'`` is a
    modulated transformer from the rotation to the top-film length.

    Parameters
    ----------
    name : str
    ratio : float, Param or sympy expression
        Modulus n (unit ``unit``).
    domains : (str, str)
        Domains of ports a and b.

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import Mass, LinearSpring
    >>> s = interconnect("lever", [Mass("m"), Transformer("tf", 2.0), LinearSpring("k")],
    ...                  [series("m", "tf.a"), series("tf.b", "k")])
    >>> s.J.tolist()
    [[0, -tf.n], [tf.n, 0]]
    """

    def __init__(self, name: str, ratio, unit: str = "1", domains=("any", "any")):
        super().__init__(name)
        self.ratio, self.unit, self.domains = ratio, unit, domains

    def piece(self) -> Piece:
        n, decl = self._param("n", self.ratio, self.unit, "transformer ratio")
        a = self._port("a", self.domains[0])
        b = self._port("b", self.domains[1], supplies=True)
        rels = (Relation(b.flow - n * a.flow, self.name, "transformer"),
                Relation(a.effort - n * b.effort, self.name, "transformer"))
        return Piece(self.name, ports=(a, b), relations=rels, params=decl)


class Gyrator(Component):
    """Gyrator ``e_a = n f_b``, ``e_b = n f_a`` (e.g. an electromechanical transducer).

    Examples
    --------
    >>> from phs import interconnect, series
    >>> from components import Inductor, Mass
    >>> s = interconnect("motor", [Inductor("L"), Gyrator("k", 0.1), Mass("m")],
    ...                  [series("L", "k.a"), series("k.b", "m")])
    >>> s.J.tolist()
    [[0, -k.n], [k.n, 0]]
    """

    def __init__(self, name: str, ratio, unit: str = "1", domains=("any", "any")):
        super().__init__(name)
        self.ratio, self.unit, self.domains = ratio, unit, domains

    def piece(self) -> Piece:
        n, decl = self._param("n", self.ratio, self.unit, "gyrator modulus")
        a = self._port("a", self.domains[0])
        b = self._port("b", self.domains[1], supplies=True)
        rels = (Relation(a.effort - n * b.flow, self.name, "gyrator"),
                Relation(b.effort - n * a.flow, self.name, "gyrator"))
        return Piece(self.name, ports=(a, b), relations=rels, params=decl)


__all__ = ["Transformer", "Gyrator", "sp"]
