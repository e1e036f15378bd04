"""Unit conversion of recorded signals: a unit written in a file (``kV``, ``mm``, ``kg*m/s``) to the model's.

One converter, :func:`unit_factor`, serves the recordings of every workflow (``Recording``, ``phs simulate
--input``, ``--scale``); units are read by the whitelist parser of :mod:`phs.units`, never evaluated.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np  # noqa: F401 (doctests)
import sympy as sp

from phs.errors import InputDataError, UnitError
from phs.units import dimension, format_dim, parse_unit, unit_expression

# unit names a recording may use: name -> (multiplier to SI, the SI unit); SI prefixes apply to these
_NAMED = {
    **{u: (sp.Integer(1), u) for u in ("m", "s", "V", "A", "N", "Ohm", "F", "C", "J", "W", "Pa", "rad", "Hz", "S", "H",
                                       "Wb", "T", "K", "mol")},
    "g": (sp.Rational(1, 1000), "kg"), "L": (sp.Rational(1, 1000), "m**3"), "bar": (sp.Integer(10) ** 5, "Pa"),
}
# names without prefixes: angles and clock times
_PLAIN = {"deg": (sp.pi / 180, "rad"), "min": (sp.Integer(60), "s"), "h": (sp.Integer(3600), "s")}
_PREFIX = {"G": 9, "M": 6, "k": 3, "c": -2, "m": -3, "u": -6, "µ": -6, "μ": -6, "n": -9, "p": -12}


def _name_si(name: str) -> tuple[sp.Expr, str]:
    """Multiplier to SI and the SI unit of one unit name (``mm`` -> (1/1000, ``m``))."""
    if name in _PLAIN:
        return _PLAIN[name]
    if name in _NAMED:
        return _NAMED[name]
    if name[:1] in _PREFIX and name[1:] in _NAMED:
        f, base = _NAMED[name[1:]]
        return sp.Integer(10) ** _PREFIX[name[:1]] * f, base
    raise UnitError(f"unknown unit {name!r} (known: an SI prefix {', '.join(p for p in _PREFIX if p != 'μ')} and "
                    f"one of {', '.join(_NAMED)}, or {', '.join(_PLAIN)})")


@lru_cache(maxsize=512)
def _si(unit: str) -> tuple[sp.Expr, tuple]:
    """Exact multiplier to SI and dimension of a unit (a product of powers of unit names, ``kg*m/s``)."""
    expr = unit_expression(unit)
    multiplier, dims = {}, {}
    for sym in expr.free_symbols:
        multiplier[sym], base = _name_si(sym.name)
        dims[sym] = parse_unit(base)
    return expr.xreplace(multiplier), dimension(expr, dims)


def _conversion(from_unit: str, to_unit: str) -> float:
    """Factor from ``from_unit`` to ``to_unit``; UnitError with the reason when there is none."""
    (f, df), (g, dg) = _si(from_unit), _si(to_unit)
    if df != dg:
        raise UnitError(f"different dimensions ({format_dim(df)} and {format_dim(dg)})")
    return float(f / g)


def unit_factor(from_unit: str, to_unit: str) -> float:
    """Factor converting values in ``from_unit`` to ``to_unit`` (e.g. ``mm`` -> ``m`` is 1e-3).

    A unit is a product of powers of unit names (``mm``, ``kV``, ``kg*m/s``, ``mm/s**2``), read by
    :func:`phs.units.unit_expression` (never evaluated as code).  A name is one of ``m s V A N Ohm
    F C J W Pa rad Hz S H Wb T K mol g L bar``, optionally after one SI prefix (``G M k c m u µ n
    p``), or ``deg``, ``min``, ``h``.  ``1``, ``rad`` and ``deg`` are dimensionless.

    Raises
    ------
    InputDataError
        If a unit is unknown or not a unit, or the dimensions differ.

    Examples
    --------
    >>> unit_factor("mm", "m"), unit_factor("kV", "V"), unit_factor("deg", "rad") == np.pi / 180
    (0.001, 1000.0, True)
    >>> unit_factor("g*mm/ms", "kg*m/s"), unit_factor("mA", "A")
    (0.001, 0.001)
    >>> unit_factor("s", "m")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: cannot convert 's' to 'm': different dimensions (s and m)
    """
    try:
        return _conversion(from_unit, to_unit)
    except UnitError as exc:  # an unknown name, or text that is not a unit (read by phs.safe_parse)
        raise InputDataError(f"cannot convert {from_unit!r} to {to_unit!r}: {exc}") from None


def column_factor(source: str, column: str, from_unit: str, to_unit: str, signal: str | None = None) -> float:
    """Factor converting the column ``column`` of ``source``, in ``from_unit``, to ``to_unit`` (the model's
    unit of ``signal``, default the column's name), or an InputDataError of one line naming them all.

    Examples
    --------
    >>> column_factor("r.csv", "U", "kV", "V")
    1000.0
    >>> column_factor("r.csv", "pos", "s", "m", "position")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: r.csv: column 'pos' is in 's', which cannot be converted to 'm', ... different dimensions (s and m)
    """
    try:
        return _conversion(from_unit, to_unit)
    except UnitError as exc:
        of = signal if signal is not None else column
        raise InputDataError(f"{source}: column {column!r} is in {from_unit!r}, which cannot be converted to "
                             f"{to_unit!r}, the model's unit of {of!r}: {exc}") from None


def model_units(system) -> dict[str, str]:
    """Unit of each signal of ``system`` a recording may hold: inputs, port outputs, measured outputs, states
    (as :meth:`codegen.results.SimulationResult.unit` names them).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> model_units(mass_spring_damper())
    {'m.p': 'kg*m/s', 'k.l': 'm', 'F': 'N', 'F.v': 'm/s', 'position': 'm'}
    """
    units = {st.name: st.unit for st in system.states}
    units.update({i.name: i.unit for i in system.inputs})
    units.update({i.output: i.output_unit for i in system.inputs})
    units.update({m.name: m.unit for m in system.measured})
    return units
