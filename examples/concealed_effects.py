"""Recordings of an electrostatic actuator whose truth holds physics the nominal model lacks.

The nominal model is the 1-DOF parallel-plate actuator
:func:`systems.electrostatic_actuator.electrostatic_actuator` (states ``x``, ``m.p``, ``Q``;
input ``U`` [V]; measured ``position`` [m] and ``current`` [A]).  For each effect of the diagnosis
library (:data:`EFFECTS`, with the control ``none``) this module builds a *truth*: the same
actuator plus that effect, in a functional form deliberately unlike the simplest candidate form.
It drives the truth with a lab-like voltage program, samples at 1 kHz and adds white Gaussian
noise.  :func:`generate` returns a :class:`phs.workflows.recording.Recording` and what the truth
was; the command line writes CSV files::

    python examples/concealed_effects.py --out DIR [--seconds S] [--seed N] [--effects A,B] [--check]

The specimen
    m = 1 g, k = 46 N/m, b = 0.024 N s/m, eps = 1.05 x 3 eps0, A = 4 cm^2, g0 = 100 um,
    R_s = 10 kOhm (the nominal defaults are k = 50, b = 0.02, eps = 3 eps0).  Pull-in at
    V_pi = sqrt(8 k g0^3 / (27 eps A)) = 34.9 V; commands stay below 26 V (0.74 V_pi), where the
    gap closes by up to 13 um with overshoot.
The truths (parameters in :data:`SIZES`; port-Hamiltonian systems built from :mod:`components`
unless said otherwise)
    charge_retention: two leaky dielectric layers (``DriftBranch`` C_i || R_i, tau = 0.15 s and
    1.2 s) in series with the gap capacitor.  leakage: a conductance across the gap growing with
    its voltage, G0 (1 + (V/V0)^2).  series_resistance: the electrode film's resistance as a
    two-section RC ladder.  coulomb_friction: LuGre-type bristles (stiffness, damping, slip
    |v| F / g(v) with a Stribeck curve g).  viscoelastic_creep: two Maxwell arms (0.08 s, 0.8 s).
    cubic_stiffness: F = k x + k3 x^3 + k5 x^5.  hysteresis: Bouc-Wen with n = 2 in passive
    Maxwell form.  quadratic_drag: F = c |v|^1.7 beside a weaker linear damper.  added_mass: a
    payload on a compliant mount (90 Hz).  input_saturation: asymmetric soft saturation
    U+ tanh(U/U+), U- tanh(U/U-) of the applied voltage.  slew_rate_limit: the applied voltage
    follows the command at most at 300 V/s.  time_delay: the applied voltage is the command 2 ms
    late.  offset: the position sensor reads (1 + g) x + x_off.  The last four act on the signals
    (amplifier, sensor): the system is the plain actuator.
Refit of the nominal model
    free parameters k, b, eps (:data:`NOMINAL_FREE`); m (weighed), R_s (the source's data
    sheet), g0 and A (geometry) are known.  :func:`concealment` refits from the nominal defaults
    with :func:`phs.workflows.identify.identify` and scores the refit against the noise-limited
    fit (the noise-free truth against the noisy recording).
Programs (:data:`TRAINING`, :data:`VALIDATION`, :data:`PROGRAMS`)
    ``steps`` (default): holds at 12, 20, 24, 8, 0 V, a 10-22 V square wave at 2 Hz, a +-16 V
    square wave at 1 Hz; validation: holds at 18, 6, 22 V, a 1.5 Hz sine, a 2-30 Hz chirp.
    ``ringing`` (quadratic_drag): square waves of four amplitudes; validation adds a 10-50 Hz
    chirp through the resonance.  ``smooth`` (time_delay, chirp to 3.5 Hz and sines; validation
    chirp to 15 Hz) and ``slew`` (slew_rate_limit, chirp to 5.5 Hz; validation chirp to 7 Hz):
    no step anywhere.  Every run starts at 0 V, idles at :data:`REST` = 0.1 V and repeats its
    program with amplitudes x1, 0.8, 1.08, 0.9 until the requested length.  Training sines and
    chirps are waveform tables (a point every 25 ms, linear in between: few kinks, so
    identification integrates long piecewise-linear stretches); validation ones are sampled at
    1 kHz.  The recorded ``U`` is the noise-free command.
Noise
    std 1 % of the position's range and 3 % of the current's standard deviation (the current's
    range is set by the few samples at voltage steps); one seeded stream per case, seed and split.

Concealment, measured with ``python examples/concealed_effects.py --out DIR --check`` (20 s runs,
seed 0).  Fit % as position / current: the nominal model refitted on the training run, the
noise-limited fit of the training run, the same refit on the validation run, the noise-limited
fit of the validation run; and the RMS of the truth minus the refitted nominal model over the
noise std (training run):

| case | nominal refit, training | noise-limited, training | nominal refit, validation | noise-limited, validation | mismatch / noise |
| --- | --- | --- | --- | --- | --- |
| charge_retention | 88.0 / 95.6 | 93.6 / 97.0 | 88.6 / 95.6 | 92.5 / 97.0 | 1.56 / 1.07 |
| leakage | 92.7 / 94.0 | 92.7 / 97.0 | 91.8 / 91.7 | 91.8 / 97.0 | 0.01 / 1.74 |
| series_resistance | 91.7 / 91.1 | 92.8 / 97.0 | 91.1 / 92.0 | 91.9 / 97.0 | 0.55 / 2.78 |
| coulomb_friction | 90.4 / 96.9 | 92.9 / 97.0 | 85.7 / 96.8 | 91.9 / 97.0 | 0.90 / 0.24 |
| viscoelastic_creep | 88.4 / 93.0 | 93.5 / 97.0 | 87.7 / 92.8 | 92.5 / 97.0 | 1.48 / 2.10 |
| cubic_stiffness | 87.2 / 96.5 | 92.8 / 97.0 | 88.4 / 96.5 | 92.1 / 97.0 | 1.49 / 0.59 |
| hysteresis | 90.4 / 94.1 | 93.2 / 97.0 | 88.1 / 93.9 | 92.0 / 97.0 | 1.00 / 1.71 |
| quadratic_drag | 90.0 / 96.9 | 92.2 / 97.0 | 86.9 / 96.8 | 93.0 / 97.0 | 0.80 / 0.24 |
| added_mass | 89.8 / 90.1 | 92.7 / 97.0 | 88.8 / 90.0 | 91.4 / 97.0 | 0.97 / 3.14 |
| input_saturation | 87.0 / 91.2 | 92.9 / 97.0 | 87.5 / 91.7 | 92.2 / 97.0 | 1.53 / 2.75 |
| slew_rate_limit | 95.3 / 91.6 | 95.7 / 97.0 | 91.8 / 81.4 | 95.4 / 97.0 | 0.44 / 2.62 |
| time_delay | 95.6 / 88.9 | 95.8 / 97.0 | 93.5 / 86.2 | 94.9 / 97.0 | 0.31 / 3.57 |
| offset | 89.0 / 94.7 | 92.7 / 97.0 | 87.2 / 94.7 | 91.8 / 97.0 | 1.13 / 1.46 |
| none | 92.7 / 97.0 | 92.7 / 97.0 | 91.8 / 97.0 | 91.8 / 97.0 | 0.01 / 0.02 |

In every case the refit scores >= 85 % on both training channels (lowest: 87.0 %), below the
noise-limited fit, and at least 3 points below the noise-limited fit on some validation channel
(smallest such gap: 3.7 points): the effect is there to be found.  The control's refit is
noise-limited.  ``tests/workflows/test_concealed_effects.py`` asserts this on 3 s runs (``--seconds
3``: lowest training fit 88.1 %, smallest gap 3.7 points), and on 20 s runs with ``-m slow``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass

import numpy as np
import sympy as sp

from components import Damper, DriftBranch, LinearSpring, Mass, Potential, Resistor, VariableCapacitor, VoltageSource
from phs import Condition, Measured, Param, interconnect, parallel, series, symbol_of_output, symbol_of_state
from phs.component import Component, Dissipator, Piece, Relation
from phs.errors import InputDataError
from phs.params import TIME
from phs.signals import Expression, square

FS = 1000.0  # sampling rate of every recording [Hz]
EPS0 = 8.854e-12
NOMINAL = {"m": 1e-3, "k": 50.0, "b": 0.02, "eps": EPS0 * 3.0, "A": 4e-4, "g0": 1e-4, "R_s": 1e4}
# the specimen differs from the nominal defaults as a real one would; refits start from the defaults
BASE = {**NOMINAL, "k": 46.0, "b": 0.024, "eps": EPS0 * 3.0 * 1.05}
NOMINAL_FREE = ("k", "b", "eps")
V_PULL_IN = math.sqrt(8 * BASE["k"] * BASE["g0"] ** 3 / (27 * BASE["eps"] * BASE["A"]))
C_GAP = BASE["eps"] * BASE["A"] / BASE["g0"]  # gap capacitance at rest [F]
NOISE = {"position": 0.01, "current": 0.03}  # noise std: fraction of the position's range, of the current's std
CHANNELS = ("position", "current")
MIN_FIT = 85.0  # the refitted nominal model scores at least this on every training channel (concealed)
MIN_GAP = 3.0  # ... and this many points below the noise-limited fit on some validation channel (detectable)

EFFECTS = ["charge_retention", "leakage", "series_resistance", "coulomb_friction", "viscoelastic_creep",
           "cubic_stiffness", "hysteresis", "quadratic_drag", "added_mass", "input_saturation", "slew_rate_limit",
           "time_delay", "offset", "none"]


class _SlipDamper(Component):
    """Translational conductive element ``v = G F`` with a state-dependent conductance ``G >= 0`` [m/(N s)]."""

    def __init__(self, name, G):
        super().__init__(name)
        self.G = G

    def piece(self) -> Piece:
        port = self._port("p", "translational")
        return Piece(self.name, ports=(port,), relations=(Relation(port.flow - self.G * port.effort, self.name, "resistive"),),
                     dissipators=(Dissipator(self.name, (port,)),))


def _sabs(v, eps):
    """Smooth absolute value ``sqrt(v**2 + eps**2)``."""
    return sp.sqrt(v**2 + eps**2)


@dataclass(frozen=True)
class Truth:
    """A truth model: the system, how the recorded command becomes the applied voltage, its form in words.

    Examples
    --------
    >>> tr = truth("time_delay")
    >>> tr.parameters, tr.applied(np.array([0.0, 0.001]), np.array([0.0, 1.0]))[0].tolist()
    ({'delay': 0.002}, [0.0, 0.002, 0.003])
    """

    effect: str
    system: object
    form: str
    parameters: dict
    applied: object = None  # callable (t, U) -> (times, values) of the applied voltage; None: U itself


def _build(name, effect_part=None, base=None):
    """The actuator of :mod:`systems.electrostatic_actuator` with the specimen's values, plus an effect.

    ``effect_part(S)`` receives symbols (``x``, ``Q``, the plate velocity ``v``, the gap capacitance
    ``C``, the gap voltage ``V_C``) and returns a dict with any of ``components``, ``electrical``
    (members of the source's series loop in place of ``"C"``), ``electrical_components`` (in place
    of the gap capacitor), ``mechanical`` (more members of the plate's velocity junction),
    ``params``, ``position`` (the measured position).
    """
    vals = {**BASE, **(base or {})}
    P = {k: Param(k, vals[k], u, d) for k, u, d in [
        ("m", "kg", "mass of the movable electrode"), ("k", "N/m", "suspension stiffness"), ("b", "N*s/m", "damping"),
        ("eps", "F/m", "permittivity of the gap"), ("A", "m**2", "electrode area"), ("g0", "m", "rest gap"),
        ("R_s", "Ohm", "series resistance of the source")]}
    x, Q = symbol_of_state("x"), symbol_of_state("Q")
    eps, A, g0 = P["eps"].symbol, P["A"].symbol, P["g0"].symbol
    C = eps * A / (g0 - x)
    S = {"x": x, "Q": Q, "v": symbol_of_state("m.p") / P["m"].symbol, "C": C, "V_C": Q * (g0 - x) / (eps * A)}
    part = effect_part(S) if effect_part else {}
    comps = [LinearSpring("k", K=P["k"], state="x", range=(-5e-5, 9e-5), scale=3e-5), Mass("m", m=P["m"], scale=1e-5, range=(-2e-5, 2e-5)),
             Damper("b", b=P["b"]), VoltageSource("U", range=(-200.0, 200.0)), Resistor("Rs", R=P["R_s"])]
    comps += part.get("electrical_components", [VariableCapacitor("C", C=C, C_typical=1e-10, state="Q", scale=1e-8)])
    comps += part.get("components", [])
    conns = [series("U", "Rs", *part.get("electrical", ["C"])), series("m", "k", "b", *part.get("mechanical", ()))]
    return interconnect(name, comps, conns, params=list(P.values()) + part.get("params", []),
                        measured=[Measured("position", part.get("position", x), "m", "gap closure as measured"),
                                  Measured("current", symbol_of_output("U.i"), "A", "source current")],
                        conditions=[Condition("gap open (x < g0)", g0 - x, "the electrodes must not touch")],
                        description=f"electrostatic actuator with {name.removeprefix('truth_').replace('_', ' ')}")


def _p(name, value, unit, description):
    return Param(name, float(value), unit, description)


# -- the truths ----------------------------------------------------------------------------------------------------------
# effect parameters at size 1, each tuned so that the effect stays concealed yet detectable (table above)
SIZES = {
    "charge_retention": {"C1": 13 * C_GAP, "tau1": 0.15, "C2": 23 * C_GAP, "tau2": 1.2},
    "leakage": {"G0": 1.5e-10, "V0": 20.0},
    "series_resistance": {"R1": 2.4e6, "R2": 4.8e6, "fraction": 0.6},
    "coulomb_friction": {"Fc": 1.0e-5, "Fs": 1.65e-5, "vs": 1e-3, "sigma0": 1e3, "sigma1": 0.5},
    "viscoelastic_creep": {"k1": 3.75, "tau1": 0.08, "k2": 3.1, "tau2": 0.8},
    "cubic_stiffness": {"k3": 2.4e10, "k5": 6.8e19},
    "hysteresis": {"k_h": 6.0, "z_max": 4e-6, "gamma_ratio": 0.5},
    "quadratic_drag": {"c": 3.0, "b": 0.01},
    "added_mass": {"m_a": 0.15e-3, "f_a": 90.0, "zeta_a": 0.1},
    "input_saturation": {"U_pos": 39.5, "U_neg": 30.0},
    "slew_rate_limit": {"S": 300.0},
    "time_delay": {"delay": 2.0e-3},
    "offset": {"offset": 3e-7, "gain": 0.03},
    "none": {},
}


def truth(effect: str, size: float = 1.0) -> Truth:
    """The truth model of ``effect``.

    Parameters
    ----------
    effect : str
        One of :data:`EFFECTS`.
    size : float
        Multiplier of the effect's strength (1: the tuned value of :data:`SIZES`).

    Returns
    -------
    Truth
        ``system`` (a PHSystem with inputs ``U`` and measured ``position``, ``current``), ``form``
        (the functional form in words), ``parameters`` (the effect's), ``applied`` (the map from the
        recorded command to the applied voltage, for amplifier effects).

    Raises
    ------
    InputDataError
        For an unknown effect or a size that is not positive.

    Examples
    --------
    >>> tr = truth("viscoelastic_creep")
    >>> tr.system.state_names
    ['x', 'm.p', 'Q', 've1.z', 've2.z']
    """
    if effect not in EFFECTS:
        raise InputDataError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
    if not size > 0:
        raise InputDataError(f"effect size must be positive, got {size}")
    return _TRUTHS[effect]({k: float(x) for k, x in SIZES[effect].items()}, float(size))


def _charge_retention(v, size):
    c1, c2 = v["C1"] / size, v["C2"] / size
    r1, r2 = v["tau1"] / (c1 + C_GAP), v["tau2"] / (c2 + C_GAP)

    def part(S):
        return {"components": [DriftBranch("D1", C1=c1, R1=r1, state="D1.Q", range=(-3e-7, 3e-7)),
                               DriftBranch("D2", C1=c2, R1=r2, state="D2.Q", range=(-3e-7, 3e-7))],
                "electrical": ["D1", "D2", "C"]}
    return Truth("charge_retention", _build("truth_charge_retention", part),
                 "two leaky dielectric layers (C_i || R_i, i = 1, 2) in series with the gap capacitor; "
                 "time constants about R_i (C_i + C_gap)", {"C1": c1, "R1": r1, "C2": c2, "R2": r2, "tau1": v["tau1"], "tau2": v["tau2"]})


def _leakage(v, size):
    g0, v0 = v["G0"] * size, v["V0"]

    def part(S):
        G0, V0 = _p("leak.G0", g0, "S", "leakage conductance at zero voltage"), _p("leak.V0", v0, "V", "voltage scale of the growth")
        G = G0.symbol * (1 + (S["V_C"] / V0.symbol) ** 2)
        return {"components": [Resistor("leak", G=G)], "electrical": [parallel("C", "leak")], "params": [G0, V0]}
    return Truth("leakage", _build("truth_leakage", part),
                 "conductance across the gap growing with its voltage: G = G0 (1 + (V_C/V0)^2)", {"G0": g0, "V0": v0})


def _series_resistance(v, size):
    r1, r2, f = v["R1"] * size, v["R2"] * size, v["fraction"]

    def part(S):
        return {"electrical_components": [VariableCapacitor("Ca", C=f * S["C"], C_typical=1e-10, state="Q", scale=1e-8),
                                          VariableCapacitor("Cb", C=(1 - f) * S["C"], C_typical=1e-10, state="Qb", scale=1e-8),
                                          Resistor("Rf1", R=r1), Resistor("Rf2", R=r2)],
                "electrical": ["Rf1", parallel("Ca", series("Rf2", "Cb"))]}
    return Truth("series_resistance", _build("truth_series_resistance", part),
                 "distributed electrode-film resistance: a two-section RC ladder (R1 to a fraction f of the electrode, "
                 "R1 + R2 to the rest)", {"R1": r1, "R2": r2, "fraction": f})


def _coulomb_friction(v, size):
    fc, fs, vs, s0, s1 = v["Fc"] * size, v["Fs"] * size, v["vs"], v["sigma0"], v["sigma1"]

    def part(S):
        g = fc + (fs - fc) * sp.exp(-((S["v"] / vs) ** 2))
        return {"components": [LinearSpring("bristle", K=s0, state="fr.z", range=(-1e-7, 1e-7), scale=1e-8),
                               Damper("bristle_d", b=s1), _SlipDamper("slip", _sabs(S["v"], 1e-6) / g)],
                "mechanical": [parallel(series("bristle", "bristle_d"), "slip")]}
    return Truth("coulomb_friction", _build("truth_coulomb_friction", part),
                 "LuGre-type bristle friction: bristle z (stiffness sigma0, damping sigma1) slipping at "
                 "|v| F / g(v), Stribeck curve g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2)",
                 {"Fc": fc, "Fs": fs, "vs": vs, "sigma0": s0, "sigma1": s1})


def _viscoelastic_creep(v, size):
    k1, k2 = v["k1"] * size, v["k2"] * size
    e1, e2 = k1 * v["tau1"], k2 * v["tau2"]

    def part(S):
        return {"components": [LinearSpring("ve1", K=k1, state="ve1.z", range=(-5e-5, 5e-5), scale=1e-5), Damper("ve1d", b=e1),
                               LinearSpring("ve2", K=k2, state="ve2.z", range=(-5e-5, 5e-5), scale=1e-5), Damper("ve2d", b=e2)],
                "mechanical": [parallel("ve1", "ve1d"), parallel("ve2", "ve2d")]}
    return Truth("viscoelastic_creep", _build("truth_viscoelastic_creep", part),
                 "generalized standard linear solid: two Maxwell arms (k_i in series with eta_i) beside the suspension",
                 {"k1": k1, "eta1": e1, "k2": k2, "eta2": e2, "tau1": v["tau1"], "tau2": v["tau2"]})


def _cubic_stiffness(v, size):
    k3, k5 = v["k3"] * size, v["k5"] * size

    def part(S):
        K3, K5 = _p("k3", k3, "N/m**3", "cubic stiffness"), _p("k5", k5, "N/m**5", "quintic stiffness")
        x = S["x"]
        return {"components": [Potential("stiffening", K3.symbol * x**4 / 4 + K5.symbol * x**6 / 6, params=[K3, K5])]}
    return Truth("cubic_stiffness", _build("truth_cubic_stiffness", part),
                 "stiffening suspension: F = k x + k3 x^3 + k5 x^5", {"k3": k3, "k5": k5})


def _hysteresis(v, size):
    kh, zmax, r = v["k_h"] * size, v["z_max"], v["gamma_ratio"]
    beta = 1.0 / ((1 + r) * zmax**2)  # loading saturates z at (beta + gamma)^(-1/2) = z_max
    gamma = r * beta

    def part(S):
        z, vel = symbol_of_state("hyst.z"), S["v"]
        G = (beta * _sabs(vel, 1e-6) * _sabs(z, 1e-9) + gamma * vel * z) / kh
        return {"components": [LinearSpring("hyst", K=kh, state="hyst.z", range=(-2e-5, 2e-5), scale=5e-6),
                               _SlipDamper("hyst_slip", G)],
                "mechanical": [parallel("hyst", "hyst_slip")]}
    return Truth("hysteresis", _build("truth_hysteresis", part),
                 "Bouc-Wen hysteresis with n = 2 in passive Maxwell form: F_h = k_h z, "
                 "z' = v - beta |v| |z| z - gamma v z^2 (beta >= |gamma|)",
                 {"k_h": kh, "beta": beta, "gamma": gamma, "n": 2, "z_max": zmax})


def _quadratic_drag(v, size):
    c = v["c"] * size

    def part(S):
        return {"components": [Damper("drag", b=c * (S["v"] ** 2 + 1e-12) ** sp.Rational(7, 20))], "mechanical": ["drag"]}
    return Truth("quadratic_drag", _build("truth_quadratic_drag", part, base={"b": v["b"]}),
                 "power-law drag F = c |v|^1.7 sign(v) (smoothed at |v| < 1e-6 m/s) beside a weaker linear damping b",
                 {"c": c, "exponent": 1.7, "b": v["b"]})


def _added_mass(v, size):
    ma = v["m_a"] * size
    ka = ma * (2 * math.pi * v["f_a"]) ** 2
    ba = 2 * v["zeta_a"] * math.sqrt(ka * ma)

    def part(S):
        return {"components": [Mass("ma", m=ma, state="ma.p", scale=1e-5),
                               LinearSpring("ka", K=ka, state="ka.l", range=(-2e-5, 2e-5), scale=1e-5), Damper("ba", b=ba)],
                "mechanical": [parallel(series("ka", "ba"), "ma")]}
    return Truth("added_mass", _build("truth_added_mass", part),
                 "payload mass m_a carried on a compliant mount (k_a, b_a): rigid added mass below f_a, decoupled above",
                 {"m_a": ma, "k_a": ka, "b_a": ba, "f_a": v["f_a"]})


def _input_saturation(v, size):
    up, un = v["U_pos"] / math.sqrt(size), v["U_neg"] / math.sqrt(size)

    def applied(t, U):
        return t, np.where(U >= 0, up * np.tanh(U / up), un * np.tanh(U / un))
    return Truth("input_saturation", _build("truth_input_saturation"),
                 "asymmetric soft saturation of the amplifier: U_applied = U+ tanh(U/U+) for U >= 0, U- tanh(U/U-) below",
                 {"U_pos": up, "U_neg": un}, applied=applied)


def _slew_rate_limit(v, size):
    rate = v["S"] / size

    def applied(t, U):
        return _rate_limited(t, U, rate)
    return Truth("slew_rate_limit", _build("truth_slew_rate_limit"),
                 "the amplifier's output follows the command at most at a slew rate S (V/s)", {"S": rate}, applied=applied)


def _time_delay(v, size):
    d = v["delay"] * size

    def applied(t, U):
        return np.concatenate([[t[0]], t + d]), np.concatenate([[U[0]], U])
    return Truth("time_delay", _build("truth_time_delay"), "transport delay of the applied voltage: U_applied(t) = U(t - d)",
                 {"delay": d}, applied=applied)


def _offset(v, size):
    off, gain = v["offset"] * size, v["gain"] * size

    def part(S):
        return {"position": (1 + gain) * S["x"] + off}
    return Truth("offset", _build("truth_offset", part),
                 "position sensor with an offset and a gain error: position = (1 + g) x + x_off", {"offset": off, "gain": gain})


def _none(v, size):
    return Truth("none", _build("truth_none"), "the nominal actuator (with the specimen's own k, b, eps)", {})


_TRUTHS = {"charge_retention": _charge_retention, "leakage": _leakage, "series_resistance": _series_resistance,
           "coulomb_friction": _coulomb_friction, "viscoelastic_creep": _viscoelastic_creep, "cubic_stiffness": _cubic_stiffness,
           "hysteresis": _hysteresis, "quadratic_drag": _quadratic_drag, "added_mass": _added_mass,
           "input_saturation": _input_saturation, "slew_rate_limit": _slew_rate_limit, "time_delay": _time_delay,
           "offset": _offset, "none": _none}


def _rate_limited(t, U, rate, substeps=20):
    """The piecewise-linear command ``U`` (samples at ``t``) passed through a rate limiter: kinks of the result."""
    h = (t[1] - t[0]) / substeps
    tf = np.arange(len(t) - 1)[:, None] * (t[1] - t[0]) + t[0] + h * np.arange(substeps)[None, :]
    tf = np.append(tf.reshape(-1), t[-1])
    uf = np.interp(tf, t, U)
    y = np.empty_like(uf)
    y[0] = uf[0]
    step = rate * h
    prev = uf[0]
    for i in range(1, len(uf)):
        d = uf[i] - prev
        prev = prev + (d if -step <= d <= step else math.copysign(step, d))
        y[i] = prev
    d2 = np.abs(y[2:] - 2 * y[1:-1] + y[:-2]) > 1e-9 * max(1.0, float(np.max(np.abs(y))))
    keep = np.concatenate([[True], d2, [True]])
    return tf[keep], y[keep]


# -- lab-like voltage programs -------------------------------------------------------------------------------------------
REST = 0.1  # idle level of the amplifier [V] (a hold at exactly 0 V lets the charge decay through denormal numbers)
TABLE_DT = 0.025  # training sines are waveform tables: points every 25 ms, linearly interpolated

# blocks: ("hold", level, s) | ("square", low, high, Hz, s) | ("sine", offset, amplitude, Hz, s)
#         | ("chirp", offset, amplitude, Hz0, Hz1, s); a level of 0 means REST.  Sines and chirps start at
#         offset - amplitude (a sine block of whole periods, or a chirp with an integer number of cycles
#         T (Hz0 + Hz1) / 2, also ends there), so the "smooth" programs have no step anywhere.
TRAINING = {
    "steps": [("hold", 12, 0.6), ("hold", 20, 0.6), ("hold", 24, 0.8), ("hold", 8, 0.6), ("hold", 0, 0.6),
              ("square", 10, 22, 2.0, 1.5), ("square", -16, 16, 1.0, 2.0), ("hold", 0, 0.5)],
    "smooth": [("chirp", 11, 11, 0.5, 3.5, 2.0), ("sine", 9, 9, 2.0, 1.5), ("sine", 12, 12, 1.0, 2.0), ("hold", 0, 0.4)],
    "slew": [("chirp", 11, 11, 0.5, 5.5, 2.0), ("sine", 9, 9, 3.0, 1.0), ("sine", 12, 12, 1.0, 2.0), ("hold", 0, 0.4)],
    "ringing": [("square", 6, 14, 3.0, 1.0), ("square", 10, 24, 3.0, 1.0), ("square", 2, 18, 2.0, 1.0),
                ("square", -14, 14, 2.0, 1.0), ("hold", 0, 0.5)],
}
VALIDATION = {
    "steps": [("hold", 18, 0.6), ("hold", 6, 0.6), ("hold", 22, 0.8), ("sine", 14, 8, 1.5, 2.0),
              ("chirp", 12, 4, 2.0, 30.0, 2.0), ("hold", 0, 0.4)],
    "smooth": [("chirp", 8, 8, 1.0, 15.0, 2.0), ("sine", 12, 12, 1.5, 2.0), ("sine", 10, 10, 3.0, 1.0), ("hold", 0, 0.4)],
    "slew": [("chirp", 10, 10, 1.0, 7.0, 2.0), ("sine", 12, 12, 1.5, 2.0), ("sine", 10, 10, 3.0, 1.0), ("hold", 0, 0.4)],
    "ringing": [("square", 8, 20, 2.5, 1.2), ("hold", 0, 0.3), ("chirp", 14, 2.5, 10.0, 50.0, 2.0), ("square", 4, 16, 4.0, 1.0),
                ("hold", 0, 0.4)],
}
# the program of each case (default "steps")
PROGRAMS = {"time_delay": "smooth", "slew_rate_limit": "slew", "quadratic_drag": "ringing"}
CYCLE_GAINS = (1.0, 0.8, 1.08, 0.9)  # amplitude of successive repetitions of a program


def _render(block, tl, gain: float, as_table: bool) -> np.ndarray:
    """Values of one block, its amplitudes scaled by ``gain``, at local times ``tl`` (sines and chirps as
    waveform tables when ``as_table``)."""
    kind, args = block[0], [gain * a for a in block[1:-1]] + [block[-1]]
    if kind == "hold":
        return np.full_like(tl, args[0] if args[0] != 0 else REST)
    if kind == "square":
        low, high, f = block[1], block[2], block[3]
        return square(gain * (high - low) / 2, f, offset=gain * (high + low) / 2)(tl)
    if kind == "sine":
        off, amp, f = args[0], args[1], block[3]
        sig = Expression(sp.Float(off) - sp.Float(amp) * sp.cos(2 * sp.pi * sp.Float(f) * TIME))
    else:
        (off, amp), (f0, f1, dur) = args[:2], block[3:]
        phase = 2 * sp.pi * (sp.Float(f0) * TIME + sp.Float((f1 - f0) / (2 * dur)) * TIME**2)
        sig = Expression(sp.Float(off) - sp.Float(amp) * sp.cos(phase))
    if not as_table:
        return np.asarray(sig(tl), dtype=float)
    knots = np.arange(0.0, tl[-1] + TABLE_DT, TABLE_DT)
    return np.interp(tl, knots, np.asarray(sig(knots), dtype=float))


def program(effect: str, seconds: float, validation: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Sample times and the recorded voltage command of a case's training or validation run.

    The run starts at 0 V, idles at :data:`REST` until 0.2 s, then repeats the case's program
    (:data:`TRAINING` or :data:`VALIDATION`), each repetition scaled by the next of
    :data:`CYCLE_GAINS`, until ``seconds``.  Training sines and chirps are waveform tables (points
    every :data:`TABLE_DT`, linear in between); validation ones are sampled at 1 kHz.

    Examples
    --------
    >>> t, U = program("none", 2.0)
    >>> len(t), float(U[0]), float(U[100]), float(U.max()) <= 0.8 * V_PULL_IN
    (2001, 0.0, 0.1, True)
    """
    if not seconds >= 0.5:
        raise InputDataError(f"seconds must be at least 0.5, got {seconds}")
    n = int(round(seconds * FS)) + 1
    t = np.arange(n) / FS
    U = np.full(n, REST)
    U[0] = 0.0
    kind = PROGRAMS.get(effect, "steps")
    blocks = (VALIDATION if validation else TRAINING)[kind]
    start, cycle = 0.2, 0
    while start < t[-1]:
        gain = CYCLE_GAINS[cycle % len(CYCLE_GAINS)]
        for block in blocks:
            dur = block[-1]
            sel = (t >= start - 1e-9) & (t < start + dur - 1e-9)
            if np.any(sel):
                U[sel] = _render(block, t[sel] - start, gain, as_table=not validation)
            start += dur
        cycle += 1
    return t, U


# -- recordings ----------------------------------------------------------------------------------------------------------
def _case_seed(effect, seed, validation):
    return [EFFECTS.index(effect) + 1, int(seed), int(bool(validation))]


def simulate_truth(tr: Truth, t, U) -> dict:
    """Noise-free ``position`` and ``current`` of a truth driven by the command ``U`` sampled at ``t``.

    The command is linearly interpolated between samples, as identification reads a recording;
    amplifier effects (``tr.applied``) transform it first.

    Examples
    --------
    >>> t, U = program("none", 0.5)
    >>> clean = simulate_truth(truth("none"), t, U)
    >>> sorted(clean), bool(clean["position"].max() > 1e-6)
    (['current', 'position'], True)
    """
    from codegen.simulator import simulate
    from phs.signals import Sampled

    times, values = tr.applied(t, U) if tr.applied is not None else (t, U)
    u = Sampled(tuple(np.asarray(times, dtype=float)), tuple(np.asarray(values, dtype=float)))
    res = simulate(tr.system, t, u={"U": u}, rtol=1e-9)
    return {ch: np.asarray(res[ch], dtype=float) for ch in CHANNELS}


def generate(effect: str, *, seconds: float = 20.0, seed: int = 0, validation: bool = False, size: float = 1.0):
    """A noisy 1 kHz recording of the truth of ``effect``, and what the truth was.

    Parameters
    ----------
    effect : str
        One of :data:`EFFECTS` (``"none"``: the control, the nominal structure itself).
    seconds : float
        Length of the recording (at least 0.5 s).
    seed : int
        Noise seed; every case, seed and split (training or validation) has its own stream, so
        the same arguments always give the same recording.
    validation : bool
        The case's validation program instead of its training program.
    size : float
        Multiplier of the effect's tuned strength.

    Returns
    -------
    (Recording, dict)
        Signals ``U`` [V] (the command, noise-free), ``position`` [m], ``current`` [A]; and
        ``info``: ``effect``, ``form`` (the truth's functional form in words), ``parameters`` (the
        effect's), ``base_parameters`` (the specimen's actuator), ``nominal_free``, ``program``,
        ``noise_std`` per channel, ``clean`` (the noise-free channels), ``seed``, ``seconds``,
        ``validation``, ``size``.

    Raises
    ------
    InputDataError
        For an unknown effect, a size that is not positive or a recording shorter than 0.5 s.

    Examples
    --------
    >>> rec, info = generate("leakage", seconds=1.0)
    >>> rec.names, len(rec), info["form"].split(":")[0]
    (['U', 'position', 'current'], 1001, 'conductance across the gap growing with its voltage')
    """
    from phs.workflows.recording import Recording

    tr = truth(effect, size)
    t, U = program(effect, seconds, validation)
    clean = simulate_truth(tr, t, U)
    scale = {"position": float(np.ptp(clean["position"])), "current": float(np.std(clean["current"]))}
    noise_std = {ch: NOISE[ch] * scale[ch] for ch in CHANNELS}
    rng = np.random.default_rng(_case_seed(effect, seed, validation))
    noisy = {ch: clean[ch] + noise_std[ch] * rng.standard_normal(len(t)) for ch in CHANNELS}
    split = "validation" if validation else "train"
    rec = Recording.from_arrays(t, {"U": U, **noisy}, source=f"concealed_effects:{effect}:{split}",
                                units={"U": "V", "position": "m", "current": "A"})
    info = {"effect": effect, "form": tr.form, "parameters": dict(tr.parameters), "base_parameters": dict(BASE),
            "nominal_free": list(NOMINAL_FREE), "program": PROGRAMS.get(effect, "steps"), "noise_std": noise_std,
            "clean": clean, "seed": int(seed), "seconds": float(seconds), "validation": bool(validation), "size": float(size)}
    return rec, info


def concealment(effect: str, *, seconds: float = 20.0, seed: int = 0, size: float = 1.0) -> dict:
    """Refit the nominal actuator to a case's training run; score it against the noise-limited fit.

    Parameters
    ----------
    effect, seconds, seed, size
        As for :func:`generate` (training and validation runs of the same length and seed).

    Returns
    -------
    dict
        Per channel (``position``, ``current``): ``nominal_fit`` and ``nominal_validation_fit``
        (NRMSE fit % of the nominal model refitted on the training run), ``truth_fit`` and
        ``truth_validation_fit`` (the noise-free truth against the noisy recording: the
        noise-limited fit), ``validation_gap`` (truth minus nominal, validation run),
        ``mismatch_to_noise`` (RMS of the truth minus the refitted nominal model over the noise
        std, training run); ``values`` (the refitted k, b, eps); ``concealed`` (the refit scores at
        least :data:`MIN_FIT` on every training channel), ``detectable`` (some validation gap is at
        least :data:`MIN_GAP`), ``noise_limited`` (every fit within 0.5 points of the noise-limited
        one, as the control must be); ``fit_seconds``.

    Examples
    --------
    >>> r = concealment("none", seconds=1.0)
    >>> r["concealed"], r["noise_limited"]
    (True, True)
    """
    from phs.workflows.identify import identify, nrmse_fit
    from systems.electrostatic_actuator import electrostatic_actuator

    train, itr = generate(effect, seconds=seconds, seed=seed, size=size)
    val, iva = generate(effect, seconds=seconds, seed=seed, size=size, validation=True)
    wall = time.perf_counter()
    fit = identify(electrostatic_actuator(), train, list(NOMINAL_FREE), validation=val)
    out = {"effect": effect, "seconds": float(seconds), "seed": int(seed), "size": float(size),
           "values": {k: float(v) for k, v in fit.values.items()}, "fit_seconds": time.perf_counter() - wall}
    for key in ("nominal_fit", "nominal_validation_fit", "truth_fit", "truth_validation_fit", "validation_gap",
                "mismatch_to_noise"):
        out[key] = {}
    for ch in CHANNELS:
        sim = train[ch] - fit.residuals[ch]
        out["nominal_fit"][ch] = float(fit.fit_percent[ch])
        out["nominal_validation_fit"][ch] = float(fit.validation_fit_percent[ch])
        out["truth_fit"][ch] = nrmse_fit(train[ch], itr["clean"][ch])
        out["truth_validation_fit"][ch] = nrmse_fit(val[ch], iva["clean"][ch])
        out["validation_gap"][ch] = out["truth_validation_fit"][ch] - out["nominal_validation_fit"][ch]
        out["mismatch_to_noise"][ch] = float(np.sqrt(np.mean((itr["clean"][ch] - sim) ** 2)) / itr["noise_std"][ch])
    out["concealed"] = all(out["nominal_fit"][ch] >= MIN_FIT for ch in CHANNELS)
    out["detectable"] = max(out["validation_gap"].values()) >= MIN_GAP
    out["noise_limited"] = all(abs(out[a][ch] - out[b][ch]) <= 0.5 for ch in CHANNELS
                               for a, b in (("truth_fit", "nominal_fit"), ("truth_validation_fit", "nominal_validation_fit")))
    return out


def table(results) -> str:
    """Markdown table of :func:`concealment` results (fit % as position / current).

    Examples
    --------
    >>> r = {"effect": "none", "nominal_fit": {"position": 95.0, "current": 97.0}, "truth_fit": {"position": 95.0, "current": 97.0},
    ...      "nominal_validation_fit": {"position": 94.0, "current": 96.0},
    ...      "truth_validation_fit": {"position": 94.0, "current": 96.0}, "mismatch_to_noise": {"position": 0.0, "current": 0.0}}
    >>> print(table([r]).splitlines()[2])
    | none | 95.0 / 97.0 | 95.0 / 97.0 | 94.0 / 96.0 | 94.0 / 96.0 | 0.00 / 0.00 |
    """
    def pair(d, fmt="{:.1f}"):
        return " / ".join(fmt.format(d[ch]) for ch in CHANNELS)

    lines = ["| case | nominal refit, training | noise-limited, training | nominal refit, validation "
             "| noise-limited, validation | mismatch / noise |", "| --- | --- | --- | --- | --- | --- |"]
    for r in results:
        lines.append(f"| {r['effect']} | {pair(r['nominal_fit'])} | {pair(r['truth_fit'])} | {pair(r['nominal_validation_fit'])} "
                     f"| {pair(r['truth_validation_fit'])} | {pair(r['mismatch_to_noise'], '{:.2f}')} |")
    return "\n".join(lines)


# -- files ---------------------------------------------------------------------------------------------------------------
def write_csv(recording, path) -> None:
    """Write a recording as CSV (columns ``t`` and its signals) atomically.

    Examples
    --------
    >>> import tempfile
    >>> from phs.workflows.recording import Recording
    >>> rec = Recording.from_arrays(np.arange(3) / FS, {"U": np.zeros(3), "position": np.ones(3)})
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_csv(rec, os.path.join(d, "r.csv"))
    ...     Recording.from_csv(os.path.join(d, "r.csv"))["position"].tolist()
    [1.0, 1.0, 1.0]
    """
    from codegen.results import write_csv_atomic

    write_csv_atomic(path, ["t"] + recording.names, np.column_stack([recording.t] + [recording[n] for n in recording.names]))


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


def main(argv=None) -> int:
    """Command line: write training and validation CSV files of every case (and check concealment).

    ``python examples/concealed_effects.py --out DIR [--seconds S] [--seed N] [--effects A,B] [--check]``
    writes ``DIR/{effect}_train.csv`` and ``DIR/{effect}_validation.csv`` (columns ``t``, ``U``,
    ``position``, ``current``; SI units) and ``DIR/cases.json`` (per case: the truth's form and
    parameters, the program, the noise std, the nominal model's free parameters).  ``--check``
    also refits the nominal model to every case, prints the concealment table and writes
    ``DIR/concealment.json``.  Nothing is written before every requested case is generated.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     main(["--out", d, "--seconds", "0.5", "--effects", "none", "--quiet"])
    ...     sorted(os.listdir(d))
    0
    ['cases.json', 'none_train.csv', 'none_validation.csv']
    """
    ap = argparse.ArgumentParser(prog="concealed_effects.py", description="Write concealed-effect recordings of the "
                                 "electrostatic actuator: training and validation CSV files of every case.")
    ap.add_argument("--out", required=True, help="directory for the CSV files (created if missing)")
    ap.add_argument("--seconds", type=float, default=20.0, help="length of every recording (default 20 s)")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    ap.add_argument("--effects", default=",".join(EFFECTS), help="comma-separated cases (default: all)")
    ap.add_argument("--check", action="store_true", help="refit the nominal model and print the concealment table")
    ap.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = ap.parse_args(argv)
    effects = [e.strip() for e in args.effects.split(",") if e.strip()]
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        ap.error(f"unknown effect(s) {unknown}; known: {', '.join(EFFECTS)}")
    files, cases, results = {}, {}, []
    for e in effects:
        wall = time.perf_counter()
        noise = {}
        for split, validation in (("train", False), ("validation", True)):
            rec, info = generate(e, seconds=args.seconds, seed=args.seed, validation=validation)
            files[f"{e}_{split}.csv"] = rec
            noise[split] = info["noise_std"]
        cases[e] = {k: info[k] for k in ("form", "parameters", "base_parameters", "nominal_free", "program", "seconds", "seed")}
        cases[e]["noise_std"] = noise
        if args.check:
            results.append(concealment(e, seconds=args.seconds, seed=args.seed))
        if not args.quiet:
            print(f"  {e}: {time.perf_counter() - wall:.1f} s", file=sys.stderr, flush=True)
    os.makedirs(args.out, exist_ok=True)
    for name, rec in files.items():
        write_csv(rec, os.path.join(args.out, name))
    from phs.io import write_atomic

    write_atomic(os.path.join(args.out, "cases.json"), json.dumps(_plain(cases), indent=2))
    if args.check:
        write_atomic(os.path.join(args.out, "concealment.json"), json.dumps(_plain(results), indent=2))
        print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
