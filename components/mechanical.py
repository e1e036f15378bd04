"""Mechanical components: masses, inertias, springs, dampers, gravity and sources.

Translational ports are (force [N], velocity [m/s]); rotational ports are
(torque [N*m], angular velocity [rad/s]).  Momentum states are "I" kind (the
port effort is the rate), displacement states are "C" kind.
"""

from __future__ import annotations

import functools

import sympy as sp

from components._base import QuadraticStorage, linear_resistor_piece, require_positive, source_piece
from phs.component import Component, Piece
from phs.errors import ModelError
from phs.params import EnergyTerm, Param


class Mass(QuadraticStorage):
    """Point mass, ``H = p**2 / (2 m)``; port (force, velocity), state ``{name}.p``.

    Examples
    --------
    >>> from phs import interconnect, series
    >>> s = interconnect("m", [Mass("m", m=2.0), LinearSpring("k", K=8.0)], [series("m", "k")])
    >>> s.state_names, s.J.tolist()
    (['m.p', 'k.l'], [[0, -1], [1, 0]])
    """

    kind = "I"
    domain = "translational"
    state_local = "p"
    state_unit = "kg*m/s"
    state_description = "momentum"

    def __init__(self, name: str, m=1.0, **kw):
        require_positive(name, "m", m)
        super().__init__(name, **kw)
        self.m = m

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return [("m", self.m, "kg", "mass")]

    def default_range(self, values) -> tuple[float, float]:
        m = values.get("m") or 1.0
        return (-10 * m, 10 * m)

    def energy(self, x) -> sp.Expr:
        return x**2 / (2 * self._syms["m"])


class RotationalInertia(Mass):
    """Rigid body rotating about a fixed axis, ``H = p**2 / (2 I)``; port (torque, angular velocity).

    Examples
    --------
    >>> RotationalInertia("J", I=1e-6).piece().storages[0].state.unit
    'kg*m**2/s'
    """

    domain = "rotational"
    state_unit = "kg*m**2/s"
    state_description = "angular momentum"

    def __init__(self, name: str, I=1e-6, **kw):  # noqa: E741
        require_positive(name, "I", I)
        QuadraticStorage.__init__(self, name, **kw)
        self.m = I

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return [("I", self.m, "kg*m**2", "moment of inertia")]

    def default_range(self, values) -> tuple[float, float]:
        i = values.get("I") or 1e-6
        return (-100 * i, 100 * i)

    def energy(self, x) -> sp.Expr:
        return x**2 / (2 * self._syms["I"])


class LinearSpring(QuadraticStorage):
    """Linear spring with rest length, ``H = K (l - L0)**2 / 2``; state is the length ``l``.

    Parameters
    ----------
    K : stiffness [N/m]
    L0 : rest length [m] (default 0: the state is then the elongation)

    Examples
    --------
    >>> LinearSpring("k", K=20.0, L0=0.015).piece().energy[0].expr
    k.K*(-k.L0 + k.l)**2/2
    """

    domain = "translational"
    state_local = "l"
    state_unit = "m"
    state_description = "length"

    def __init__(self, name: str, K=1.0, L0=0.0, **kw):
        require_positive(name, "K", K)
        super().__init__(name, **kw)
        self.K, self.L0 = K, L0

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        out = [("K", self.K, "N/m", "stiffness")]
        if not (isinstance(self.L0, (int, float)) and self.L0 == 0):
            out.append(("L0", self.L0, "m", "rest length"))
        return out

    def default_range(self, values) -> tuple[float, float]:
        L0 = values.get("L0") or 0.0
        return (L0 - max(L0, 0.1), L0 + max(L0, 0.1))

    def default_rest(self, values) -> float | None:
        """At rest the spring has its rest length ``L0`` (when ``L0`` has a value)."""
        return values.get("L0")

    def energy(self, x) -> sp.Expr:
        L0 = self._syms.get("L0", 0)
        return self._syms["K"] * (x - L0) ** 2 / 2


class TorsionalSpring(QuadraticStorage):
    """Torsional spring, ``H = K_b theta**2 / 2``; port (torque, angular velocity), state ``theta``.

    Examples
    --------
    >>> TorsionalSpring("kb", K=0.04, state="theta").piece().storages[0].state.name
    'theta'
    """

    domain = "rotational"
    state_local = "theta"
    state_unit = "rad"
    state_description = "angle"

    def __init__(self, name: str, K=1.0, **kw):
        require_positive(name, "K", K)
        super().__init__(name, **kw)
        self.K = K

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return [("K", self.K, "N*m/rad", "torsional stiffness")]

    def default_range(self, values) -> tuple[float, float]:
        return (-float(sp.pi), float(sp.pi))

    def energy(self, x) -> sp.Expr:
        return self._syms["K"] * x**2 / 2


class NonlinearSpring(QuadraticStorage):
    """Spring defined by a force law ``F(q)``; the energy ``int_0^q F`` is derived symbolically.

    Parameters
    ----------
    name : str
    force : sympy expression
        Restoring force [N] as an expression of ``variable`` (and parameters).
    variable : sympy Symbol
        The displacement symbol used in ``force``.
    params : sequence of Param
        Parameters appearing in ``force``.
    unit : str
        Unit of the displacement (default m); the force times it must be J.

    Raises
    ------
    ModelError
        If sympy cannot integrate the force law in closed form.

    Examples
    --------
    A Gaussian force law integrates to an error function:

    >>> import sympy as sp
    >>> q = sp.Symbol("q", real=True)
    >>> s = NonlinearSpring("g", force=2 * sp.exp(-q**2), variable=q)
    >>> s.piece().energy[0].expr
    sqrt(pi)*erf(g.q)
    """

    domain = "translational"
    state_local = "q"
    state_unit = "m"
    state_description = "displacement"

    def __init__(self, name: str, force, variable, params=(), unit: str = "m", rotational: bool = False, **kw):
        super().__init__(name, **kw)
        if not isinstance(variable, sp.Symbol) or variable not in sp.sympify(force).free_symbols:
            raise ModelError(f"component {name!r}: the force law must be an expression of the given variable symbol")
        self.force, self.variable, self.extra = sp.sympify(force), variable, tuple(params)
        self.state_unit = unit
        if rotational:
            self.domain = "rotational"

    def parameters(self) -> list[tuple[str, float | sp.Expr, str, str]]:
        return []

    def default_range(self, values) -> tuple[float, float]:
        return (-0.1, 0.1)

    def energy(self, x) -> sp.Expr:
        e = _antiderivative(self.force, self.variable).xreplace({_UPPER: x})
        if e.has(sp.Integral):
            raise ModelError(f"component {self.name!r}: cannot integrate the force law {self.force} in closed form; "
                             "give the energy with a Potential component instead")
        return e

    def piece(self) -> Piece:
        pc = super().piece()
        return Piece(pc.name, storages=pc.storages, energy=pc.energy, ports=pc.ports, params=self.extra)


_UPPER = sp.Symbol("_upper", real=True)


@functools.lru_cache(maxsize=256)
def _antiderivative(force: sp.Expr, variable: sp.Symbol) -> sp.Expr:
    """int_0^_upper force d(variable), computed once per force law (sympy integration is slow)."""
    s = sp.Dummy("s", real=True)
    return sp.simplify(sp.integrate(force.subs(variable, s), (s, 0, _UPPER)))


class Damper(Component):
    """Linear damper ``F = b v`` (translational) on a velocity port.

    Examples
    --------
    >>> Damper("b", b=0.5).piece().dissipators[0].label
    'b'
    """

    domain = "translational"
    unit = "N*s/m"

    def __init__(self, name: str, b=1.0):
        super().__init__(name)
        require_positive(name, "b", b)
        self.b = b

    def piece(self) -> Piece:
        sym, decl = self._param("b", self.b, self.unit, "damping coefficient")
        return linear_resistor_piece(self, self._port("p", self.domain), sym, False, decl)


class RotationalDamper(Damper):
    """Linear rotational damper ``tau = b omega``.

    Examples
    --------
    >>> RotationalDamper("b", b=0.0031).piece().params[0].unit
    'N*m*s/rad'
    """

    domain = "rotational"
    unit = "N*m*s/rad"


class Potential(Component):
    """A stateless energy term ``H = energy(x)`` of other components' states (no port).

    Its force appears in dH/dx of the states the energy depends on (a conservative
    field: the zero-voltage part of an actuator's force law, a restoring torque of a
    joint).  :class:`Gravity` is the special case ``m g h(x)``.

    Parameters
    ----------
    name : str
    energy : sympy expression
        Energy [J] in terms of states (:func:`phs.symbol_of_state`) and parameters.
    params : sequence of Param
        Parameters used in ``energy``.

    Examples
    --------
    >>> from phs.component import symbol_of_state
    >>> th = symbol_of_state("theta")
    >>> Potential("tilt", 0.5 * th**2).piece().energy[0].expr
    0.5*theta**2
    """

    def __init__(self, name: str, energy, params=()):
        super().__init__(name)
        self.energy, self.params = sp.sympify(energy), tuple(params)
        for p in self.params:
            if not isinstance(p, Param):
                raise ModelError(f"component {name!r}: {p!r} in params is not a Param")

    def piece(self) -> Piece:
        return Piece(self.name, energy=(EnergyTerm(self.name, self.energy),), params=self.params)


class Gravity(Component):
    """Gravitational potential ``H = m g h(x)`` of a body whose height is an expression of states.

    It owns no state and has no port: its force appears in dH/dx of the
    states that ``height`` depends on.

    Parameters
    ----------
    name : str
    height : sympy expression
        Height [m] of the centre of mass as a function of other states.
    m : float, Param or expression
        Mass [kg].
    g : float or Param
        Gravitational acceleration [m/s**2].

    Examples
    --------
    >>> import sympy as sp
    >>> from phs.component import symbol_of_state
    >>> th = symbol_of_state("theta")
    >>> Gravity("grav", height=-0.1 * sp.cos(th), m=0.01).piece().energy[0].expr
    -0.1*grav.g*grav.m*cos(theta)
    """

    def __init__(self, name: str, height, m=1.0, g=9.81):
        super().__init__(name)
        self.height, self.m, self.g = sp.sympify(height), m, g

    def piece(self) -> Piece:
        ms, d1 = self._param("m", self.m, "kg", "mass lifted by gravity")
        gs, d2 = self._param("g", self.g, "m/s**2", "gravitational acceleration")
        return Piece(self.name, energy=(EnergyTerm(self.name, ms * gs * self.height),), params=d1 + d2)


class ForceSource(Component):
    """Force input ``{name}`` [N] with conjugate output velocity ``{name}.v``.

    Examples
    --------
    >>> ForceSource("F").piece().sources[0].info.output
    'F.v'
    """

    domain, unit, out, out_unit = "translational", "N", "v", "m/s"

    def __init__(self, name: str, range=None):
        super().__init__(name)
        self.range = range

    def piece(self) -> Piece:
        return source_piece(self, self._port("p", self.domain, supplies=True), "effort", self.unit,
                            f"{self.name}.{self.out}", self.out_unit, "applied " + self.domain + " effort", self.range)


class TorqueSource(ForceSource):
    """Torque input ``{name}`` [N*m] with conjugate output ``{name}.omega``.

    Examples
    --------
    >>> TorqueSource("T").piece().sources[0].info.output
    'T.omega'
    """

    domain, unit, out, out_unit = "rotational", "N*m", "omega", "rad/s"


__all__ = ["Mass", "RotationalInertia", "LinearSpring", "TorsionalSpring", "NonlinearSpring", "Damper",
           "RotationalDamper", "Gravity", "Potential", "ForceSource", "TorqueSource", "Param"]
