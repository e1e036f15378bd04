"""The specimen actuator, and its truths: the same actuator plus one effect its nominal model lacks.

The nominal model is the 1-DOF parallel-plate actuator
:func:`systems.electrostatic_actuator.electrostatic_actuator` (states ``x``, ``m.p``, ``Q``;
input ``U`` [V]; measured ``position`` [m] and ``current`` [A]).  For each effect of the diagnosis
library (:data:`EFFECTS`, with the control ``none``), :func:`truth` builds the specimen's actuator
plus that effect, in a functional form deliberately unlike the simplest candidate form.
:mod:`examples.concealed_effects` drives the truths with lab-like voltage programs and records them.

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
Pairs (:func:`pair_truth`, or ``truth("A+B")``)
    the actuator holding two effects, each at its single-effect strength: the two effects' parts
    joined into one system (an effect in series with the gap capacitor takes the other electrical
    effect in that capacitor's place), amplifier effects one after the other, the offset on the
    measured position.  Only ``leakage`` with ``series_resistance`` is refused (the leak attaches to
    the gap capacitor the ladder replaces): :func:`pair_problem` says why.

Examples
--------
>>> tr = truth("leakage")
>>> tr.system.state_names, tr.parameters
(['x', 'm.p', 'Q'], {'G0': 1.5e-10, 'V0': 20.0})
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import sympy as sp

from components import Damper, DriftBranch, LinearSpring, Mass, Potential, Resistor, VariableCapacitor, VoltageSource
from phs import Condition, Measured, Param, interconnect, parallel, series, symbol_of_output, symbol_of_state
from phs.component import Component, Dissipator, Piece, Relation
from phs.errors import InputDataError

EPS0 = 8.854e-12
NOMINAL = {"m": 1e-3, "k": 50.0, "b": 0.02, "eps": EPS0 * 3.0, "A": 4e-4, "g0": 1e-4, "R_s": 1e4}
# the specimen differs from the nominal defaults as a real one would; refits start from the defaults
BASE = {**NOMINAL, "k": 46.0, "b": 0.024, "eps": EPS0 * 3.0 * 1.05}
V_PULL_IN = math.sqrt(8 * BASE["k"] * BASE["g0"] ** 3 / (27 * BASE["eps"] * BASE["A"]))
C_GAP = BASE["eps"] * BASE["A"] / BASE["g0"]  # gap capacitance at rest [F]

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
    P, S = _specimen(base)
    x, C, g0 = S["x"], S["C"], P["g0"].symbol
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


def _specimen(base=None):
    """The specimen's parameters (``Param`` by name, ``base`` overriding :data:`BASE`) and the symbols
    ``S`` an effect's part receives (see :func:`_build`)."""
    vals = {**BASE, **(base or {})}
    P = {k: Param(k, vals[k], u, d) for k, u, d in [
        ("m", "kg", "mass of the movable electrode"), ("k", "N/m", "suspension stiffness"), ("b", "N*s/m", "damping"),
        ("eps", "F/m", "permittivity of the gap"), ("A", "m**2", "electrode area"), ("g0", "m", "rest gap"),
        ("R_s", "Ohm", "series resistance of the source")]}
    x, Q = symbol_of_state("x"), symbol_of_state("Q")
    eps, A, g0 = P["eps"].symbol, P["A"].symbol, P["g0"].symbol
    C = eps * A / (g0 - x)
    S = {"x": x, "Q": Q, "v": symbol_of_state("m.p") / P["m"].symbol, "C": C, "V_C": Q * (g0 - x) / (eps * A)}
    return P, S


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
    """The truth model of ``effect``, or of a pair of effects ``"A+B"`` (:func:`pair_truth`).

    Parameters
    ----------
    effect : str
        One of :data:`EFFECTS`, or two of them (not ``none``) joined by ``+``.
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
        For an unknown effect, a pair that cannot be combined or a size that is not positive.

    Examples
    --------
    >>> tr = truth("viscoelastic_creep")
    >>> tr.system.state_names
    ['x', 'm.p', 'Q', 've1.z', 've2.z']
    >>> truth("leakage+offset").system.name
    'truth_leakage_and_offset'
    """
    if "+" in effect:
        names = effect.split("+")
        if len(names) != 2:
            raise InputDataError(f"a case holds one effect or a pair 'A+B', got {effect!r}")
        return pair_truth(*names, size=size)
    if effect not in EFFECTS:
        raise InputDataError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
    if not size > 0:
        raise InputDataError(f"effect size must be positive, got {size}")
    e = _effect(effect, size)
    return Truth(effect, _build(f"truth_{effect}", e.part, e.base), e.form, e.parameters, e.applied)


@dataclass(frozen=True)
class _Effect:
    """What one effect does to the specimen: its form and parameters, ``part(S)`` (what it adds to the
    actuator, see :func:`_build`), ``applied`` (amplifier effects) and ``base`` (specimen values it changes)."""

    form: str
    parameters: dict
    part: object = None
    applied: object = None
    base: dict | None = None


def _effect(effect, size):
    return _EFFECTS[effect]({k: float(x) for k, x in SIZES[effect].items()}, float(size))


# -- pairs ---------------------------------------------------------------------------------------------------------------
AMPLIFIER_ORDER = ("input_saturation", "slew_rate_limit", "time_delay")
"""Order in which two amplifier effects act on the command: the saturation on the sampled command, the
slew limit on its (uniformly sampled) result, the delay last (it commutes with both, and the slew limiter
needs uniform samples).  Not chosen on a measurement."""


def pair_truth(first: str, second: str, size: float = 1.0) -> Truth:
    """The actuator holding two effects: both effects' parts composed into one port-Hamiltonian system.

    Components, mechanical members and parameters of the two parts are joined; an electrical effect
    in series with the gap capacitor (``charge_retention``) takes the other electrical effect in place
    of that capacitor (``leakage`` across it, ``series_resistance``'s RC ladder); an effect that
    attaches to the gap capacitor itself (``leakage``) cannot be combined with one that replaces that
    capacitor (``series_resistance``) and is refused.  Amplifier effects act through ``applied``,
    two of them one after the other in :data:`AMPLIFIER_ORDER`; ``offset`` acts on the measured
    position.  Each effect has its single-effect strength times ``size``.  The system is the same
    whichever order the two are named in.

    Parameters
    ----------
    first, second : str
        Two different effects of :data:`EFFECTS`, neither ``none``.
    size : float
        Multiplier of both effects' strengths.

    Returns
    -------
    Truth
        ``effect`` is ``"first+second"``; ``parameters`` maps each effect to its parameters.

    Raises
    ------
    InputDataError
        For an unknown effect, ``none``, the same effect twice, two effects that cannot be
        combined, or a size that is not positive (one line naming the pair).

    Examples
    --------
    >>> tr = pair_truth("leakage", "cubic_stiffness")
    >>> tr.system.state_names, sorted(tr.parameters)
    (['x', 'm.p', 'Q'], ['cubic_stiffness', 'leakage'])
    >>> pair_problem("series_resistance", "leakage")
    "cannot combine 'series_resistance' and 'leakage': leakage attaches to the gap capacitor, which series_resistance replaces"
    """
    if not size > 0:
        raise InputDataError(f"effect size must be positive, got {size} for the pair {first}+{second}")
    a, b, ea, eb, base, part = _pair_plan(first, second, size)
    system = _build(f"truth_{a}_and_{b}", part, base)
    e = {a: ea, b: eb}
    return Truth(f"{first}+{second}", system, f"{first}: {e[first].form}; {second}: {e[second].form}",
                 {first: dict(e[first].parameters), second: dict(e[second].parameters)}, _combined_applied(ea, eb, a, b))


def pair_problem(first: str, second: str) -> str | None:
    """Why two effects cannot be combined into one truth (one line), or None when they can.

    Examples
    --------
    >>> pair_problem("charge_retention", "leakage") is None, pair_problem("leakage", "leakage")
    (True, "a pair needs two different effects, got 'leakage' twice")
    """
    try:
        _pair_plan(first, second, 1.0)
    except InputDataError as err:
        return str(err)
    return None


def _pair_plan(first, second, size):
    """The two effects in :data:`EFFECTS` order, their :class:`_Effect`, the combined base values and part
    (tried on the specimen's symbols, so that a pair that cannot be combined is refused before anything
    is built)."""
    a, b = _pair_names(first, second)
    named = f"{first!r} and {second!r}"
    ea, eb = _effect(a, size), _effect(b, size)
    base = _combined_base(a, b, ea, eb, named)
    part = ea.part or eb.part
    if ea.part and eb.part:
        part = _combined_part(a, b, ea.part, eb.part, named)
        part(_specimen(base)[1])
    return a, b, ea, eb, base, part


def _pair_names(first, second):
    """The two effects in :data:`EFFECTS` order (the system does not depend on the order they are named in)."""
    for e in (first, second):
        if e not in EFFECTS:
            raise InputDataError(f"unknown effect {e!r} in the pair {first}+{second}; known: {', '.join(EFFECTS[:-1])}")
        if e == "none":
            raise InputDataError(f"'none' is no effect: a pair combines two of {', '.join(EFFECTS[:-1])}")
    if first == second:
        raise InputDataError(f"a pair needs two different effects, got {first!r} twice")
    return tuple(sorted((first, second), key=EFFECTS.index))


def _combined_base(a, b, ea, eb, named):
    base = dict(ea.base or {})
    for k, val in (eb.base or {}).items():
        if k in base and base[k] != val:
            raise InputDataError(f"cannot combine {named}: they set the specimen's {k} to {base[k]} and {val}")
        base[k] = val
    return base or None


def _combined_applied(ea, eb, a, b):
    """Both maps of the command, in :data:`AMPLIFIER_ORDER` (or the one there is)."""
    acting = sorted((name, e.applied) for name, e in ((a, ea), (b, eb)) if e.applied is not None)
    maps = [m for _, m in sorted(acting, key=lambda p: AMPLIFIER_ORDER.index(p[0]))]
    if len(maps) < 2:
        return maps[0] if maps else None
    inner, outer = maps

    def applied(t, U):
        return outer(*inner(t, U))
    return applied


def _combined_part(a, b, part_a, part_b, named):
    """``part(S)`` of the pair: both parts joined (see :func:`pair_truth`); refuses with one line naming
    the pair as ``named`` says."""

    def part(S):
        pa, pb = part_a(S), part_b(S)
        for (x, px), (y, py) in (((a, pa), (b, pb)), ((b, pb), (a, pa))):
            if "electrical_components" in px:  # x replaces the gap capacitor: y must not attach to it
                if "electrical_components" in py:
                    raise InputDataError(f"cannot combine {named}: both replace the gap capacitor")
                try:
                    (part_b if y == b else part_a)({k: S[k] for k in S if k not in ("C", "V_C")})
                except KeyError:
                    raise InputDataError(f"cannot combine {named}: {y} attaches to the gap capacitor, which {x} "
                                         "replaces") from None
        out = {"components": pa.get("components", []) + pb.get("components", []),
               "mechanical": list(pa.get("mechanical", ())) + list(pb.get("mechanical", ())),
               "params": pa.get("params", []) + pb.get("params", [])}
        for key in ("electrical_components", "position"):
            have = [p[key] for p in (pa, pb) if key in p]
            if len(have) > 1:
                raise InputDataError(f"cannot combine {named}: both set the {key.replace('_', ' ')}")
            if have:
                out[key] = have[0]
        la, lb = pa.get("electrical"), pb.get("electrical")
        if la and lb:  # one in series with the gap capacitor takes the other in its place
            outer, inner = (la, lb) if "C" in la else (lb, la) if "C" in lb else (None, None)
            if outer is None:
                raise InputDataError(f"cannot combine {named}: both change the gap capacitor's branch")
            i = outer.index("C")
            out["electrical"] = list(outer[:i]) + list(inner) + list(outer[i + 1:])
        elif la or lb:
            out["electrical"] = list(la or lb)
        names = [c.name for c in out["components"] + out.get("electrical_components", [])]
        clash = sorted(_duplicates(names) | _duplicates([q.name for q in out["params"]]))
        if clash:
            raise InputDataError(f"cannot combine {named}: both define {', '.join(clash)}")
        return out
    return part


def _duplicates(names):
    return {n for n in names if names.count(n) > 1}


def _charge_retention(v, size):
    c1, c2 = v["C1"] / size, v["C2"] / size
    r1, r2 = v["tau1"] / (c1 + C_GAP), v["tau2"] / (c2 + C_GAP)

    def part(S):
        return {"components": [DriftBranch("D1", C1=c1, R1=r1, state="D1.Q", range=(-3e-7, 3e-7)),
                               DriftBranch("D2", C1=c2, R1=r2, state="D2.Q", range=(-3e-7, 3e-7))],
                "electrical": ["D1", "D2", "C"]}
    return _Effect("two leaky dielectric layers (C_i || R_i, i = 1, 2) in series with the gap capacitor; "
                   "time constants about R_i (C_i + C_gap)", {"C1": c1, "R1": r1, "C2": c2, "R2": r2, "tau1": v["tau1"], "tau2": v["tau2"]},
                   part)


def _leakage(v, size):
    g0, v0 = v["G0"] * size, v["V0"]

    def part(S):
        G0, V0 = _p("leak.G0", g0, "S", "leakage conductance at zero voltage"), _p("leak.V0", v0, "V", "voltage scale of the growth")
        G = G0.symbol * (1 + (S["V_C"] / V0.symbol) ** 2)
        return {"components": [Resistor("leak", G=G)], "electrical": [parallel("C", "leak")], "params": [G0, V0]}
    return _Effect("conductance across the gap growing with its voltage: G = G0 (1 + (V_C/V0)^2)", {"G0": g0, "V0": v0}, part)


def _series_resistance(v, size):
    r1, r2, f = v["R1"] * size, v["R2"] * size, v["fraction"]

    def part(S):
        return {"electrical_components": [VariableCapacitor("Ca", C=f * S["C"], C_typical=1e-10, state="Q", scale=1e-8),
                                          VariableCapacitor("Cb", C=(1 - f) * S["C"], C_typical=1e-10, state="Qb", scale=1e-8),
                                          Resistor("Rf1", R=r1), Resistor("Rf2", R=r2)],
                "electrical": ["Rf1", parallel("Ca", series("Rf2", "Cb"))]}
    return _Effect("distributed electrode-film resistance: a two-section RC ladder (R1 to a fraction f of the electrode, "
                   "R1 + R2 to the rest)", {"R1": r1, "R2": r2, "fraction": f}, part)


def _coulomb_friction(v, size):
    fc, fs, vs, s0, s1 = v["Fc"] * size, v["Fs"] * size, v["vs"], v["sigma0"], v["sigma1"]

    def part(S):
        g = fc + (fs - fc) * sp.exp(-((S["v"] / vs) ** 2))
        return {"components": [LinearSpring("bristle", K=s0, state="fr.z", range=(-1e-7, 1e-7), scale=1e-8),
                               Damper("bristle_d", b=s1), _SlipDamper("slip", _sabs(S["v"], 1e-6) / g)],
                "mechanical": [parallel(series("bristle", "bristle_d"), "slip")]}
    return _Effect("LuGre-type bristle friction: bristle z (stiffness sigma0, damping sigma1) slipping at "
                   "|v| F / g(v), Stribeck curve g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2)",
                   {"Fc": fc, "Fs": fs, "vs": vs, "sigma0": s0, "sigma1": s1}, part)


def _viscoelastic_creep(v, size):
    k1, k2 = v["k1"] * size, v["k2"] * size
    e1, e2 = k1 * v["tau1"], k2 * v["tau2"]

    def part(S):
        return {"components": [LinearSpring("ve1", K=k1, state="ve1.z", range=(-5e-5, 5e-5), scale=1e-5), Damper("ve1d", b=e1),
                               LinearSpring("ve2", K=k2, state="ve2.z", range=(-5e-5, 5e-5), scale=1e-5), Damper("ve2d", b=e2)],
                "mechanical": [parallel("ve1", "ve1d"), parallel("ve2", "ve2d")]}
    return _Effect("generalized standard linear solid: two Maxwell arms (k_i in series with eta_i) beside the suspension",
                   {"k1": k1, "eta1": e1, "k2": k2, "eta2": e2, "tau1": v["tau1"], "tau2": v["tau2"]}, part)


def _cubic_stiffness(v, size):
    k3, k5 = v["k3"] * size, v["k5"] * size

    def part(S):
        K3, K5 = _p("k3", k3, "N/m**3", "cubic stiffness"), _p("k5", k5, "N/m**5", "quintic stiffness")
        x = S["x"]
        return {"components": [Potential("stiffening", K3.symbol * x**4 / 4 + K5.symbol * x**6 / 6, params=[K3, K5])]}
    return _Effect("stiffening suspension: F = k x + k3 x^3 + k5 x^5", {"k3": k3, "k5": k5}, part)


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
    return _Effect("Bouc-Wen hysteresis with n = 2 in passive Maxwell form: F_h = k_h z, "
                   "z' = v - beta |v| |z| z - gamma v z^2 (beta >= |gamma|)",
                   {"k_h": kh, "beta": beta, "gamma": gamma, "n": 2, "z_max": zmax}, part)


def _quadratic_drag(v, size):
    c = v["c"] * size

    def part(S):
        return {"components": [Damper("drag", b=c * (S["v"] ** 2 + 1e-12) ** sp.Rational(7, 20))], "mechanical": ["drag"]}
    return _Effect("power-law drag F = c |v|^1.7 sign(v) (smoothed at |v| < 1e-6 m/s) beside a weaker linear damping b",
                   {"c": c, "exponent": 1.7, "b": v["b"]}, part, base={"b": v["b"]})


def _added_mass(v, size):
    ma = v["m_a"] * size
    ka = ma * (2 * math.pi * v["f_a"]) ** 2
    ba = 2 * v["zeta_a"] * math.sqrt(ka * ma)

    def part(S):
        return {"components": [Mass("ma", m=ma, state="ma.p", scale=1e-5),
                               LinearSpring("ka", K=ka, state="ka.l", range=(-2e-5, 2e-5), scale=1e-5), Damper("ba", b=ba)],
                "mechanical": [parallel(series("ka", "ba"), "ma")]}
    return _Effect("payload mass m_a carried on a compliant mount (k_a, b_a): rigid added mass below f_a, decoupled above",
                   {"m_a": ma, "k_a": ka, "b_a": ba, "f_a": v["f_a"]}, part)


def _input_saturation(v, size):
    up, un = v["U_pos"] / math.sqrt(size), v["U_neg"] / math.sqrt(size)

    def applied(t, U):
        return t, np.where(U >= 0, up * np.tanh(U / up), un * np.tanh(U / un))
    return _Effect("asymmetric soft saturation of the amplifier: U_applied = U+ tanh(U/U+) for U >= 0, U- tanh(U/U-) below",
                   {"U_pos": up, "U_neg": un}, applied=applied)


def _slew_rate_limit(v, size):
    rate = v["S"] / size

    def applied(t, U):
        return _rate_limited(t, U, rate)
    return _Effect("the amplifier's output follows the command at most at a slew rate S (V/s)", {"S": rate}, applied=applied)


def _time_delay(v, size):
    d = v["delay"] * size

    def applied(t, U):
        return np.concatenate([[t[0]], t + d]), np.concatenate([[U[0]], U])
    return _Effect("transport delay of the applied voltage: U_applied(t) = U(t - d)", {"delay": d}, applied=applied)


def _offset(v, size):
    off, gain = v["offset"] * size, v["gain"] * size

    def part(S):
        return {"position": (1 + gain) * S["x"] + off}
    return _Effect("position sensor with an offset and a gain error: position = (1 + g) x + x_off", {"offset": off, "gain": gain},
                   part)


def _none(v, size):
    return _Effect("the nominal actuator (with the specimen's own k, b, eps)", {})


_EFFECTS = {"charge_retention": _charge_retention, "leakage": _leakage, "series_resistance": _series_resistance,
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

