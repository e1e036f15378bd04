"""Parameters, states and inputs: named symbols with units, values and ranges."""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, fields

import sympy as sp

from phs.errors import ModelError, ParameterError, ParameterRangeWarning

RANGE_ROUNDING = 4e-16
"""Relative slack of the range checks: a bound computed from a value (``10 * 1e-6`` is ``9.999999999999999e-06``)
holds that value's own rounding, and a value a user typed as the bound is inside it."""


def within(v: float, lo: float, hi: float) -> bool:
    """Whether ``v`` lies in ``[lo, hi]``, each bound widened by its rounding (:data:`RANGE_ROUNDING`).

    Examples
    --------
    >>> within(1e-5, 1e-7, 10 * 1e-6), within(1.001e-5, 1e-7, 10 * 1e-6)
    (True, False)
    """
    return lo - RANGE_ROUNDING * abs(lo) <= v <= hi + RANGE_ROUNDING * abs(hi)


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")


def check_name(name: str, what: str) -> str:
    """Return ``name`` if it is a valid dotted identifier, else raise.

    Examples
    --------
    >>> check_name("seg2.theta", "state")
    'seg2.theta'
    """
    if not isinstance(name, str) or not _NAME.match(name) or "__" in name:
        raise ModelError(
            f"invalid {what} name {name!r}: use letters, digits and '_' in dot-separated "
            "parts that do not start with a digit, and no '__' (reserved for C identifiers)"
        )
    return name


def c_identifier(name: str) -> str:
    """C-safe identifier of a dotted name (``seg2.theta`` -> ``seg2__theta``).

    Examples
    --------
    >>> c_identifier("seg2.theta")
    'seg2__theta'
    """
    return name.replace(".", "__")


@dataclass(frozen=True)
class Param:
    """A model parameter: a symbol with a value, a unit and a sentence.

    Parameters
    ----------
    name : str
        Dotted name; the paper's symbol for shared physics (``K_b``), prefixed
        with the component for local ones (``seg2.K_b``).
    value : float or None
        Default value (SI units).  ``None`` means the user must supply it.
    unit : str
        Unit expression such as ``"N*m/rad"`` (see :mod:`phs.units`).
    description : str
        One sentence saying what the parameter is.
    range : (float, float), optional
        Physical range used by checks and sampling.  Defaults to a decade
        either side of a positive value, or ``[-|v|-1, |v|+1]`` otherwise.
        A declared value outside it is refused (:class:`ParameterError`); a value
        set later (:meth:`with_value`, ``with_params``) only warns (:meth:`checked`).
    positive : bool, optional
        Whether the symbol carries sympy's ``positive`` assumption (used to
        decide definiteness symbolically).  Defaults to ``value > 0``.

    Examples
    --------
    >>> K_b = Param("K_b", 0.04, "N*m/rad", "torsional stiffness of the bottom film")
    >>> K_b.symbol, K_b.range
    (K_b, (0.004, 0.4))
    >>> Param("K_b", 0.5, "N*m/rad", range=(0.01, 0.1))
    Traceback (most recent call last):
    ...
    phs.errors.ParameterError: parameter 'K_b' = 0.5 [N*m/rad] is outside its declared range [0.01, 0.1]
    """

    name: str
    value: float | None
    unit: str = "1"
    description: str = ""
    range: tuple[float, float] | None = None
    positive: bool | None = None

    def __post_init__(self) -> None:
        check_name(self.name, "parameter")
        if self.value is not None:
            try:
                v = float(self.value)
            except (TypeError, ValueError):
                raise ModelError(f"parameter {self.name!r}: value {self.value!r} is not a number") from None
            if not math.isfinite(v):
                raise ModelError(f"parameter {self.name!r}: value {v} is not finite")
            object.__setattr__(self, "value", v)
        if self.positive is None:
            object.__setattr__(self, "positive", self.value is not None and self.value > 0)
        if self.range is None:
            v = self.value
            if v is None:
                rng = (0.0, 1.0) if self.positive else (-1.0, 1.0)
            elif v > 0:
                rng = (v / 10.0, v * 10.0)
            else:
                rng = (-abs(v) - 1.0, abs(v) + 1.0)
            object.__setattr__(self, "range", rng)
        try:
            lo, hi = (float(r) for r in self.range)
        except (TypeError, ValueError):
            raise ModelError(f"parameter {self.name!r}: range {self.range!r} is not a pair of numbers (lo, hi)") from None
        if not lo <= hi:
            raise ModelError(f"parameter {self.name!r}: range [{lo}, {hi}] has lower > upper")
        object.__setattr__(self, "range", (lo, hi))
        if self.positive and self.value is not None and not self.value > 0:
            raise ModelError(f"parameter {self.name!r} is declared positive but its value is {self.value:g}")
        if self.value is not None and not within(self.value, lo, hi):
            raise ParameterError(f"parameter {self.name!r} = {self.value:g} [{self.unit}] is outside its declared range "
                                 f"[{lo:g}, {hi:g}]")

    def _copy(self, **changes) -> Param:
        """Copy with fields changed, without the checks of a declaration: only for a value that passed
        :meth:`checked` (which warns, not refuses, outside the declared range) or a new name."""
        out = object.__new__(Param)
        for f in fields(Param):
            object.__setattr__(out, f.name, changes.get(f.name, getattr(self, f.name)))
        return out

    def checked(self, value, where: str = "") -> float:
        """``value`` as a float, refused unless finite and of the declared sign; warned outside the range.

        Every value that enters from outside (``with_params``, ``params=`` overrides, ``--param``)
        passes here: a parameter declared positive (a resistance, a capacitance, a mass) refuses
        zero and negative values with a :class:`ParameterError` naming it; a value outside the
        declared range is accepted with a :class:`ParameterRangeWarning` (ranges bound sampling and
        fits, not physics: a fit may end outside them when given wider bounds, a study may look
        past them) and the range is kept.  Only a declaration whose own value lies outside its
        range is refused (:class:`Param`).  ``where`` is appended to the message (e.g. ``" (--param)"``).

        Examples
        --------
        >>> Param("C", 1e-6, "F").checked(2e-6)
        2e-06
        >>> Param("C", 1e-6, "F").checked(-1e-6)
        Traceback (most recent call last):
        ...
        phs.errors.ParameterError: parameter 'C' [F] is declared positive; value -1e-06 refused
        """
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ParameterError(f"parameter {self.name!r}: value {value!r} is not a number{where}") from None
        if not math.isfinite(v):
            raise ParameterError(f"parameter {self.name!r}: value {v} is not finite{where}")
        if self.positive and not v > 0:
            raise ParameterError(f"parameter {self.name!r} [{self.unit}] is declared positive; value {v:g} refused{where}")
        lo, hi = self.range
        if not within(v, lo, hi):
            warnings.warn(f"parameter {self.name!r} = {v:g} is outside its declared range [{lo:g}, {hi:g}]{where}",
                          ParameterRangeWarning, stacklevel=3)
        return v

    @property
    def symbol(self) -> sp.Symbol:
        """The sympy symbol of this parameter."""
        return param_symbol(self.name, bool(self.positive))

    # Arithmetic acts on the symbol, so ``eps * A / (g0 - x)`` may be written with the Params
    # themselves; the expression refers to the symbols only, so the Params are still declared
    # where the model is built (``interconnect(params=[...])``).
    def _sympy_(self) -> sp.Symbol:
        """The symbol, for ``sympy.sympify`` and sympy functions (``sp.sqrt(k)``).

        Examples
        --------
        >>> import sympy as sp
        >>> k, m = Param("k", 50.0, "N/m"), Param("m", 1e-3, "kg")
        >>> sp.sqrt(k / m), 2 * k - m
        (sqrt(k)/sqrt(m), 2*k - m)
        """
        return self.symbol

    def __add__(self, other):
        return self.symbol + _operand(other)

    def __radd__(self, other):
        return _operand(other) + self.symbol

    def __sub__(self, other):
        return self.symbol - _operand(other)

    def __rsub__(self, other):
        return _operand(other) - self.symbol

    def __mul__(self, other):
        return self.symbol * _operand(other)

    def __rmul__(self, other):
        return _operand(other) * self.symbol

    def __truediv__(self, other):
        return self.symbol / _operand(other)

    def __rtruediv__(self, other):
        return _operand(other) / self.symbol

    def __pow__(self, other):
        return self.symbol ** _operand(other)

    def __rpow__(self, other):
        return _operand(other) ** self.symbol

    def __neg__(self):
        return -self.symbol

    def __pos__(self):
        return self.symbol

    def with_value(self, value: float) -> Param:
        """Copy with another value.

        Examples
        --------
        >>> Param("R", 1e3, "Ohm").with_value(2e3).value
        2000.0
        """
        return self._copy(value=self.checked(value))

    def renamed(self, name: str) -> Param:
        """Copy under another name (used to untie a shared parameter).

        Examples
        --------
        >>> Param("K_b", 0.04, "N*m/rad").renamed("seg2.K_b").name
        'seg2.K_b'
        """
        return self._copy(name=check_name(name, "parameter"))


def stored_param(name: str, value, unit: str = "1", description: str = "", range=None, positive=None) -> Param:
    """A parameter read back from a saved model.

    A saved value may be an override outside the declared range (set by ``with_params`` or a fit given
    wider bounds, and warned then): it is restored with the same warning, not refused as a declaration
    would be.

    Examples
    --------
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     p = stored_param("R", 1e9, "Ohm", "", (1e2, 1e4), True)
    >>> p.value, p.range, "outside its declared range" in str(caught[0].message)
    (1000000000.0, (100.0, 10000.0), True)
    """
    if range is not None and isinstance(value, (int, float)) and not isinstance(value, bool):
        lo, hi = _pair(range, f"parameter {name!r}")
        if lo <= hi and not lo <= value <= hi:
            return Param(name, min(max(value, lo), hi), unit, description, (lo, hi), positive).with_value(value)
    return Param(name, value, unit, description, range, positive)


def _pair(rng, what: str) -> tuple[float, float]:
    """A declared range as a tuple of two floats (a list given by the caller is not kept: it could change)."""
    try:
        lo, hi = (float(r) for r in rng)
    except (TypeError, ValueError):
        raise ModelError(f"{what}: range {rng!r} is not a pair of numbers (lo, hi)") from None
    return lo, hi


def _operand(other):
    """The other operand of a :class:`Param`'s arithmetic: a Param's symbol, anything else as is."""
    return other.symbol if isinstance(other, Param) else other


def param_symbol(name: str, positive: bool) -> sp.Symbol:
    """Sympy symbol for a parameter name (positive or merely real)."""
    return sp.Symbol(name, positive=True) if positive else sp.Symbol(name, real=True)


def state_symbol(name: str) -> sp.Symbol:
    """Sympy symbol of a state (always real)."""
    return sp.Symbol(name, real=True)


def input_symbol(name: str) -> sp.Symbol:
    """Sympy symbol of an input (always real)."""
    return sp.Symbol(name, real=True)


TIME = sp.Symbol("t", real=True)
"""The time symbol used by input signals."""


@dataclass(frozen=True)
class StateInfo:
    """A state of a system: name, unit, physical range, scale and meaning.

    ``kind`` is ``"C"`` for displacement-like states (charge, angle, length:
    the port flow is the state's rate) and ``"I"`` for momentum-like states
    (the port effort is the state's rate).  ``rest`` is the state's value at
    rest (a spring's rest length), the default initial state of a simulation;
    without it the default is 0 moved into the range.

    Examples
    --------
    >>> StateInfo("seg1.theta", "rad", (-0.4, 0.4), scale=0.2).typical
    0.2
    >>> StateInfo("l", "m", (0.01, 0.02)).initial, StateInfo("l", "m", (0.01, 0.02), rest=0.015).initial
    (0.01, 0.015)
    """

    name: str
    unit: str = "1"
    range: tuple[float, float] = (-1.0, 1.0)
    description: str = ""
    kind: str = "C"
    scale: float | None = None
    owner: str = ""
    rest: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "range", _pair(self.range, f"state {self.name!r}"))

    @property
    def symbol(self) -> sp.Symbol:
        return state_symbol(self.name)

    @property
    def initial(self) -> float:
        """The default initial value: :attr:`rest` when declared, else 0 moved into the range."""
        if self.rest is not None:
            return float(self.rest)
        return min(max(0.0, self.range[0]), self.range[1])

    @property
    def typical(self) -> float:
        """Characteristic magnitude used to scale the state in solvers."""
        if self.scale is not None:
            return float(self.scale)
        m = max(abs(self.range[0]), abs(self.range[1]))
        return m if m > 0 else 1.0


@dataclass(frozen=True)
class InputInfo:
    """An input of a system and the name of its power-conjugate output.

    Examples
    --------
    >>> InputInfo("U", "V", output="U.i", output_unit="A").symbol
    U
    """

    name: str
    unit: str = "1"
    output: str = ""
    output_unit: str = "1"
    kind: str = "effort"
    description: str = ""
    range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.range is not None:
            object.__setattr__(self, "range", _pair(self.range, f"input {self.name!r}"))

    @property
    def symbol(self) -> sp.Symbol:
        return input_symbol(self.name)


@dataclass(frozen=True)
class Condition:
    """A validity condition ``expr >= 0`` with a label naming where it comes from.

    Examples
    --------
    >>> import sympy as sp
    >>> Condition("l_e <= L_e", 0.015 - sp.Symbol("l_e")).label
    'l_e <= L_e'
    """

    label: str
    expr: sp.Expr
    description: str = ""


@dataclass(frozen=True)
class EnergyTerm:
    """One additive term of the Hamiltonian, labelled by the component that stores it."""

    label: str
    expr: sp.Expr


@dataclass(frozen=True)
class Measured:
    """A measured output: a named function of state and input (a sensor's reading).

    Examples
    --------
    >>> import sympy as sp
    >>> Measured("tip", 0.03 * sp.sin(sp.Symbol("theta", real=True)), "m").unit
    'm'
    """

    name: str
    expr: sp.Expr
    unit: str = "1"
    description: str = ""
    command: bool = False
    """A controller's computed command (its output force, recorded by its firmware), not a sensor of the
    plant: diagnosis tries drive elements (a delay, a saturation) between this command and the plant."""
