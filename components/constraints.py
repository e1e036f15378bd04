"""Geometric constraints and definitions of geometric variables.

A geometric variable (the zipped electrode length ``l_e`` of a HASEL) is not
a state: it is defined by a relation among states and parameters, solved
here for the variable and substituted wherever the variable appears (energy,
transformer ratios, measured outputs).  Validity conditions travel with it
and the simulator stops with a clear message when a trajectory leaves them.
"""

from __future__ import annotations

import sympy as sp

from phs.component import Component, Definition, Piece
from phs.errors import ModelError
from phs.params import Condition, Param, check_name


def geometric_symbol(name: str) -> sp.Symbol:
    """Symbol of a geometric variable, for use in other components' expressions.

    Examples
    --------
    >>> geometric_symbol("seg1.l_e")
    seg1.l_e
    """
    return sp.Symbol(check_name(name, "geometric variable"), real=True)


class Geometry(Component):
    """Explicit definitions of geometric variables, ``{name: expression}``.

    Parameters
    ----------
    name : str
    definitions : dict of str -> sympy expression
    params : sequence of Param used in the expressions
    conditions : sequence of (label, expr) meaning ``expr >= 0``
    units : dict of str -> unit string

    Examples
    --------
    >>> from phs.component import symbol_of_state
    >>> th = symbol_of_state("theta")
    >>> Geometry("geo", {"tip": 0.1 * sp.sin(th)}).piece().definitions[0].symbol
    tip
    """

    def __init__(self, name: str, definitions: dict, params=(), conditions=(), units=None):
        super().__init__(name)
        self.defs = {check_name(k, "geometric variable"): sp.sympify(v) for k, v in definitions.items()}
        self.params, self.conds, self.units = tuple(params), tuple(conditions), dict(units or {})

    def piece(self) -> Piece:
        defs = tuple(Definition(geometric_symbol(k), v, self.name, self.units.get(k, "1")) for k, v in self.defs.items())
        conds = tuple(Condition(f"{self.name}: {lab}", sp.sympify(e)) for lab, e in self.conds)
        return Piece(self.name, definitions=defs, params=self.params, conditions=conds)


class GeometricConstraint(Component):
    """A relation among geometric variables solved for a dependent one.

    Parameters
    ----------
    name : str
    variable : str
        Name of the dependent geometric variable (use :func:`geometric_symbol`
        for it inside ``relation`` and in other components).
    relation : sympy Eq or expression (== 0)
        E.g. volume conservation ``A_T == A_s + X_h (L_e - l_e)``.
    params : sequence of Param appearing in the relation
    conditions : sequence of (label, expr) meaning ``expr >= 0``; may use the variable
    branch : int
        Which solution to take when the relation has several.

    Raises
    ------
    ModelError
        If the relation cannot be solved for the variable.

    Examples
    --------
    >>> from phs.component import symbol_of_state
    >>> th = symbol_of_state("theta")
    >>> le = geometric_symbol("l_e")
    >>> c = GeometricConstraint("vol", "l_e", sp.Eq(1, th + 2 * le), conditions=[("l_e >= 0", le)])
    >>> c.piece().definitions[0].expr
    1/2 - theta/2
    """

    def __init__(self, name: str, variable: str, relation, params=(), conditions=(), branch: int = 0, unit: str = "1"):
        super().__init__(name)
        self.variable = geometric_symbol(variable)
        rel = relation.lhs - relation.rhs if isinstance(relation, sp.Equality) else sp.sympify(relation)
        if self.variable not in rel.free_symbols:
            raise ModelError(f"component {name!r}: the relation does not contain the variable {variable!r}")
        self.relation, self.params, self.conds, self.branch, self.unit = rel, tuple(params), tuple(conditions), branch, unit
        for p in self.params:
            if not isinstance(p, Param):
                raise ModelError(f"component {name!r}: {p!r} in params is not a Param")

    def piece(self) -> Piece:
        try:
            sols = sp.solve(self.relation, self.variable, dict=False)
        except (NotImplementedError, ValueError) as exc:
            raise ModelError(f"component {self.name!r}: cannot solve the relation for {self.variable}: {exc}") from None
        if not sols:
            raise ModelError(f"component {self.name!r}: the relation has no solution for {self.variable}")
        if self.branch >= len(sols):
            raise ModelError(f"component {self.name!r}: branch {self.branch} requested but only {len(sols)} solution(s)")
        expr = sols[self.branch]
        conds = tuple(Condition(f"{self.name}: {lab}", sp.sympify(e).xreplace({self.variable: expr}))
                      for lab, e in self.conds)
        return Piece(self.name, definitions=(Definition(self.variable, expr, self.name, self.unit),),
                     params=self.params, conditions=conds)
