"""The hydrogel continuum arm of Doroudchi et al.: a Cosserat rod bent by 16 hydrogel voxel actuators.

A 45 mm backbone (cross-section 11 mm x 4.5 mm, bending across the 4.5 mm side), clamped at its base,
carries 8 segments; segment ``j`` has an upper SVA ``j`` and a lower SVA ``j + 8`` (the paper's
numbering: 1–8 top row, 9–16 bottom row, counted from the base).  The backbone is a
:class:`components.CosseratRod` with ``8 m`` elements (``m`` per segment); each SVA is a
:class:`components.HydrogelActuator` whose tension acts as a couple over its segment's span, joined
to the rod's couple port by a 1-junction (the two SVAs of a segment share it).

Symbols: ``rod.*`` the backbone (``rod.uy{k}`` node deflections, ``rod.tip_y`` the tip deflection, the
paper's x), ``sva{i}.e``/``sva{i}.p`` the actuators, inputs ``V{i}`` [V] the heater voltages.

Deviations from the paper (each argued in ``docs/systems/hydrogel_arm.md``):

* eq. 7 is the step response of ``f'' + b1 f' + b2 f = b0`` (bracket ``1 - ...``, ``sqrt(b1**2/4 - b2) t``);
  its coefficients are taken at the operating amplitude ``V_a`` (heating and cooling alike);
* eq. 6 gives no couple at the straight configuration; the SVA tension ``T`` acts as the couple
  ``r T`` over its segment, with an effective lever arm ``r`` fitted to Table II, case 4;
* Young's modulus is chosen so that the first bending period is the reported 1.56 s (the printed
  2.005 kPa gives 2.3 s with this cross-section and the paper's density);
* damping: Kelvin–Voigt with ``tau = 0.05 s`` (first-mode damping ratio 0.1); the printed
  ``B = tau K`` with ``tau`` twice the period would make the arm overdamped (ratio 6.3); the water drag
  ``R C q|q|`` of eq. 5 is the rod's quadratic drag ``c_q`` with the paper's ``C = 0.0262 kg/m**2``
  (``drag``), which adds a damping ratio of the order of 1e-4 at millimetre amplitudes;
* ``lever`` may give the two rows different lever arms, and ``V_t`` takes eq. 8's time coefficients at one
  voltage for all amplitudes (the reading under which Table II's voltage trend is reproduced, see
  :mod:`systems.hydrogel_cases`);
* gravity is left out by default: with the period-matched stiffness the buoyant weight would bend the
  arm far beyond the measured 0.29 mm sag (``gravity=True`` includes it with buoyancy).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from components import CosseratRod, HydrogelActuator
from phs import Measured, Param, PHSystem, interconnect, series, symbol_of_state
from phs.errors import ModelError

LENGTH, WIDTH, THICKNESS = 0.045, 0.011, 0.0045  # m
DENSITY, WATER = 1346.8, 1000.0  # kg/m**3
PERIOD = 1.56  # s, first bending period of the tip (Fig. 6)
SEGMENTS = 8
AREA = WIDTH * THICKNESS
SECOND_MOMENT = WIDTH * THICKNESS**3 / 12
YOUNG = (2 * math.pi / PERIOD) ** 2 * DENSITY * AREA * LENGTH**4 / (1.875104069**4 * SECOND_MOMENT)
"""Young's modulus [Pa] giving the first clamped-free bending period ``PERIOD`` (about 4.3 kPa)."""
LEVER = 2.9e-4  # m, effective lever arm of an SVA's tension (fitted to Table II, case 4)
TAU = 0.05  # s, Kelvin-Voigt retardation time
DRAG = 0.0262  # kg/m**2, water drag coefficient C of eq. 5 (Sec. V-A)


def hydrogel_arm(per_segment: int = 2, svas: Sequence[int] = tuple(range(1, 17)), V_a: float = 3.6,
                 tau: float = TAU, lever: float | tuple[float, float] = LEVER, gravity: bool = False,
                 E: float | None = None, drag: float = DRAG, V_t: float | None = None) -> PHSystem:
    """The hydrogel arm as a port-Hamiltonian system.

    Parameters
    ----------
    per_segment : int
        Rod elements per actuated segment (the rod has ``8 per_segment`` elements).
    svas : sequence of int
        SVAs present (1–8 upper row, 9–16 lower row); each adds the input ``V{i}``.
    V_a : float
        Operating voltage amplitude [V] (eq. 8's coefficients are taken there).
    tau : float
        Kelvin–Voigt retardation time of the backbone [s].
    lever : float or (float, float)
        Effective lever arm of the SVA tension [m], or one per row ``(upper, lower)``; a row's lever arm
        may be a :class:`~phs.Param` (positive), then one parameter shared by the row's SVAs (the lower
        row's SVAs take its negative), as a fit of the rows needs.
    gravity : bool
        Include the buoyant weight in water.
    E : float, optional
        Young's modulus [Pa] (default: matched to the 1.56 s period).
    drag : float
        Water drag coefficient ``C`` of eq. 5 [kg/m**2] (0: none).
    V_t : float, optional
        Voltage [V] at which eq. 8's time coefficients are taken for every SVA (default: ``V_a``).

    Returns
    -------
    PHSystem

    Examples
    --------
    >>> arm = hydrogel_arm(per_segment=1, svas=[1, 9])
    >>> arm.input_names, len(arm.states)
    (['V1', 'V9'], 52)
    >>> two = hydrogel_arm(per_segment=1, svas=[1, 9], lever=(2e-4, 3e-4))
    >>> two.param("sva1.r").value, two.param("sva9.r").value
    (0.0002, -0.0003)
    >>> rows = hydrogel_arm(per_segment=1, svas=[1, 9], lever=(Param("r_up", 2e-4, "m"), Param("r_lo", 3e-4, "m")))
    >>> [p for p in rows.param_names if p.endswith("r") or p.startswith("r_")]
    ['r_up', 'r_lo']
    """
    bad = [i for i in svas if not (isinstance(i, int) and 1 <= i <= 16)]
    if bad or len(set(svas)) != len(svas):
        raise ModelError(f"hydrogel_arm: SVAs are numbered 1..16, each at most once; got {list(svas)}")
    if not isinstance(per_segment, int) or per_segment < 1:
        raise ModelError(f"hydrogel_arm: per_segment must be a positive integer, got {per_segment!r}")
    levers = tuple(lever) if isinstance(lever, (tuple, list)) else (lever, lever)
    if len(levers) != 2 or not all(isinstance(r, (int, float, Param)) and ((r.value or 0.0) if isinstance(r, Param) else r) > 0
                                   for r in levers):
        raise ModelError(f"hydrogel_arm: lever must be a positive number or a pair (upper, lower) of positive numbers "
                         f"or Params; got {lever!r}")
    shared = [r for r in levers if isinstance(r, Param)]
    levers = tuple(r.symbol if isinstance(r, Param) else r for r in levers)
    m = per_segment
    segments = sorted({(i - 1) % SEGMENTS + 1 for i in svas})
    spans = [((j - 1) * m, j * m) for j in segments]
    rod = CosseratRod("rod", n=SEGMENTS * m, L=LENGTH, rho=DENSITY, A=AREA, I=SECOND_MOMENT, E=E or YOUNG,
                      G=(E or YOUNG) / 3, tau=tau, c_q=drag, gravity=gravity, rho_w=WATER, couples=spans)
    comps, conns = [rod], []
    for j, (a, b) in zip(segments, spans):
        members = []
        for i in (j, j + SEGMENTS):
            if i in svas:
                r = levers[0] if i <= SEGMENTS else -levers[1]
                comps.append(HydrogelActuator(f"sva{i}", input=f"V{i}", V_a=V_a, r=r, V_t=V_t))
                members.append(f"sva{i}.c")
        conns.append(series(f"rod.c{a}_{b}", *members))
    tip = Measured("tip", 1e3 * symbol_of_state(f"rod.uy{SEGMENTS * m}"), "mm", "tip deflection across the backbone")
    return interconnect("hydrogel_arm", comps, conns, params=shared, measured=[tip],
                        description="Hydrogel continuum arm (Doroudchi et al.): Cosserat backbone bent by hydrogel SVAs")


__all__ = ["hydrogel_arm", "YOUNG", "LEVER", "TAU", "PERIOD", "DRAG"]
