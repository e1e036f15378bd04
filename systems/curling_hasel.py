"""Curling HASEL actuator: n interconnected port-Hamiltonian segments.

Source: Cisneros, Wu, Rabenorosoa, Le Gorrec, "Dynamic modeling of a curling
HASEL actuator using the port-Hamiltonian framework with experimental
validation" (eqs. 1-22, Tables 3-4).  Built only from :mod:`components`.

States per segment ``i`` (names ``seg{i}.theta``, ``seg{i}.l_p``,
``seg{i}.p``, ``seg{i}.Q1``, ``seg{i}.Q2``): bending angle, top-film length,
angular momentum, charge of the retention capacitor C1, charge of the
electrode capacitor C2.

Hamiltonian (per segment, summed)::

    H = K_b theta**2/2 + K (l_p - L_p)**2/2 + p**2/(2 I_s) + Q1**2/(2 C1) + Q2**2/(2 C2(l_e))
        + m g y_c   (gravity of the link's centre of mass, summed over the chain)

Geometry (volume conservation of the incompressible dielectric, eqs. 1-4)::

    alpha = (pi - theta)/2
    c     = L_v cos(alpha) + sqrt(l_p**2 - L_v**2 sin(alpha)**2 + eps**2)     (third side of the shell triangle)
    A_s   = L_v c sin(alpha) / 4                                            (shell area, = l_p L_v sin(delta1)/4)
    A_T   = A_s + X_h (L_e - l_e),  A_T = X_h L_e                           (unzipped at rest)
    C2    = eps0 eps_r w (l_e/(2 t_f) + (L_e - l_e)/(2 t_f + X_h))

Coupling: ``l_p' = d theta'`` with ``d = 2 A_s / l_p`` (a modulated
transformer); the electrostatic torque is ``-dH/dtheta - d dH/dl_p`` with no
hand-written coupling.  Electrical network per segment: the source voltage
times the input map ``gamma1 cos(gamma2 theta)`` (a modulated transformer)
drives ``R0 -> (C1 || R1) -> (C2 || R2)``.  All segments hang on one source
``U``.  Outputs: the source current ``U.i`` (port output, with feedthrough
through R0) and the measured tip displacement
``tip = (L_v + L_e) sum_j sin(sum_{i<=j} theta_i)`` and ``current``.

Deviations from the printed paper (each discussed in ``docs/systems/curling_hasel.md``):

* Inertia: ``I_s`` per segment (eq. 15); the printed ``(1/12) a m`` is not an
  inertia; the default is the chosen value of ``I_s`` documented in the docs
  page.  ``inertia="chain"`` uses the serial-chain M(theta) of eq. 12 instead.
* Geometry: the arcsin form of delta1 is replaced by the equivalent
  law-of-cosines form and ``sqrt(X)`` by ``sqrt(X + eps**2)``, which keeps the
  model finite at the singular rest point (``theta = 0, l_p = L_v``) and makes
  the shell area of negative angles ~0 instead of negative.
* Eq. 17's ``A_s K (l_p - L_p)/l_p`` is taken as ``d K (l_p - L_p)`` with
  ``d = 2 A_s/l_p`` (the factor 2 of eq. 16), which the transformer produces.
* Gravity: potential of every link's centre of mass in the chain (``H_g``),
  not the local term of eq. 17.
* ``R0`` is per segment: each segment has its own branch driven by ``U``.
* Units: ``U`` in volts and the input gain ``gamma1`` rescaled (see docs).
* Electrical network (``network="referred"``, default): R0, R1, R2 of Table 4 multiplied and C1 divided
  by ``REFERRAL = (2.0 / 0.04038)**2``, so that the currents seen by the source are those of the
  paper's own scale (printed gain on U in kV): 33 mA peaks at a 5 kV step, microamperes of leakage;
  ``network="printed"`` keeps Table 4's values (80 A peaks, tens of mA of leakage).
"""

from __future__ import annotations

import sympy as sp

from components import Gravity, VoltageSource
from phs import Measured, Param, PHSystem, interconnect, parallel, series, symbol_of_output, symbol_of_state
from phs.errors import ModelError
from systems._hasel import electrode_branch, pouch_parameters, shell

#: the printed input gain 40.38 read on U in kV (the paper's own scale), as a gain on volts
GAMMA1_PRINTED = 40.38e-3
#: the default gain on volts (the rescaling of the docs page)
GAMMA1_DEFAULT = 2.0
#: (gamma1 / printed gamma1)**2: the factor by which the rescaling multiplies every conductance seen
#: from the source; the "referred" network divides it out again (about 2453)
REFERRAL = (GAMMA1_DEFAULT / GAMMA1_PRINTED) ** 2
NETWORKS = ("referred", "printed")


def default_parameters(network: str = "referred") -> dict[str, Param]:
    """The curling HASEL's parameters (Tables 3 and 4 and the documented choices).

    Parameters
    ----------
    network : {"referred", "printed"}
        ``"referred"`` (default): Table 4's R0, R1, R2 times ``REFERRAL`` and C1 divided by it, so that
        the source sees the currents of the paper's own scale (milliampere peaks at 5 kV);
        ``"printed"``: Table 4's values on the rescaled electrode voltage (ampere peaks, watts of
        leakage).  See ``docs/systems/curling_hasel.md``.

    Examples
    --------
    >>> default_parameters()["K_b"].value
    0.04
    >>> round(default_parameters()["R0"].value / 1e6, 3), default_parameters("printed")["R0"].value
    (2.453, 1000.0)
    """
    if network not in NETWORKS:
        raise ModelError(f"curling_hasel: network must be 'referred' or 'printed', got {network!r}")
    k = REFERRAL if network == "referred" else 1.0
    note = " (Table 4 value referred through the gain rescaling)" if network == "referred" else ""
    P = pouch_parameters(L_e=0.015) + [
        Param("m", 0.007, "kg", "mass of one segment", (0.003, 0.015)),
        Param("R0", 1e3 * k, "Ohm", "connector resistance (per segment branch)" + note, (1e2 * k, 1e5 * k)),
        Param("R1", 1e6 * k, "Ohm", "resistance of the charge-retention branch" + note, (1e5 * k, 1e7 * k)),
        Param("R2", 1.47e6 * k, "Ohm", "leakage resistance across the electrodes" + note, (1e5 * k, 1e7 * k)),
        Param("C1", 1.75e-5 / k, "F", "charge-retention capacitance" + note, (1e-6 / k, 1e-4 / k)),
        Param("K", 20.83, "N/m", "stiffness of the top film", (5.0, 50.0)),
        Param("K_b", 0.04, "N*m/rad", "torsional stiffness of the bottom film", (0.01, 0.1)),
        Param("b", 0.0031, "N*m*s/rad", "rotational damping", (0.0005, 0.01)),
        Param("gamma1", 2.0, "1", "input-map gain (printed 40.38; rescaled, see docs)", (0.5, 4.0)),
        Param("gamma2", 7.05, "1", "input-map angular frequency", (4.0, 10.0)),
        Param("g", 9.81, "m/s**2", "gravitational acceleration", (9.7, 9.9)),
        Param("I_s", 1.75e-5, "kg*m**2", "effective rotational inertia of one segment (eq. 15)", (1e-6, 1e-4)),
    ]
    return {p.name: p for p in P}


def curling_hasel(n_segments: int = 4, *, inertia: str = "segment", gravity: bool = True, drift: bool = True, untie=(),
                  network: str = "referred", **overrides) -> PHSystem:
    """Curling HASEL with ``n_segments`` segments sharing one voltage source.

    Parameters
    ----------
    n_segments : int
        Number of segments (1 to at least 32).
    inertia : {"segment", "chain"}
        Per-segment inertia ``I_s`` (eq. 15) or the serial-chain M(theta) of eq. 12.
    gravity : bool
        Include the gravitational potential of the links.
    drift : bool
        Include the charge-retention branch ``C1 || R1`` of each segment (without it: the model of
        the paper before the drift was explained; ``C1``, ``R1`` and the states ``seg{i}.Q1`` go away).
    untie : sequence of str
        Shared parameters to declare per segment (``seg{i}.K_b``) instead of once.
    network : {"referred", "printed"}
        Values of R0, R1, R2, C1: Table 4's referred through the input-gain rescaling (default; source
        current peaks of 33 mA at a 5 kV step, microamperes of leakage) or as printed (80 A peaks).
    **overrides : float
        Parameter values by name (``K_b=0.05``).

    Returns
    -------
    PHSystem

    Examples
    --------
    >>> s = curling_hasel(2)
    >>> s.state_names[:5]
    ['seg1.theta', 'seg1.l_p', 'seg1.p', 'seg1.Q1', 'seg1.Q2']
    >>> s.input_names, s.measured_names
    (['U'], ['tip', 'current'])
    """
    if not isinstance(n_segments, int) or n_segments < 1:
        raise ModelError(f"curling_hasel: n_segments must be a positive integer, got {n_segments!r}")
    if inertia not in ("segment", "chain"):
        raise ModelError(f"curling_hasel: inertia must be 'segment' or 'chain', got {inertia!r}")
    base = default_parameters(network)
    unknown = [k for k in list(overrides) + list(untie) if k not in base]
    if unknown:
        raise ModelError(f"curling_hasel: unknown parameter(s) {unknown}; known: {sorted(base)}")
    for k, v in overrides.items():
        base[k] = base[k].with_value(v)

    def P(name: str, i: int) -> Param:
        q = base[name]
        return q.renamed(f"seg{i}.{name}") if name in untie else q

    def S(name: str, i: int) -> sp.Symbol:
        return P(name, i).symbol

    comps, conns = [VoltageSource("U", range=(-10e3, 10e3))], []
    shared = [q for k, q in base.items() if k not in untie and (drift or k not in ("C1", "R1"))]
    a = base["L_v"].symbol + base["L_e"].symbol  # link length
    thetas = [symbol_of_state(f"seg{i}.theta") for i in range(1, n_segments + 1)]
    ga_ports = []
    for i in range(1, n_segments + 1):
        Pi, Si = (lambda n, i=i: P(n, i)), (lambda n, i=i: S(n, i))
        parts, (mech, top), A_s, th = shell(f"seg{i}", Pi, Si, inertia=(inertia == "segment"))
        if inertia == "chain":
            mech.insert(1, f"chain.p{i}")
        elec, econns, _ = electrode_branch(f"seg{i}", [A_s], th, Pi, Si, drift=drift)
        comps += parts + elec
        conns += [series(*mech), top] + econns
        ga_ports.append(f"seg{i}.ga.a")
        if gravity:
            phi = sum(thetas[:i])
            prev = sum((a * sp.cos(sum(thetas[:j])) for j in range(1, i)), sp.Integer(0))
            comps.append(Gravity(f"seg{i}.grav", height=-(prev + a / 2 * sp.cos(phi)), m=P("m", i), g=P("g", i)))
    if inertia == "chain":
        from components.kinematics import KinematicChain

        comps.append(KinematicChain("chain", angles=[f"seg{i}.theta" for i in range(1, n_segments + 1)],
                                    lengths=[a] * n_segments, masses=[S("m", i) for i in range(1, n_segments + 1)],
                                    momenta=[f"seg{i}.p" for i in range(1, n_segments + 1)]))
    conns.append(parallel("U", *ga_ports) if n_segments > 1 else series("U", ga_ports[0]))
    tip = a * sum(sp.sin(sum(thetas[: j + 1])) for j in range(n_segments))
    params = shared + [P(k, i) for k in untie for i in range(1, n_segments + 1)]
    return interconnect(
        f"curling_hasel{n_segments}", comps, conns, params=params,
        measured=[Measured("tip", tip, "m", "tip displacement h(theta), eq. 5"),
                  Measured("current", symbol_of_output("U.i"), "A", "source current (measured by the amplifier)")],
        description=f"curling HASEL actuator, {n_segments} segments ({inertia} inertia)",
    )
