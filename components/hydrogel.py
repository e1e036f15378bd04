"""A thermally driven hydrogel soft voxel actuator (SVA) acting as a bending couple.

Doroudchi et al. identify the isometric force of an SVA heated by a step voltage of amplitude V as
the step response of a second-order system (their eq. 7, with two typos fixed: the bracket is
``1 - exp(..)(..)``, so the force starts at zero, and the time multiplies the square root)::

    f_a(t) = b0/b2 (1 - exp(-b1 t/2) (cosh(w t) + b1/(2 w) sinh(w t))),   w = sqrt(b1**2/4 - b2),

    b0 = d11 V + d12,   b1 = d21 V**2 + d22,   b2 = d31 V + d32                 (eq. 8, Table I)

i.e. ``f'' + b1 f' + b2 f = b0``.  As a port-Hamiltonian element this is an active tendon: a spring of
stiffness ``k`` (state: its elongation ``e``, tension ``T = k e``) in series with a virtual mass
``mu`` and damper ``c`` driven by the force ``beta V``::

    e' = p/mu - r w_rel,    p' = -k e - c p/mu + beta V,    H = k e**2/2 + p**2/(2 mu)

with ``mu = k/b2``, ``c = b1 mu``, ``beta = b0/(b2 V_a)``: with the plates held (``w_rel = 0``) the
tension obeys ``T'' + b1 T' + b2 T = b0 V/V_a``, the paper's law for a step of amplitude ``V_a``.
The coefficients are those of the operating amplitude ``V_a`` (the drive switches between 0 and
``V_a``), so heating and cooling have the same time constants and the element is linear in V.  With
``V_t`` given, the time coefficients ``b1, b2`` are taken at ``V_t`` instead (``b0`` stays at ``V_a``):
every amplitude then shares one time course and the force scales with ``b0(V_a)``.  The
tension acts on the backbone as the couple ``M = r T`` over the SVA's segment (``r`` the lever arm,
positive on the side the segment bends towards); the plates' relative rotation ``w_rel`` shortens the
spring, which gives the SVA the bending stiffness ``k r**2`` in series with its activation (``k`` small
recovers the paper's prescribed force).  Port ``c``: (couple on the rod, relative angular velocity);
input ``V`` [V] with the conjugate output ``beta p/mu``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from components._base import require_positive
from phs.component import Component, Dissipator, Piece, Relation, Source
from phs.errors import ModelError
from phs.params import EnergyTerm, InputInfo

if TYPE_CHECKING:
    import numpy as np
    import sympy as sp

TABLE_I = {"d11": 0.0024, "d12": -0.0004, "d21": 0.4900, "d22": 0.1564, "d31": 0.0383, "d32": 0.0002}
"""Coefficients of eq. 8 (Table I of Doroudchi et al.): force in N, voltage in V, time in s."""


def force_coefficients(V, d=None) -> tuple[float | sp.Expr, float | sp.Expr, float | sp.Expr]:
    """``(b0, b1, b2)`` of eq. 8 at the voltage ``V`` (numbers or sympy expressions).

    Examples
    --------
    >>> [round(b, 5) for b in force_coefficients(1.08)]
    [0.00219, 0.72794, 0.04156]
    """
    d = TABLE_I if d is None else d
    return d["d11"] * V + d["d12"], d["d21"] * V**2 + d["d22"], d["d31"] * V + d["d32"]


def step_force(t, V, d=None) -> np.ndarray | float:
    """Isometric SVA force [N] ``t`` seconds after a voltage step of amplitude ``V`` (eq. 7, typos fixed).

    Examples
    --------
    >>> round(float(step_force(0.0, 1.08)), 12), round(float(step_force(40.0, 1.08)), 5)
    (0.0, 0.04795)
    """
    import numpy as np

    b0, b1, b2 = force_coefficients(V, d)
    w = np.sqrt(complex(b1**2 / 4 - b2))
    t = np.asarray(t, dtype=float)
    shape = np.cosh(w * t) + b1 / (2 * w) * np.sinh(w * t)
    return (b0 / b2 * (1 - np.exp(-b1 * t / 2) * shape)).real


class HydrogelActuator(Component):
    """Hydrogel SVA: an active tendon whose isometric tension follows eqs. 7–8 of Doroudchi et al.

    Parameters
    ----------
    name : str
        Component name; states ``{name}.e`` (spring elongation) and ``{name}.p`` (drive momentum).
    input : str, optional
        Name of the voltage input (default ``V_{name}``).
    V_a : float or Param
        Operating voltage amplitude [V] at which eq. 8's coefficients are taken.
    r : float or Param
        Lever arm of the tension about the backbone [m] (sign: side the segment bends towards).
    k : float or Param
        Series stiffness of the tendon [N/m].
    d : dict, optional
        Coefficients of eq. 8 as numbers or Params (default Table I).
    V_t : float or Param, optional
        Voltage [V] at which the time coefficients ``b1``, ``b2`` of eq. 8 are taken (default ``V_a``).

    Examples
    --------
    >>> pc = HydrogelActuator("sva1", V_a=3.6, r=3e-4).piece()
    >>> [s.state.name for s in pc.storages], pc.sources[0].info.name
    (['sva1.e', 'sva1.p'], 'V_sva1')
    >>> [p.name for p in HydrogelActuator("sva2", V_a=1.8, V_t=1.08).piece().params][:4]
    ['sva2.V_a', 'sva2.r', 'sva2.k', 'sva2.V_t']
    """

    def __init__(self, name: str, input: str | None = None, V_a=3.6, r=3e-4, k=10.0, d=None, V_t=None):
        super().__init__(name)
        require_positive(name, "V_a", V_a)
        require_positive(name, "k", k)
        if V_t is not None:
            require_positive(name, "V_t", V_t)
        self.V_t = V_t
        if isinstance(r, (int, float)) and r == 0:
            raise ModelError(f"component {name!r}: the lever arm r must be nonzero")
        self.input = input or f"V_{name}".replace(".", "_")
        self.V_a, self.r, self.k, self.d = V_a, r, k, dict(TABLE_I if d is None else d)

    def piece(self) -> Piece:
        params, sym = [], {}
        for key, value, unit, desc in [("V_a", self.V_a, "V", "operating voltage amplitude"),
                                       ("r", self.r, "m", "lever arm of the tension"),
                                       ("k", self.k, "N/m", "series stiffness of the tendon")] + (
                [("V_t", self.V_t, "V", "voltage of eq. 8's time coefficients b1, b2")] if self.V_t is not None else []) + [
                (key, value, _D_UNITS[key], f"coefficient {key} of eq. 8") for key, value in self.d.items()]:
            s, decl = self._param(key, value, unit, desc)
            sym[key] = s
            params.extend(decl)
        b0, b1, b2 = force_coefficients(sym["V_a"], sym)
        if "V_t" in sym:
            _, b1, b2 = force_coefficients(sym["V_t"], sym)
        mu = sym["k"] / b2
        c, beta = b1 * mu, b0 / (b2 * sym["V_a"])
        e = self._state("e", None, "m", (-1.0, 1.0), "elongation of the tendon spring", "C", "translational", 5e-3)
        p = self._state("p", None, "kg*m/s", (-10.0, 10.0), "momentum of the drive", "I", "translational", 1e-2)
        port = self._port("c", "rotational")
        drive = self._port("drive", "electrical", supplies=True)
        info = InputInfo(self.input, "V", f"{self.input}.y", "N*m/(s*V)", "effort", "heater voltage", (0.0, 3.7))
        v = p.coenergy
        relations = (
            Relation(e.rate - v + sym["r"] * port.flow, self.name, "kinematic"),
            Relation(p.rate + e.coenergy + c * v - beta * drive.effort, self.name, "balance"),
            Relation(drive.flow - beta * v, self.name, "drive"),
            Relation(port.effort + sym["r"] * e.coenergy, self.name, "couple"),
        )
        energy = (EnergyTerm(self.name, sym["k"] * e.state.symbol**2 / 2 + p.state.symbol**2 / (2 * mu)),)
        return Piece(self.name, storages=(e, p), energy=energy, ports=(port,), internal=(drive,), relations=relations,
                     sources=(Source(info, drive),), dissipators=(Dissipator(self.name, (), c * v**2),),
                     params=tuple(params), references=("Doroudchi et al., eqs. 7-8 and Table I",))


_D_UNITS = {"d11": "N/(V*s**2)", "d12": "N/s**2", "d21": "1/(V**2*s)", "d22": "1/s", "d31": "1/(V*s**2)", "d32": "1/s**2"}

__all__ = ["HydrogelActuator", "TABLE_I", "force_coefficients", "step_force"]
