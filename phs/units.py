"""Dimensional analysis of model expressions.

Units are written as products of powers of unit names, e.g. ``"N*m/rad"``,
``"kg*m**2"``, ``"V"``, ``"1"``.  Only dimensions are checked (prefixes and
scales do not matter here): every term of a Hamiltonian must come out in
joules, arguments of transcendental functions must be dimensionless, and the
terms of a sum must agree.
"""

from __future__ import annotations

from fractions import Fraction

import sympy as sp

from phs.errors import UnitError
from phs.safe_parse import Arithmetic, evaluate

# exponents of (m, kg, s, A, K, mol, cd)
_BASE = {
    "m": (1, 0, 0, 0, 0, 0, 0),
    "kg": (0, 1, 0, 0, 0, 0, 0),
    "s": (0, 0, 1, 0, 0, 0, 0),
    "A": (0, 0, 0, 1, 0, 0, 0),
    "K": (0, 0, 0, 0, 1, 0, 0),
    "mol": (0, 0, 0, 0, 0, 1, 0),
    "cd": (0, 0, 0, 0, 0, 0, 1),
}
_DERIVED = {
    "1": "1",
    "rad": "1",
    "sr": "1",
    "N": "kg*m/s**2",
    "J": "kg*m**2/s**2",
    "W": "kg*m**2/s**3",
    "Pa": "kg/(m*s**2)",
    "Hz": "1/s",
    "C": "A*s",
    "V": "kg*m**2/(A*s**3)",
    "F": "A**2*s**4/(kg*m**2)",
    "Ohm": "kg*m**2/(A**2*s**3)",
    "S": "A**2*s**3/(kg*m**2)",
    "H": "kg*m**2/(A**2*s**2)",
    "Wb": "kg*m**2/(A*s**2)",
    "T": "kg/(A*s**2)",
    "g": "kg",
    "mm": "m",
    "cm": "m",
    "um": "m",
    "ms": "s",
    "kV": "V",
    "mA": "A",
    "uA": "A",
    "kN": "N",
    "mN": "N",
    "L": "m**3",
    "bar": "Pa",
    "deg": "1",
}

Dim = tuple[Fraction, ...]
DIMENSIONLESS: Dim = tuple(Fraction(0) for _ in range(7))
_UNIT_CACHE: dict[str, Dim] = {}


def _mul(a: Dim, b: Dim) -> Dim:
    return tuple(x + y for x, y in zip(a, b))


def _pow(a: Dim, k: Fraction) -> Dim:
    return tuple(x * k for x in a)


class _UnitNames(Arithmetic):
    """Products of powers of names and numbers; every name is a unit symbol, checked by :func:`parse_unit`."""

    operators = frozenset({"*", "/", "**"})

    def __init__(self):
        super().__init__({}, exact=True)

    def name(self, name: str):
        """Any name is a unit symbol here."""
        return sp.Symbol(name)


_MAX_UNIT_LENGTH = 200


def unit_expression(unit: str, where: str = "") -> sp.Expr:
    """The unit string as a sympy product of powers of unit-name symbols, read by the safe parser.

    Any name is accepted here (:func:`parse_unit` then checks it is a known
    unit); anything but names, numbers, ``*``, ``/`` and ``**`` (or ``^``)
    is refused, and nothing is evaluated.

    Parameters
    ----------
    unit : str
        The unit, e.g. ``"N*m/rad"``.
    where : str, optional
        Where the unit comes from (``"params[2].unit"``), said first in errors.

    Raises
    ------
    UnitError
        Naming ``where`` and the unit string, when the text is not a product
        of powers of names.

    Examples
    --------
    >>> unit_expression("kg*m^2/s")
    kg*m**2/s
    >>> try:
    ...     unit_expression("__import__('os')", "params[2].unit")
    ... except UnitError as err:
    ...     print(err)
    params[2].unit: unit "__import__('os')": name '__import__' is not allowed (names with '__' are reserved)
    """
    prefix = f"{where}: " if where else ""
    if not isinstance(unit, str):
        raise UnitError(f"{prefix}a unit must be text, not {type(unit).__name__}")
    text = unit.replace("^", "**").replace("Ω", "Ohm").strip() or "1"
    label = prefix + (f"unit {unit!r}" if len(unit) <= 60 else "a unit")
    return evaluate(text, label, _UnitNames(), error=UnitError, max_length=_MAX_UNIT_LENGTH)


def parse_unit(unit: str, where: str = "") -> Dim:
    """Dimension of a unit string as exponents of (m, kg, s, A, K, mol, cd).

    Parameters
    ----------
    unit : str
        A product of powers of unit names (``"N*m/rad"``, ``"kg*m**2"``, ``"m^2"``).
    where : str, optional
        Where the unit comes from, said first in errors.

    Raises
    ------
    UnitError
        If the string uses an unknown unit name or is not a product of powers.

    Examples
    --------
    >>> parse_unit("N*m/rad") == parse_unit("J")
    True
    >>> format_dim(parse_unit("V*A"))
    'kg*m**2/s**3'
    """
    key = (unit.strip() or "1") if isinstance(unit, str) else None
    if key in _UNIT_CACHE:
        return _UNIT_CACHE[key]
    expr = unit_expression(unit, where)
    try:
        dim = _dim_of_unit_expr(expr, unit)
    except UnitError as exc:
        if not where:
            raise
        raise UnitError(f"{where}: {exc}") from None
    _UNIT_CACHE[key] = dim
    return dim


def _dim_of_unit_expr(expr: sp.Expr, unit: str) -> Dim:
    if expr.is_Number:
        return DIMENSIONLESS
    if expr.is_Symbol:
        n = expr.name
        if n in _BASE:
            return tuple(Fraction(v) for v in _BASE[n])
        if n in _DERIVED:
            return parse_unit(_DERIVED[n]) if _DERIVED[n] != "1" else DIMENSIONLESS
        raise UnitError(f"unknown unit {n!r} in {unit!r}")
    if expr.is_Mul:
        d = DIMENSIONLESS
        for a in expr.args:
            d = _mul(d, _dim_of_unit_expr(a, unit))
        return d
    if expr.is_Pow and expr.exp.is_Rational:
        return _pow(_dim_of_unit_expr(expr.base, unit), Fraction(int(expr.exp.p), int(expr.exp.q)))
    raise UnitError(f"cannot read unit {unit!r}: only products of powers of unit names are allowed")


def format_dim(dim: Dim) -> str:
    """Readable SI form of a dimension (``kg*m**2/s**2``).

    Examples
    --------
    >>> format_dim(parse_unit("J"))
    'kg*m**2/s**2'
    """
    names = ["m", "kg", "s", "A", "K", "mol", "cd"]
    order = [1, 0, 2, 3, 4, 5, 6]
    num, den = [], []
    for i in order:
        e = dim[i]
        if e == 0:
            continue
        a = abs(e)
        txt = names[i] if a == 1 else f"{names[i]}**{a}"
        (num if e > 0 else den).append(txt)
    s = "*".join(num) if num else "1"
    if den:
        s += "/" + (den[0] if len(den) == 1 else "(" + "*".join(den) + ")")
    return s


_TRANSCENDENTAL = (
    sp.sin, sp.cos, sp.tan, sp.asin, sp.acos, sp.atan, sp.exp, sp.log,
    sp.sinh, sp.cosh, sp.tanh, sp.erf, sp.erfc, sp.asinh, sp.atanh, sp.acosh,
)


class _Mismatch(Exception):
    pass


def _float_exponent(exp) -> Fraction | None:
    """A floating-point exponent that is exactly a fraction of denominator at most 12 (``-0.5``), else None."""
    if not exp.is_Float:
        return None
    f = Fraction(float(exp)).limit_denominator(12)
    return f if float(f) == float(exp) else None


def dimension(expr: sp.Expr, units: dict[sp.Symbol, Dim], free_floats: bool = False) -> Dim | None:
    """Dimension of ``expr`` given the dimension of each symbol.

    Raises ``UnitError`` naming the offending sub-expression when a sum mixes
    dimensions or a transcendental function receives a dimensioned argument.

    With ``free_floats``, a floating-point number (``35.15``, not ``2`` or ``1/2``) is a constant whose
    unit was not declared: it takes whatever dimension its place requires, and an expression whose
    dimension rests on one comes out as None (undecided) rather than dimensionless.  So do zero, NaN and
    the infinities, which carry no unit of their own (the zero branch of a contact force
    ``Piecewise((k*x, x > 0), (0, True))``, the bound of ``Max(0, F)``), and a floating-point exponent
    that is exactly a simple fraction (``x**-0.5``) is that fraction.

    Examples
    --------
    >>> k, x = sp.symbols("k x")
    >>> format_dim(dimension(k * x**2 / 2, {k: parse_unit("N/m"), x: parse_unit("m")}))
    'kg*m**2/s**2'
    >>> m = parse_unit("m")
    >>> dimension(x + 2.5 * k, {x: m, k: m}, free_floats=True) == m, dimension(2.5 * x, {x: m}, free_floats=True)
    (True, None)
    >>> dimension(sp.Max(0, k * x), {x: m, k: m}, free_floats=True) == parse_unit("m**2")
    True
    """
    cache: dict[sp.Expr, Dim | None] = {}

    def same(dims, e, what):
        known = [x for x in dims if x is not None]
        if any(x != known[0] for x in known):
            raise UnitError(what)
        return known[0] if known else None

    def plain(a, e) -> None:
        if rec(a) not in (DIMENSIONLESS, None):
            raise UnitError(f"argument of {e.func.__name__} is not dimensionless in {e}")

    def rec(e: sp.Expr) -> Dim | None:
        if e in cache:
            return cache[e]
        if e.is_Number or e.is_NumberSymbol:
            d = None if free_floats and (e.is_Float or e.is_zero or not e.is_finite) else DIMENSIONLESS
        elif e.is_Symbol:
            if e not in units:
                raise UnitError(f"no unit known for symbol {e}")
            d = units[e]
        elif e.is_Add:
            dims = [rec(a) for a in e.args]
            known = [(a, x) for a, x in zip(e.args, dims) if x is not None]
            for a, da in known[1:]:
                if da != known[0][1]:
                    raise UnitError(
                        f"sum mixes dimensions: {known[0][0]} is {format_dim(known[0][1])} but {a} is {format_dim(da)}"
                    )
            d = known[0][1] if known else None
        elif e.is_Mul:
            dims = [rec(a) for a in e.args]
            d = DIMENSIONLESS
            for x in dims:
                d = None if d is None or x is None else _mul(d, x)
        elif e.is_Pow:
            db = rec(e.base)
            exact = _float_exponent(e.exp) if free_floats else None  # x**-0.5, as sympy leaves 1/sqrt(4.0*x**2)
            if e.exp.is_Rational or exact is not None:
                d = None if db is None else _pow(db, exact if exact is not None else Fraction(str(e.exp)))
            else:
                if rec(e.exp) not in (DIMENSIONLESS, None) or db not in (DIMENSIONLESS, None):
                    raise UnitError(f"non-integer power of a dimensioned quantity: {e}")
                d = DIMENSIONLESS
        elif isinstance(e, _TRANSCENDENTAL):
            for a in e.args:
                plain(a, e)
            d = DIMENSIONLESS
        elif isinstance(e, (sp.Abs, sp.re, sp.im)):
            d = rec(e.args[0])
        elif isinstance(e, (sp.sign, sp.Heaviside)):
            rec(e.args[0])
            d = DIMENSIONLESS
        elif isinstance(e, (sp.Max, sp.Min)):
            d = same([rec(a) for a in e.args], e, f"{e.func.__name__} mixes dimensions in {e}")
        elif isinstance(e, sp.atan2):
            same([rec(a) for a in e.args], e, f"atan2 arguments differ in dimension in {e}")
            d = DIMENSIONLESS
        elif isinstance(e, sp.Piecewise):
            d = same([rec(c[0]) for c in e.args], e, f"branches of a piecewise expression differ in dimension in {e}")
        elif hasattr(e, "_dimension"):  # custom functions declare how they combine their arguments' dimensions
            dims = [rec(a) for a in e.args]
            d = None if None in dims else e._dimension(dims)
        else:
            raise UnitError(f"cannot determine the dimension of {e}")
        cache[e] = d
        return d

    return rec(sp.sympify(expr, strict=True))  # a sympy expression, never text


JOULE = parse_unit("J")
