"""Shared fixtures: a seeded random generator and the small reference systems.

Systems are session-scoped (a PHSystem is immutable, so sharing is safe) and
may be used in hypothesis tests, which refuse function-scoped fixtures.

Hypothesis runs under the profile ``ci`` unless ``HYPOTHESIS_PROFILE`` names another:
derandomized (the same examples on every run and machine), no example database (nothing is
written into the checkout), no deadline (timings vary on shared machines).  ``HYPOTHESIS_PROFILE=explore``
draws fresh random examples, still without a database, for a search beyond the fixed examples.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import settings

from systems.examples import duffing_oscillator, mass_spring_damper, rc_circuit, rlc_circuit

settings.register_profile("ci", derandomize=True, database=None, deadline=None)
settings.register_profile("explore", derandomize=False, database=None, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

SEED = 20240611


@pytest.fixture
def rng() -> np.random.Generator:
    """A freshly seeded generator per test, so every test is reproducible on its own."""
    return np.random.default_rng(SEED)


@pytest.fixture(scope="session")
def rc():
    return rc_circuit()


@pytest.fixture(scope="session")
def rlc():
    return rlc_circuit()


@pytest.fixture(scope="session")
def msd():
    return mass_spring_damper()


@pytest.fixture(scope="session")
def duffing():
    return duffing_oscillator(b=0.3)


@pytest.fixture(scope="session")
def examples(rc, rlc, msd, duffing):
    """The reference systems by name."""
    return {"rc": rc, "rlc": rlc, "msd": msd, "duffing": duffing}


def electromechanical_system():
    """A coupled model exercising most translation paths: a capacitance modulated by a spring length,
    a geometric angle phi = asin(l / L) (validity conditions), gravity on it, a state-modulated
    transformer, a gaussian (erf-energy) spring and measured outputs that use an input."""
    import sympy as sp

    from components import (
        Damper,
        ForceSource,
        GeometricConstraint,
        Gravity,
        LinearSpring,
        Mass,
        NonlinearSpring,
        Resistor,
        Transformer,
        VariableCapacitor,
        VoltageSource,
        geometric_symbol,
    )
    from phs import Measured, Param, bond, interconnect, series, symbol_of_input, symbol_of_state

    l, Q, U = symbol_of_state("k.l"), symbol_of_state("Cv.Q"), symbol_of_input("U")  # noqa: E741
    phi = geometric_symbol("phi")
    C0, l0 = Param("C0", 1e-6, "F", "nominal capacitance"), Param("l0", 0.05, "m", "modulation length")
    L, Lp = Param("L", 0.2, "m", "arm length"), Param("L_p", 0.1, "m", "pendulum length")
    g0, w = Param("g0", 0.5, "N", "gaussian force"), Param("w", 0.05, "m", "gaussian width")
    n0 = Param("n0", 0.5, "1", "nominal lever ratio")
    q = sp.Symbol("q", real=True)
    C = C0.symbol * (1 + (l / l0.symbol) ** 2)
    comps = [
        VoltageSource("U"), Resistor("R", R=1e3), VariableCapacitor("Cv", C=C, C_typical=1e-6),
        ForceSource("F"), Mass("m", m=0.1), LinearSpring("k", K=20.0, range=(-0.1, 0.1)), Damper("b", b=0.5),
        Transformer("tf", n0.symbol * (2 + sp.cos(l / l0.symbol))),
        NonlinearSpring("s", force=g0.symbol * sp.exp(-(q / w.symbol) ** 2), variable=q, params=[g0, w]),
        GeometricConstraint("geo", "phi", sp.Eq(sp.sin(phi), l / L.symbol), params=[L]),
        Gravity("grav", height=Lp.symbol * sp.cos(phi), m=0.05),
    ]
    conns = [series("U", "R", "Cv"), series("F", "m", "k", "b", "tf.a"), bond("tf.b", "s")]
    measured = [Measured("v_C", Q / C, "V", "capacitor voltage"),
                Measured("P_R", (U - Q / C) ** 2 / sp.Symbol("R.R", positive=True), "W", "resistor power"),
                Measured("angle", phi, "rad", "arm angle")]
    return interconnect("em", comps, conns, params=[C0, l0, L, Lp, n0], measured=measured)


def arm_system():
    """A damped double pendulum (a KinematicChain: sympy functions with their own CasADi translation)."""
    from components import KinematicChain, RotationalDamper, TorqueSource, TorsionalSpring
    from phs import interconnect, series

    arm = KinematicChain("arm", ["j1.theta", "j2.theta"], lengths=[0.1, 0.08], masses=[0.05, 0.03])
    return interconnect("arm", [arm, TorqueSource("T"), TorsionalSpring("j1", K=0.04, state="j1.theta"),
                                RotationalDamper("b1", b=1e-3), TorsionalSpring("j2", K=0.02, state="j2.theta"),
                                RotationalDamper("b2", b=1e-3)],
                        [series("T", "arm.p1", "j1", "b1"), series("arm.p2", "j2", "b2")])


@pytest.fixture(scope="session")
def electromechanical():
    return electromechanical_system()


@pytest.fixture(scope="session")
def arm():
    return arm_system()
