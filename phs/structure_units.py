"""Dimensional analysis of the whole port-Hamiltonian structure, not only of the energy.

With efforts ``e_j = ∂H/∂x_j`` in ``[H]/[x_j]`` (joules per unit of the state) and flows ``ẋ_i`` in
``[x_i]/s``, the form ``ẋ = (J − R)∇H + (G − P)u``, ``y = (G + P)ᵀ∇H + (S + N)u`` fixes the unit of every
entry:

* ``J[i,j]`` and ``R[i,j]``: ``[x_i] / (s·[e_j])`` (a damper on a momentum in kg·m/s with velocity efforts
  has ``R`` in N·s/m = kg/s);
* ``G[i,k]`` and ``P[i,k]``: ``[x_i] / (s·[u_k])``;
* each port is power-conjugate: ``[u_k]·[y_k]`` is a power (W), so ``Gᵀ∇H`` comes out in the declared
  output unit exactly when ``G`` has the unit above;
* ``S[k,l]`` and ``N[k,l]``: ``[y_k] / [u_l]``;
* a measured output's expression: its declared unit.

An entry whose dimension cannot be determined is skipped and counted, never failed: one in the row
or column of a state or port whose unit was left at the default ``"1"`` (dimensionless or not
declared: it cannot be told), a function
without a dimension rule, or a product resting on a floating-point constant (``35.15 · u``: a gain
baked into the model as a number, whose unit was never declared; exact numbers such as ``1``, ``2``,
``1/2`` are dimensionless, while zero, NaN and the infinities take any unit: the zero branch of
``Piecewise((k*x, x > 0), (0, True))`` or of ``Max(0, F)`` agrees with the other).

:class:`~phs.system.PHSystem` refuses at construction an entry that this analysis decides is wrong from
declared units (:func:`construction_problems`); what it cannot decide (a skipped entry, one resting on a
parameter left at the default unit ``"1"``, a unit string that cannot be read) is left to
:meth:`~phs.system.PHSystem.check`.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> structure_unit_problems(mass_spring_damper())
([], 0)
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import sympy as sp

from phs._sparse import nonzero_entries
from phs.errors import UnitError
from phs.units import DIMENSIONLESS, JOULE, Dim, _mul, _pow, dimension, format_dim, parse_unit

WATT = parse_unit("W")
_SECOND = parse_unit("s")
_NAMED = {}
for _name in ("N", "J", "W", "Pa", "V", "C", "F", "Ohm", "H", "Wb", "T", "S", "Hz"):
    _NAMED.setdefault(parse_unit(_name), _name)


def _div(a: Dim, b: Dim) -> Dim:
    return _mul(a, _pow(b, -1))


def readable(dim: Dim) -> str:
    """SI base form of a dimension, with its derived unit's name when it has one.

    Examples
    --------
    >>> readable(parse_unit("N")), readable(parse_unit("N*s/m"))
    ('kg*m/s**2 (N)', 'kg/s')
    """
    text = format_dim(dim)
    return f"{text} ({_NAMED[dim]})" if dim in _NAMED and _NAMED[dim] != text else text


def _undeclared(unit: str) -> bool:
    """A unit left at its default ``"1"``: it may mean dimensionless or not declared, so nothing is decided on it."""
    return not isinstance(unit, str) or unit.strip() in ("", "1")


def _element(system, i: int, j: int) -> str:
    """The resistive elements acting on entry (i, j) of the dissipation matrix, as `` (damper 'b')``."""
    key = (min(i, j), max(i, j))
    labels = [label for label, entries in system.dissipators if key in entries]
    return f" (element {', '.join(map(repr, labels))})" if labels else ""


def structure_unit_problems(system, *, declared_only: bool = False) -> tuple[list[str], int]:
    """Entries of J, R, G, P, S, N, port pairs and measured outputs whose dimension is wrong, and how many were skipped.

    Parameters
    ----------
    system : PHSystem
    declared_only : bool
        Decide only on declared units: a parameter left at the default unit ``"1"`` is then undeclared
        too (as states and ports always are), and the entries resting on it are skipped.  Without it
        such a parameter is dimensionless (:meth:`~phs.system.PHSystem.check`).

    Returns
    -------
    (problems, skipped)
        One sentence per wrong entry naming it (``R[1,1] (element 'b') is kg*m/s**2 (N), expected kg/s``), and
        the number of entries whose dimension could not be determined.

    Raises
    ------
    UnitError
        When a declared unit string cannot be read (naming where it is declared).

    Examples
    --------
    >>> from dataclasses import replace
    >>> from phs.errors import ModelError
    >>> from systems.examples import mass_spring_damper
    >>> msd = mass_spring_damper()
    >>> structure_unit_problems(msd)
    ([], 0)
    >>> try:  # the constructor refuses what this function decides is wrong
    ...     msd._replace(params=[replace(q, unit="N") if q.name == "b.b" else q for q in msd.params])
    ... except ModelError as err:
    ...     print(err.problems)
    ("R[0,0] (element 'b') is kg*m/s**2 (N), expected kg/s",)
    """
    units = {s.symbol: parse_unit(s.unit, f"state {s.name!r}") for s in system.states}
    units.update({q.symbol: parse_unit(q.unit, f"parameter {q.name!r}") for q in system.params
                  if not (declared_only and _undeclared(q.unit))})  # left out: "no unit known", skipped
    units.update({u.symbol: parse_unit(u.unit, f"input {u.name!r}") for u in system.inputs})
    xs = [units[s.symbol] for s in system.states]
    us = [units[u.symbol] for u in system.inputs]
    ys = [parse_unit(u.output_unit, f"output of input {u.name!r}") for u in system.inputs]
    effort = [_div(JOULE, d) for d in xs]
    flow = [_div(d, _SECOND) for d in xs]
    names = system.state_names
    problems: list[str] = []
    skipped = 0

    def entry(expr, expected: Dim, what: str) -> None:
        nonlocal skipped
        try:
            d = dimension(expr, units, free_floats=True)
        except UnitError as exc:
            if "cannot determine" in str(exc) or "no unit known" in str(exc):
                skipped += 1
            else:
                problems.append(f"{what}: {exc}")
            return
        if d is None:  # rests on a floating-point constant whose unit was not declared
            skipped += 1
            return
        if d != expected and not (d == DIMENSIONLESS and expr.is_number and expr == 0):
            problems.append(f"{what} is {readable(d)}, expected {readable(expected)}")

    n = len(system.states)
    # a state or port left at the default unit "1" has no declared unit: entries in its row or column are skipped
    free_x = {i for i, st in enumerate(system.states) if _undeclared(st.unit)}
    free_u = {k for k, u in enumerate(system.inputs) if _undeclared(u.unit)}
    free_y = {k for k, u in enumerate(system.inputs) if _undeclared(u.output_unit)}

    def check(expr, expected, what, free) -> None:
        nonlocal skipped
        if free:
            skipped += 1
        else:
            entry(expr, expected, what)

    for label, M in (("J", system.J), ("R", system.R)):
        for i, j, v in nonzero_entries(M):
            where = f" ({names[i]}, {names[j]})" if label == "J" else _element(system, i, j)
            check(v, _div(flow[i], effort[j]), f"{label}[{i},{j}]{where}", {i, j} & free_x)
    for label, M in (("G", system.G), ("P", system.P)):
        for i, k, v in nonzero_entries(M):
            where = f" (state {names[i]!r}, input {system.inputs[k].name!r})" if label == "G" else _element(system, i, n + k)
            check(v, _div(flow[i], us[k]), f"{label}[{i},{k}]{where}", i in free_x or k in free_u)
    touched = {k for M in (system.G, system.P) for _, k, _ in nonzero_entries(M)}
    touched |= {k for M in (system.S, system.N) for k, _, _ in nonzero_entries(M)}
    for k, u in enumerate(system.inputs):
        if k in touched and k not in free_u | free_y and _mul(us[k], ys[k]) != WATT:
            problems.append(f"port {u.name!r}: input unit {u.unit!r} times unit {u.output_unit!r} of its output "
                            f"{u.output!r} is {readable(_mul(us[k], ys[k]))}, not a power (W)")
    for label, M in (("S", system.S), ("N", system.N)):
        for k, m, v in nonzero_entries(M):
            where = _element(system, n + k, n + m) if label == "S" else ""
            check(v, _div(ys[k], us[m]), f"{label}[{k},{m}]{where}", k in free_y or m in free_u)
    outs = {sp.Symbol(u.output, real=True): y for u, y in zip(system.inputs, ys)}
    units.update(outs)
    free_symbols = ({system.states[i].symbol for i in free_x} | {system.inputs[k].symbol for k in free_u}
                    | {sp.Symbol(system.inputs[k].output, real=True) for k in free_y})
    for mo in system.measured:
        expr = sp.sympify(mo.expr, strict=True)
        check(expr, parse_unit(mo.unit, f"measured output {mo.name!r}"), f"measured output {mo.name!r}",
              _undeclared(mo.unit) or expr.free_symbols & free_symbols)
    return problems, skipped


def construction_problems(system) -> list[str]:
    """The wrong entries that the declared units decide, one line each: what the constructor refuses.

    Every entry, port and measured output whose units are all declared and readable is decided by
    :func:`structure_unit_problems`; each wrong one is a line naming it, its unit and the expected
    unit.  Left to :meth:`~phs.system.PHSystem.check`: everything when a declared unit cannot be read
    (``check()`` names it), the skipped entries (see the module docstring), and the entries resting on
    a parameter whose unit was left at the default ``"1"`` (dimensionless or not declared: ``check()``
    takes it as dimensionless, the constructor cannot tell).

    Examples
    --------
    >>> import sympy as sp
    >>> from phs import Param, PHSystem, StateInfo
    >>> p = sp.Symbol("p", real=True)
    >>> m, b = Param("m", 1.0, "kg"), Param("b", 0.4, "N")  # a damper declared in N, not N*s/m
    >>> PHSystem("slide", [StateInfo("p", "kg*m/s", kind="I")], p**2 / (2 * m.symbol), [[0]], [[b.symbol]],
    ...          params=[m, b])
    Traceback (most recent call last):
    ...
    phs.errors.ModelError: invalid port-Hamiltonian system 'slide':
      - R[0,0] is kg*m/s**2 (N), expected kg/s
    """
    key = _structure_key(system)
    with _PASSED_LOCK:
        if key in _PASSED:  # the same structure and units passed already (with_params: other values only)
            _PASSED.move_to_end(key)
            return []
    try:
        problems = structure_unit_problems(system, declared_only=True)[0]
    except UnitError:  # a unit string that cannot be read: not decided here, named by check()
        return []
    if not problems:
        with _PASSED_LOCK:
            _PASSED[key] = True
            while len(_PASSED) > PASSED_CACHE:
                _PASSED.popitem(last=False)
    return problems


#: How many structures that passed :func:`construction_problems` are remembered (most recent first out last):
#: a model rebuilt with other parameter values (``with_params``, as fits and diagnoses do in their loops) is not
#: analysed again.  The hydrogel arm's ``with_params`` took 118 ms without the check, 209 ms with it uncached.
PASSED_CACHE = 32
_PASSED: OrderedDict = OrderedDict()
_PASSED_LOCK = threading.Lock()


def _structure_key(system) -> tuple:
    """What the verdict of :func:`construction_problems` depends on: every unit and every expression (not the
    parameter values; the dissipators' labels only name the culprits of a failure, which is not remembered)."""
    return (tuple((st.symbol, st.unit) for st in system.states), tuple((q.symbol, q.unit) for q in system.params),
            tuple((u.symbol, u.unit, u.output, u.output_unit) for u in system.inputs),
            system.J, system.R, system.G, system.P, system.S, system.N,
            tuple((mo.name, mo.expr, mo.unit) for mo in system.measured))
