"""Manta-ray fin: n shells sharing one chamber and one electrical branch.

Source: the curling HASEL paper (Cisneros et al.), section 4.5, eqs. 24-27 and
Table 6.  Built only from :mod:`components`.

The fin is a single pouch with a corrugated shape: every corrugation is a
shell (states ``shell{i}.theta``, ``shell{i}.l_p``, ``shell{i}.p``) and all
shells share the dielectric liquid with one chamber, electrodes on one side,
so there is a single electrical branch (states ``fin.Q1``, ``fin.Q2``)::

    A_T = sum_i A_s^i + A_c,   A_c = X_h L_e (unzipped at rest)          (eq. 24)
    l_e = L_e - (A_T - sum_i A_s^i) / X_h                                (eq. 25)
    C2  = eps0 eps_r w (l_e/(2 t_f) + (L_e - l_e)/(2 t_f + X_h))          (eq. 27)
    tip = L_v sum_j sin(sum_{i<=j} theta_i)                              (eq. 26)

Every shell's angle enters the capacitor through ``l_e``, so the electrostatic
torque on each shell comes from the gradient of the one electrode energy.
The shell mechanics and the electrical branch are those of
:mod:`systems.curling_hasel` (same geometry regularisation).

Choices where the paper is silent (documented in ``docs/systems/manta_ray_fin.md``):

* 4 shells by default; the total mass ``m`` is split evenly; the per-shell
  inertia ``I_s`` is the printed ``(1/12) a m`` evaluated with ``a = L_v`` and
  ``m/n`` (as in the curling model).
* The input map of the single branch uses the mean angle ``mean(theta_i)``.
* ``gamma1`` is rescaled with the same interpretation as the curling HASEL
  (``U`` in volts); gravity is left out (the fin flaps in water, buoyancy
  balances its weight).
"""

from __future__ import annotations

import sympy as sp

from components import VoltageSource
from phs import Measured, Param, PHSystem, interconnect, series, symbol_of_output
from phs.errors import ModelError
from systems._hasel import electrode_branch, pouch_parameters, shell


def default_parameters(n_shells: int = 4) -> dict[str, Param]:
    """Parameters of the fin (Table 6 and the documented choices).

    Examples
    --------
    >>> default_parameters()["K_b"].value
    0.2616
    """
    P = pouch_parameters(L_e=0.05) + [
        Param("m", 0.018, "kg", "total mass of the fin", (0.01, 0.03)),
        Param("R0", 1e3, "Ohm", "connector resistance", (1e2, 1e5)),
        Param("R1", 1.18e5, "Ohm", "resistance of the charge-retention branch", (1e4, 1e6)),
        Param("R2", 1.55e6, "Ohm", "leakage resistance across the electrodes", (1e5, 1e7)),
        Param("C1", 2.05e-5, "F", "charge-retention capacitance", (1e-6, 1e-4)),
        Param("K", 0.7, "N/m", "stiffness of the top film", (0.1, 5.0)),
        Param("K_b", 0.2616, "N*m/rad", "torsional stiffness of a shell", (0.05, 1.0)),
        Param("b", 0.0266, "N*m*s/rad", "rotational damping of a shell", (0.005, 0.1)),
        Param("gamma1", 4.0, "1", "input-map gain (printed 42; rescaled, see docs)", (1.0, 8.0)),
        Param("gamma2", 8.9, "1", "input-map angular frequency", (5.0, 12.0)),
        Param("I_s", 0.015 * 0.018 / n_shells / 12, "kg*m**2", "effective rotational inertia of one shell",
              (1e-7, 1e-4)),
    ]
    return {p.name: p for p in P}


def manta_ray_fin(n_shells: int = 4, **overrides) -> PHSystem:
    """Manta-ray fin with ``n_shells`` shells on one chamber and one electrical branch.

    Parameters
    ----------
    n_shells : int
        Number of shells (corrugations).
    **overrides : float
        Parameter values by name.

    Examples
    --------
    >>> fin = manta_ray_fin(3)
    >>> [n for n in fin.state_names if n.startswith("fin.")]
    ['fin.Q1', 'fin.Q2']
    >>> fin.measured_names
    ['tip', 'current']
    """
    if not isinstance(n_shells, int) or n_shells < 1:
        raise ModelError(f"manta_ray_fin: n_shells must be a positive integer, got {n_shells!r}")
    base = default_parameters(n_shells)
    unknown = [k for k in overrides if k not in base]
    if unknown:
        raise ModelError(f"manta_ray_fin: unknown parameter(s) {unknown}; known: {sorted(base)}")
    for k, v in overrides.items():
        base[k] = base[k].with_value(v)

    def P(name):
        return base[name]

    def S(name):
        return base[name].symbol

    comps, conns, areas, thetas = [VoltageSource("U", range=(-10e3, 10e3))], [], [], []
    for i in range(1, n_shells + 1):
        parts, (mech, top), A_s, th = shell(f"shell{i}", P, S)
        comps += parts
        conns += [series(*mech), top]
        areas.append(A_s)
        thetas.append(th)
    elec, econns, _ = electrode_branch("fin", areas, sum(thetas) / n_shells, P, S, q2_scale=5e-6)
    comps += elec
    conns += econns + [series("U", "fin.ga.a")]
    tip = S("L_v") * sum(sp.sin(sum(thetas[: j + 1])) for j in range(n_shells))
    return interconnect(
        f"manta_ray_fin{n_shells}", comps, conns, params=list(base.values()),
        measured=[Measured("tip", tip, "m", "fin tip displacement, eq. 26"),
                  Measured("current", symbol_of_output("U.i"), "A", "source current")],
        description=f"manta-ray fin, {n_shells} shells on one chamber and one electrical branch",
    )


__all__ = ["manta_ray_fin", "default_parameters"]
