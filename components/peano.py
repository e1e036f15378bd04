"""Peano-HASEL actuator: a charge storage whose capacitance follows the measured force-strain law.

Source: Michelis, Gravert, Katzschmann, "Modeling and simulation of rigid-soft hybrid
HASEL-actuated robotic swimmers", eqs. 1-3.  Eq. 3 is the symbolic-regression fit of the
blocking force of a Peano-HASEL at a fixed voltage ``V_ref``::

    F(e) = b1 e + b2 (1 / (e + b3) - b4)        e = 100 s: contraction strain in percent  (eq. 3)
    F(e) = F(e*)  for e > e* = sqrt(b2 / b1) - b3 = 4.44 %      (end of stroke, see below)

(printed ``b1 = 1``, ``b2 = 21.71``, ``b3 = 0.22``, ``b4 = 0.39``; F in N).  The force of a
Peano-HASEL scales with the square of the voltage (eq. 1: ``a1`` holds ``eps0 eps_r w V**2 /
(4 t)``), so at any voltage the contraction force is ``(V / V_ref)**2 F(e)``.  Such a force is
the electrostatic force of a capacitor whose capacitance grows with the contraction::

    C(s) = C0 + (2 L0 / V_ref**2) int_0^s F(100 u) du
         = C0 + (2 L0 / (100 V_ref**2)) (b1 e**2 / 2 + b2 log(1 + e / b3) - b2 b4 e)
    H_el = Q**2 / (2 C(s)),   tension = dH_el/dl = (V / V_ref)**2 F(e),   V = Q / C(s)

with ``l = L0 (1 - s)`` the actuator's length.  Eq. 3 has its minimum (0.63 N) at ``e* = 4.44 %``
and rises beyond it (its linear term), unlike a Peano-HASEL whose force falls monotonically to
the end of its stroke (eqs. 1-2); the force is held at ``F(e*)`` beyond ``e*`` (C continued
linearly, F continuous with zero slope there), so a fully contracted actuator pulls with its
residual force and the structure around it sets the stroke end.  The fit has a pole at
``e = -b3`` (the pouch pulled flat, eq. 1's ``alpha -> 0``); the model is valid while
``e > -b3`` and ``C > 0`` (run-time conditions), which the taut film keeps.  The force is thus in ``grad H`` (a multi-port
storage like the curling HASEL's variable capacitor) and the model stays port-Hamiltonian.

The unactuated actuator resists stretching beyond its flat length (the film goes into
tension; the authors name this counteracting force as missing from their model).  With the
stretch ``d = -L0 s`` (positive when the actuator is longer than its flat length)::

    F_film(d) = k_f (d + sqrt(d**2 + d0**2)) / 2         (a smooth one-sided spring)
    H_film(d) = k_f (d**2 + d sqrt(d**2 + d0**2) + d0**2 asinh(d / d0)) / 4

``H_film`` is written in closed form (its derivative in ``d`` is ``F_film``), it is zero at
``d = 0`` and grows like ``k_f d**2 / 2`` once the film is taut.

``law="eq12"``: the alpha-parametric law of eqs. 1-2 (Kellaris et al.'s Peano-HASEL), of which
eq. 3 is the symbolic-regression fit::

    F = a1 cos(alpha) / (1 - cos(alpha))                                       (eq. 1)
    s = 1 - a2 (1 + a3 rho(alpha)),  rho = (sin(alpha) - alpha) / sqrt(alpha - sin(alpha) cos(alpha))   (eq. 2)

It is the force of the capacitance ``C(alpha) = C0 + kappa (g(alpha_0) - g(alpha))`` with
``g = alpha / sqrt(alpha - sin(alpha) cos(alpha))`` (the unzipped length of the pouch),
``kappa = 2 a1 L0 a2 a3 / V_ref**2`` and ``alpha_0`` the angle at zero strain: since
``g' / rho' = cos / (1 - cos)``, ``dH_el/dl = (V / V_ref)**2 F`` exactly.  ``alpha(s)`` inverts
eq. 2: a closed-form start (``(-2 sqrt(6) q)**(2/3)`` with a cubic correction, 1.3e-4 rad) and one
Newton step (5.6e-9 rad; two: 2e-12); H is that expression, so the force is its exact gradient and the
energy balance is exact, and the force differs from eq. 1 at the inverted angle by the
inversion's residual only.  The paper prints no a_i: the defaults ``EQ12`` are a least-squares
fit to eq. 3 (relative error over e = 0 ... e*).  The stroke ends at ``alpha = pi/2`` (F = 0,
e = 5.55 %), beyond which C is held (F = 0); the pole (the pouch flat, ``alpha -> 0``) is at
``s = 1 - a2`` (e = -0.195 %).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import sympy as sp

from components.electrical import VariableCapacitor
from phs.component import Component, Piece
from phs.errors import ModelError
from phs.params import Condition, EnergyTerm

if TYPE_CHECKING:
    import numpy as np

EQ3 = {"b1": 1.0, "b2": 21.71, "b3": 0.22, "b4": 0.39}
"""Printed coefficients of eq. 3 (strain in percent, force in N)."""
EQ12 = {"a1": 1.821, "a2": 1.00195, "a3": 0.12598}
"""Coefficients of eqs. 1-2 (not printed): least-squares fit to eq. 3 over e = 0 ... 4.44 % (force in N, strain a fraction)."""
LAWS = ("eq3", "eq12")
_START = (-0.00012573, 0.00166006, -0.03846667, 0.00589012)  # cubic correction of the start of the inversion of eq. 2


def _rho(a):
    return (sp.sin(a) - a) / sp.sqrt(a - sp.sin(a) * sp.cos(a))


def _unzipped(a):
    return a / sp.sqrt(a - sp.sin(a) * sp.cos(a))


def eq12_angle(s, a2, a3, newton: int = 1) -> sp.Expr:
    """``alpha`` of eq. 2 at the contraction strain ``s`` (a fraction): closed-form start and ``newton`` Newton steps.

    Examples
    --------
    >>> a = 0.9
    >>> s = 1 - EQ12["a2"] * (1 + EQ12["a3"] * _rho(sp.Float(a)))
    >>> abs(float(eq12_angle(s, EQ12["a2"], EQ12["a3"])) - a) < 1e-8     # one Newton step: 5.6e-9 rad at worst
    True
    >>> abs(float(eq12_angle(s, EQ12["a2"], EQ12["a3"], newton=2)) - a) < 1e-11
    True
    """
    q = ((1 - s) / a2 - 1) / a3
    a = (-2 * sp.sqrt(6) * q) ** sp.Rational(2, 3)
    a = a * (1 + sum(c * a**k for k, c in enumerate(_START)))
    for _ in range(newton):
        a = a - (_rho(a) - q) / sp.diff(_rho(sp.Symbol("_a")), sp.Symbol("_a")).subs(sp.Symbol("_a"), a)
    return a


def eq12_force(alpha, a1=EQ12["a1"]) -> float | np.ndarray | sp.Expr:
    """Eq. 1: blocking force [N] at the angle ``alpha`` (numbers, arrays or sympy expressions).

    Examples
    --------
    >>> round(float(eq12_force(sp.pi / 3)), 4)    # cos = 1/2: F = a1
    1.821
    """
    if isinstance(alpha, sp.Basic):
        cos = sp.cos(alpha)
    else:
        import numpy

        cos = numpy.cos(alpha)
    return a1 * cos / (1 - cos)


def peano_force(e, b1=EQ3["b1"], b2=EQ3["b2"], b3=EQ3["b3"], b4=EQ3["b4"]) -> float | np.ndarray | sp.Expr:
    """Eq. 3: blocking force [N] of the Peano-HASEL at the fit's voltage and contraction strain ``e`` [%].

    Works on numbers, numpy arrays and sympy expressions.

    Examples
    --------
    >>> round(peano_force(2.0), 4)   # 2 + 21.71 (1/2.22 - 0.39)
    3.3124
    """
    return b1 * e + b2 * (1 / (e + b3) - b4)


def film_energy(d, k_f, d0) -> sp.Expr:
    """Energy [J] of the one-sided film spring at stretch ``d`` [m]; its derivative is the resisting force.

    Examples
    --------
    >>> import sympy as sp
    >>> d = sp.Symbol("d", real=True)
    >>> sp.simplify(sp.diff(film_energy(d, 2, 1), d) - (d + sp.sqrt(d**2 + 1)))
    0
    """
    root = sp.sqrt(d**2 + d0**2)
    return k_f * (d**2 + d * root + d0**2 * sp.asinh(d / d0)) / 4


class PeanoHasel(Component):
    """A Peano-HASEL: charge ``{name}.Q`` on a capacitance set by eq. 3, plus its film's stretch resistance.

    The mechanics enter only through ``strain``, an expression of other components'
    states (the contraction strain ``s``, a fraction: 0.02 is 2 %), so that the actuator
    pulls on whatever geometry it spans through ``grad H``.

    Parameters
    ----------
    name : str
    strain : sympy expression
        Contraction strain ``s`` of the actuator (positive = shorter than flat).
    L0 : float or Param
        Flat (unactuated, untensioned) length [m].
    V_ref : float or Param
        Voltage at which eq. 3 was measured [V].
    C0 : float or Param
        Capacitance at zero strain [F].
    k_f, d0 : float or Param
        Film stiffness [N/m] and smoothing length [m] of the one-sided stretch spring.
    b1, b2, b3, b4 : float or Param
        Coefficients of eq. 3 (``N``, ``N``, percent, 1/percent); printed values by default.
    law : {"eq3", "eq12"}
        The force-strain law: eq. 3 (default) or the alpha-parametric eqs. 1-2 (module docstring).
    a1, a2, a3 : float or Param
        Coefficients of eqs. 1-2 (``N``, 1, 1; used with ``law="eq12"``); ``EQ12`` by default.
    state, range, scale : optional
        Name, physical range and scale of the charge state (as for :class:`components.Capacitor`).

    Raises
    ------
    ModelError
        If ``strain`` is not a sympy expression, or ``law`` is not ``"eq3"`` or ``"eq12"``.

    Examples
    --------
    >>> from phs.component import symbol_of_state
    >>> th = symbol_of_state("phi")
    >>> pc = PeanoHasel("L", strain=0.02 + 0.004 * th / 0.05).piece()
    >>> [s.state.name for s in pc.storages], [e.label for e in pc.energy]
    (['L.Q'], ['L', 'L.film'])
    """

    def __init__(self, name: str, strain, L0=0.05, V_ref=6000.0, C0=1.5e-9, k_f=1e5, d0=2e-5,
                 b1=EQ3["b1"], b2=EQ3["b2"], b3=EQ3["b3"], b4=EQ3["b4"], state: str | None = None, range=None, scale=None,
                 law: str = "eq3", a1=EQ12["a1"], a2=EQ12["a2"], a3=EQ12["a3"]):
        super().__init__(name)
        if not isinstance(strain, sp.Expr):
            raise ModelError(f"component {name!r}: strain must be a sympy expression of states")
        if law not in LAWS:
            raise ModelError(f"component {name!r}: law must be 'eq3' or 'eq12', got {law!r}")
        self.strain, self.kw, self.law = strain, {"state": state, "range": range, "scale": scale}, law
        self.values = {"L0": L0, "V_ref": V_ref, "C0": C0, "k_f": k_f, "d0": d0}
        self.values.update({"b1": b1, "b2": b2, "b3": b3, "b4": b4} if law == "eq3" else {"a1": a1, "a2": a2, "a3": a3})

    _META = {"L0": ("m", "flat length of the actuator"),
             "V_ref": ("V", "voltage of the force-strain fit (eq. 3)"),
             "C0": ("F", "capacitance at zero contraction strain"),
             "k_f": ("N/m", "stiffness of the taut film (resists stretch beyond the flat length)"),
             "d0": ("m", "smoothing length of the one-sided film spring"),
             "b1": ("N", "eq. 3: linear coefficient (per percent strain)"),
             "b2": ("N", "eq. 3: hyperbolic coefficient"),
             "b3": ("1", "eq. 3: pole offset (percent strain)"),
             "b4": ("1", "eq. 3: offset of the hyperbola (per percent strain)"),
             "a1": ("N", "eqs. 1-2: force scale (fitted to eq. 3, not printed)"),
             "a2": ("1", "eqs. 1-2: length ratio, flat pouch at strain 1 - a2 (fitted to eq. 3)"),
             "a3": ("1", "eqs. 1-2: geometry of the pouch, 2 sqrt(A)/L (fitted to eq. 3)")}

    def symbols(self) -> tuple[dict, list]:
        """The parameters' symbols by key and their declarations (numbers become ``{name}.{key}``).

        Examples
        --------
        >>> from phs.component import symbol_of_state
        >>> S, decl = PeanoHasel("L", strain=symbol_of_state("phi")).symbols()
        >>> str(S["b2"]), decl[6].value
        ('L.b2', 21.71)
        """
        S, decl = {}, []
        for key, value in self.values.items():
            unit, desc = self._META[key]
            S[key], d = self._param(key, value, unit, desc)
            decl.extend(d)
        return S, decl

    def capacitance(self, S: dict) -> sp.Expr:
        """``C(s)`` [F] from the parameters' symbols ``S`` (see the module docstring).

        Beyond the fit's minimum ``e* = sqrt(b2/b1) - b3`` the force is held at ``F(e*)`` (C is
        continued linearly; F is continuous with zero slope there).

        Examples
        --------
        >>> from phs.component import symbol_of_state
        >>> a = PeanoHasel("L", strain=symbol_of_state("s"))
        >>> S, decl = a.symbols()
        >>> C = a.capacitance(S).subs({d.symbol: d.value for d in decl})
        >>> float(C.subs(symbol_of_state("s"), 0))   # C0 at zero strain
        1.5e-09
        """
        if self.law == "eq12":
            return self._capacitance_eq12(S)
        e = 100 * self.strain
        e_star = sp.sqrt(S["b2"] / S["b1"]) - S["b3"]

        def integral(v):
            return S["b1"] * v**2 / 2 + S["b2"] * sp.log(1 + v / S["b3"]) - S["b2"] * S["b4"] * v

        beyond = integral(e_star) + peano_force(e_star, S["b1"], S["b2"], S["b3"], S["b4"]) * (e - e_star)
        return S["C0"] + 2 * S["L0"] / (100 * S["V_ref"] ** 2) * sp.Piecewise((integral(e), e <= e_star), (beyond, True))

    def _capacitance_eq12(self, S: dict) -> sp.Expr:
        """``C(s)`` of eqs. 1-2: ``C0 + kappa (g(alpha_0) - g(alpha(s)))``, held beyond ``alpha = pi/2`` (F = 0)."""
        a2, a3 = S["a2"], S["a3"]
        kappa = 2 * S["a1"] * S["L0"] * a2 * a3 / S["V_ref"] ** 2
        g0 = _unzipped(eq12_angle(sp.Integer(0), a2, a3))
        s_end = 1 - a2 * (1 + a3 * _rho(sp.pi / 2))
        inside = S["C0"] + kappa * (g0 - _unzipped(eq12_angle(self.strain, a2, a3)))
        end = S["C0"] + kappa * (g0 - _unzipped(sp.pi / 2))
        return sp.Piecewise((inside, self.strain <= s_end), (end, True))

    def piece(self) -> Piece:
        S, decl = self.symbols()
        C = self.capacitance(S)
        cap = VariableCapacitor(self.name, C=C, C_typical=1e-9, **self.kw).piece()
        stretch = -S["L0"] * self.strain
        film = EnergyTerm(f"{self.name}.film", film_energy(stretch, S["k_f"], S["d0"]))
        pole = (Condition(f"{self.name}: strain above the pole of eq. 3", 100 * self.strain + S["b3"],
                          "eq. 3 diverges at e = -b3 (-0.22 %): the pouch pulled flat") if self.law == "eq3" else
                Condition(f"{self.name}: strain above the pole of eqs. 1-2", self.strain - (1 - S["a2"]),
                          "eqs. 1-2 diverge at s = 1 - a2 (alpha -> 0, -0.195 %): the pouch pulled flat"))
        conds = (pole,
                 Condition(f"{self.name}: capacitance positive", C,
                           "C(s) > 0: the log term of the integrated fit falls steeply below e = 0"))
        return Piece(self.name, storages=cap.storages, energy=cap.energy + (film,), ports=cap.ports,
                     params=cap.params + tuple(decl), conditions=conds)


__all__ = ["PeanoHasel", "peano_force", "film_energy", "eq12_angle", "eq12_force", "EQ3", "EQ12"]
