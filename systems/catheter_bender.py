"""A hydraulic soft bending actuator pressing on a load cell: volume in, contact force out.

Source: "Force analysis and modelling of soft actuators for catheter robots" (eqs. 1-12,
Table 1, Figs. 4-13).  The paper identifies a black-box force model ``F = X Phi`` (eqs.
3-6) from a volume-controlled bender; this module is a physical model of the same rig built
from :mod:`components`, from which such data are generated and the paper's regression
(:func:`phs.workflows.regression.regress`) is reproduced.

Structure (states ``chamber.V`` [m**3], ``tip.p`` [kg*m/s], ``tip_spring.l`` [m]; input
``q`` [m**3/s], the flow the cylinder pushes into the bender)::

    0-junction (common pressure P):  q = V_c' + A y'             flow source, chamber, wall
    P(V_c) = k1 V_c + k2 V_c**2 + k3 V_c**3                     compliant chamber (elastomer wall)
    F_wall = A P                                                 pressure on the effective area
    1-junction (tip velocity y'):    p' = A P - (K_b + k_c) y - b y'   bender + contact + damping
    H = k1 V_c**2/2 + k2 V_c**3/3 + k3 V_c**4/4 + p**2/(2 m) + (K_b + k_c) y**2 / 2

Measured outputs: ``volume = V_c + A y`` [m**3] (what the LVDT measures: the volume pushed in),
``force = k_c y + F_pre`` [N] (the load cell: contact stiffness times indentation, plus the
preload that the paper's constant term absorbs) and ``pressure = P(V_c)`` [Pa].

Quasi-statically ``F - F_pre = tau P(V_c)`` with the transmission ``tau = k_c A / (K_b + k_c)``
and ``V_c ~ x`` (the wall swallows almost no volume), so ``F ~ tau (k1 x + k2 x**2 + k3 x**3)``:
the static polynomial that eqs. 11 and 12 select.  The fast mode (tip mass on the two springs,
about 50 Hz) lies far above the chirp's 5 Hz, so the time-derivative terms matter little, as the
paper finds.

Choices (the paper gives the bender's dimensions, Table 1, but no material law, mass or
stiffness): the chamber coefficients and transmission are chosen so that the static force
resembles the reduced fits, eq. 11 (unconstrained, ``3.47e-3 x**2`` N with x in mL) and
eq. 12 (constrained, ``6.52e-4 x**3``); the roller of the constrained condition stiffens the
chamber's wall and sends more of the bending into the cell (larger ``tau``).
"""

from __future__ import annotations

import sympy as sp

from components import Chamber, Damper, FlowSource, LinearSpring, Mass, PressureTransducer
from phs import Measured, Param, PHSystem, interconnect, parallel, series, symbol_of_state
from phs.errors import ModelError
from phs.params import TIME
from phs.signals import Expression, Signal, exponential_chirp

ML = 1e-6
"""One millilitre in m**3 (the unit of the paper's volume x)."""

_LOADING = {  # chosen: (k1 [Pa/m**3], k2 [Pa/m**6], k3 [Pa/m**9], K_b [N/m], F_pre [N])
    "unconstrained": (1e9, 7e14, 2e19, 1500.0, 0.0122),
    "constrained": (5e8, 1e14, 1e20, 1166.67, 0.00242),
}


def default_parameters(loading: str = "unconstrained") -> dict[str, Param]:
    """Parameters of :func:`catheter_bender` for a loading condition (Fig. 4 of the paper).

    Parameters
    ----------
    loading : {"unconstrained", "constrained"}

    Returns
    -------
    dict of str -> Param

    Raises
    ------
    ModelError
        For an unknown loading condition.

    Examples
    --------
    >>> P = default_parameters("constrained")
    >>> P["k3"].value, P["k3"].unit
    (1e+20, 'Pa/m**9')
    """
    if loading not in _LOADING:
        raise ModelError(f"catheter_bender: loading must be one of {sorted(_LOADING)}, got {loading!r}")
    k1, k2, k3, K_b, F_pre = _LOADING[loading]
    P = [
        Param("k1", k1, "Pa/m**3", f"chamber: linear coefficient of P(V) ({loading}; chosen)", (1e7, 1e11)),
        Param("k2", k2, "Pa/m**6", f"chamber: quadratic coefficient of P(V) ({loading}; chosen)", (0.0, 1e17)),
        Param("k3", k3, "Pa/m**9", f"chamber: cubic coefficient of P(V) ({loading}; chosen)", (0.0, 1e22)),
        Param("A", 2e-5, "m**2", "effective area of the bending wall at the tip (chosen)", (1e-6, 1e-3)),
        Param("K_b", K_b, "N/m", f"bending stiffness of the bender at its tip ({loading}; chosen)", (10.0, 1e5)),
        Param("k_c", 500.0, "N/m", "contact stiffness of the load cell and wall (chosen)", (10.0, 1e5)),
        Param("m", 0.02, "kg", "moving mass: elastomer and water (chosen)", (1e-3, 0.2)),
        Param("b", 2.0, "N*s/m", "damping of the tip (chosen)", (0.0, 100.0)),
        Param("F_pre", F_pre, "N", f"preload of the tip on the load cell ({loading}; the constant of "
                                   f"eq. {11 if loading == 'unconstrained' else 12})", (0.0, 1.0)),
    ]
    return {p.name: p for p in P}


def catheter_bender(loading: str = "unconstrained", **overrides: float) -> PHSystem:
    """The volume-driven soft bender pressing on a load cell (see the module docstring).

    Parameters
    ----------
    loading : {"unconstrained", "constrained"}
        Loading condition of Fig. 4 (free arch, or a roller halfway up).
    **overrides : float
        Parameter values by name (see :func:`default_parameters`).

    Returns
    -------
    PHSystem
        Input ``q`` [m**3/s]; measured outputs ``volume`` [m**3], ``force`` [N], ``pressure`` [Pa].

    Raises
    ------
    ModelError
        For an unknown loading condition or parameter.

    Examples
    --------
    >>> s = catheter_bender()
    >>> s.state_names, s.input_names, s.measured_names
    (['chamber.V', 'tip.p', 'tip_spring.l'], ['q'], ['volume', 'force', 'pressure'])
    """
    P = default_parameters(loading)
    unknown = sorted(set(overrides) - set(P))
    if unknown:
        raise ModelError(f"catheter_bender: unknown parameter(s) {unknown}; known: {sorted(P)}")
    P = {k: (p.with_value(overrides[k]) if k in overrides else p) for k, p in P.items()}
    S = {k: p.symbol for k, p in P.items()}
    comps = [
        FlowSource("q", range=(-1e-4, 1e-4)),
        Chamber("chamber", k1=P["k1"], k2=P["k2"], k3=P["k3"], range=(-2e-6, 3e-5), scale=1e-6),
        PressureTransducer("wall", A=P["A"]),
        Mass("tip", m=P["m"], range=(-0.01, 0.01), scale=1e-4),
        LinearSpring("tip_spring", K=S["K_b"] + S["k_c"], range=(-0.005, 0.01), scale=1e-4),
        Damper("tip_damping", b=P["b"]),
    ]
    conns = [parallel("q", "chamber", "wall.a"), series("wall.b", "tip", "tip_spring", "tip_damping")]
    V, y = symbol_of_state("chamber.V"), symbol_of_state("tip_spring.l")
    pressure = S["k1"] * V + S["k2"] * V**2 + S["k3"] * V**3
    measured = [Measured("volume", V + S["A"] * y, "m**3", "fluid volume pushed into the bender"),
                Measured("force", S["k_c"] * y + S["F_pre"], "N", "contact force on the load cell"),
                Measured("pressure", pressure, "Pa", "pressure in the bender")]
    return interconnect(f"catheter_bender_{loading}", comps, conns, params=[P["K_b"], P["k_c"], P["F_pre"]],
                        measured=measured,
                        description=f"hydraulic soft bender pressing on a load cell ({loading} loading)")


def volume_chirp(mean: float, amplitude: float, f0: float, f1: float, duration: float) -> tuple[Signal, Signal]:
    """Exponential chirp of the volume (eqs. 1-2) and the flow ``q = x'`` that drives :func:`catheter_bender`.

    Parameters
    ----------
    mean, amplitude : float
        Volume about which the chirp swings and its amplitude [m**3].
    f0, f1, duration : float
        Start and final frequency [Hz] and the time to reach ``f1`` [s].

    Returns
    -------
    (volume, flow) : tuple of Signal

    Examples
    --------
    >>> x, q = volume_chirp(5e-6, 2e-6, 0.05, 2.0, 20.0)
    >>> float(x(0.0)), round(float(q(0.0)) / (2e-6 * 2 * 3.141592653589793 * 0.05), 9)
    (5e-06, 1.0)
    """
    x = exponential_chirp(amplitude, f0, f1, duration, offset=mean)
    expr = x.expr_on(0.0, duration)
    return x, Expression(sp.diff(expr, TIME))
