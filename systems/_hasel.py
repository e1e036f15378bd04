"""Building blocks shared by the HASEL models (curling actuator, manta-ray fin).

Each function returns components from :mod:`components` and the junctions
that join them; no J, R or g is written by hand.
"""

from __future__ import annotations

import sympy as sp

from components import (
    DriftBranch,
    GeometricConstraint,
    Geometry,
    LinearSpring,
    Resistor,
    RotationalDamper,
    RotationalInertia,
    TorsionalSpring,
    Transformer,
    VariableCapacitor,
    geometric_symbol,
)
from phs import Param, parallel, series, symbol_of_state


def pouch_parameters(L_e: float) -> list[Param]:
    """Geometry and material of a HASEL pouch shared by the curling actuator and the fin
    (Tables 3 and 6 of the curling HASEL paper) and the rest-point regularisation length.

    Examples
    --------
    >>> [p.name for p in pouch_parameters(0.015)][:3]
    ['L_p', 'L_v', 'L_e']
    """
    return [
        Param("L_p", 0.015, "m", "rest length of the top film", (0.01, 0.02)),
        Param("L_v", 0.015, "m", "length of the bottom film", (0.01, 0.02)),
        Param("L_e", L_e, "m", "length of the electrodes (chamber)", (L_e * 2 / 3, L_e * 4 / 3)),
        Param("X_h", 0.002, "m", "chamber height", (0.001, 0.004)),
        Param("eps_r", 2.2, "1", "relative permittivity of the dielectric", (1.5, 3.5)),
        Param("eps0", 8.854e-12, "F/m", "vacuum permittivity", (8.85e-12, 8.86e-12)),
        Param("w", 0.05, "m", "actuator width", (0.03, 0.08)),
        Param("t_f", 18e-6, "m", "film thickness", (10e-6, 30e-6)),
        Param("eps_geo", 1.5e-5, "m", "regularisation length of the shell triangle at rest", (1e-7, 1e-4)),
    ]


def shell(prefix: str, P, S, *, inertia: bool = True, theta_scale: float = 0.2, l_scale: float = 0.015):
    """Mechanical part of one shell: torsional spring (bottom film), linear spring (top film),
    inertia, damper, the modulated transformer ``l_p' = (2 A_s / l_p) theta'`` and the shell area.

    ``P(name)`` returns the Param to use, ``S(name)`` its symbol.  The shell area uses the
    law-of-cosines form of eqs. 1-2, regularised by ``eps_geo`` at the rest point (see
    ``docs/systems/curling_hasel.md``).  Returns ``(components, connections, A_s, theta)``;
    the rotational 1-junction is the first connection, its inertia member is
    ``{prefix}.I`` (or the caller's chain port when ``inertia`` is False, to be appended).

    Examples
    --------
    >>> from systems.curling_hasel import default_parameters
    >>> base = default_parameters()
    >>> comps, conns, A_s, th = shell("s1", base.__getitem__, lambda n: base[n].symbol)
    >>> [c.name for c in comps][:3], str(A_s)
    (['s1.Kb', 's1.K', 's1.I'], 's1.A_s')
    """
    th, lp = symbol_of_state(f"{prefix}.theta"), symbol_of_state(f"{prefix}.l_p")
    Lv = S("L_v")
    alpha = (sp.pi - th) / 2
    A_s = geometric_symbol(f"{prefix}.A_s")
    c = Lv * sp.cos(alpha) + sp.sqrt(lp**2 - Lv**2 * sp.sin(alpha) ** 2 + S("eps_geo") ** 2)
    comps = [
        TorsionalSpring(f"{prefix}.Kb", K=P("K_b"), state=f"{prefix}.theta", range=(-0.4, 0.4), scale=theta_scale),
        LinearSpring(f"{prefix}.K", K=P("K"), L0=P("L_p"), state=f"{prefix}.l_p", range=(0.0145, 0.02),
                     scale=l_scale),
    ]
    if inertia:
        comps.append(RotationalInertia(f"{prefix}.I", I=P("I_s"), state=f"{prefix}.p", scale=1e-5))
    comps += [
        RotationalDamper(f"{prefix}.b", b=P("b")),
        Transformer(f"{prefix}.d", 2 * A_s / lp, unit="m", domains=("rotational", "translational")),
        Geometry(f"{prefix}.shell", {f"{prefix}.A_s": Lv * c * sp.sin(alpha) / 4}, units={f"{prefix}.A_s": "m**2"},
                 # l_p >= L_v cos(theta/2), to within the regularisation (the square root stays real down to
                 # X = -eps**2, i.e. about eps**2 / (2 L_v) below the chord)
                 conditions=[("top film not shorter than the chord (arcsin argument <= 1, within eps_geo)",
                              lp - Lv * sp.sin(alpha) + S("eps_geo") ** 2 / (2 * Lv))]),
    ]
    mech = [f"{prefix}.Kb"] + ([f"{prefix}.I"] if inertia else []) + [f"{prefix}.b", f"{prefix}.d.a"]
    return comps, [mech, series(f"{prefix}.d.b", f"{prefix}.K")], A_s, th


def electrode_branch(prefix: str, shell_areas, map_angle, P, S, *, q2_scale: float = 2e-6, drift: bool = True):
    """Electrical part: volume conservation for the zipped length, the electrode capacitor C2(l_e)
    with R2 across it, the charge-retention branch C1 || R1 in series, R0, and the input map
    ``gamma1 cos(gamma2 angle)`` as a modulated transformer from the source port ``{prefix}.ga.a``.

    Without ``drift`` the retention branch is left out (``R0 -> (C2 || R2)``).

    Returns ``(components, connections, l_e)``.

    Examples
    --------
    >>> from systems.curling_hasel import default_parameters
    >>> base = default_parameters()
    >>> comps, conns, l_e = electrode_branch("s1", [geometric_symbol("s1.A_s")], symbol_of_state("s1.theta"),
    ...                                      base.__getitem__, lambda n: base[n].symbol)
    >>> conns[0].describe()
    'series(s1.ga.b, s1.R0, s1.D, parallel(s1.C2, s1.R2))'
    """
    Le, Xh, tf = S("L_e"), S("X_h"), S("t_f")
    l_e = geometric_symbol(f"{prefix}.l_e")
    comps = [
        GeometricConstraint(
            f"{prefix}.volume", f"{prefix}.l_e", sp.Eq(Xh * Le, sum(shell_areas) + Xh * (Le - l_e)), unit="m",
            conditions=[("zipped length l_e >= 0", l_e), ("zipped length l_e <= L_e (fully zipped)", Le - l_e),
                        ("input map gamma1 cos(gamma2 theta) keeps its sign (|gamma2 theta| <= pi/2)",
                         sp.cos(S("gamma2") * map_angle))],
        ),
        *([DriftBranch(f"{prefix}.D", C1=P("C1"), R1=P("R1"), state=f"{prefix}.Q1", range=(-0.1, 0.1))] if drift else []),
        VariableCapacitor(
            f"{prefix}.C2", C=S("eps0") * S("eps_r") * S("w") * (l_e / (2 * tf) + (Le - l_e) / (2 * tf + Xh)),
            C_typical=4e-10, state=f"{prefix}.Q2", scale=q2_scale,
        ),
        Resistor(f"{prefix}.R2", R=P("R2")),
        Resistor(f"{prefix}.R0", R=P("R0")),
        # the loop sees gamma1 cos(gamma2 angle) U; a transformer has e_a = n e_b, hence n = 1 / map
        Transformer(f"{prefix}.ga", 1 / (S("gamma1") * sp.cos(S("gamma2") * map_angle)),
                    domains=("electrical", "electrical")),
    ]
    chain = [f"{prefix}.ga.b", f"{prefix}.R0"] + ([f"{prefix}.D"] if drift else [])
    conns = [series(*chain, parallel(f"{prefix}.C2", f"{prefix}.R2"))]
    return comps, conns, l_e
