"""Recordings of the electrostatic actuator whose truth holds physics the diagnosis library cannot express.

The nominal model, the specimen, the voltage programs (``steps``), the sampling (1 kHz) and the noise
(1 % of the position's range, 3 % of the current's std) are those of :mod:`examples.concealed_effects`;
the truths differ from it by an effect outside :data:`components.candidates.LIBRARY`:

fringe_field
    The gap capacitance has a fringe-field part that grows more slowly than the plate's as the gap
    closes: ``C(x) = eps A / (g0 - x) + f C_gap sqrt(g0 / (g0 - x))``.  Conservative, on the
    electrical storage ``Q`` and its coupling to ``x``.
heating_resistance
    The dielectric's leakage resistance heats with the energy it dissipates and cools to ambient, its
    conductance rising with temperature: ``G = G0 (1 + alpha T)``, ``C_th dT/dt = G V² - T / R_th``
    (``V`` the gap voltage; thermal time constant 1 s).  Dissipative with a memory (a thermal state);
    simulated as an ODE (the heat flow is not a port-Hamiltonian storage of the nominal model).  (The
    source's series resistance itself cannot show heating at 1 kHz: its RC time is 0.35 us.)
engaging_spring
    A one-sided spring (a stop) that engages part-way through the stroke:
    ``F = k_c softplus_w(x - x_c)`` with ``x_c`` = 6 um (about half the largest closure), ``w`` = 0.3 um.
    Conservative, on ``x``.
softening_stiffness
    A suspension stiffness that softens exponentially with stroke: an extra stiffness
    ``k_e exp(-|x| / x_e)`` beside the linear ``k``, energy ``k_e x_e² (exp(-|x|/x_e) - 1 + |x|/x_e)``.
    Conservative, on ``x``.
drive_gain
    The drive's gain falls with stroke: the source reaches the electrodes through a ratio
    ``κ(x) = 1 / (1 + (x / x_g)²)`` (``x_g`` = 20 um: 0.86 at the largest closure, about 8 um), a
    modulated transformer (:func:`components.candidates.maps.scale_input`), so the source current
    recorded is ``κ`` times the electrodes' current.  An input map, on ``U``, depending on ``x``.

:func:`generate` returns a :class:`phs.workflows.recording.Recording` and what the truth was, with the
noise-free channels (so a test can compute the truth's own validation-fit gain).

Examples
--------
>>> rec, info = generate("engaging_spring", seconds=1.0)
>>> rec.names, info["nature"], info["state"]
(['U', 'position', 'current'], 'conservative', 'x')
"""

from __future__ import annotations

import os
import sys

import numpy as np
import sympy as sp

from phs.errors import InputDataError

if __package__:  # imported as examples.concealed_novel
    from .concealed_effects import CHANNELS, NOISE, NOMINAL_FREE, program, simulate_truth
    from .concealed_truths import BASE, C_GAP, Truth, _build
else:  # run as a script: the modules beside this file
    if os.path.dirname(os.path.abspath(__file__)) not in sys.path:
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from concealed_effects import CHANNELS, NOISE, NOMINAL_FREE, program, simulate_truth
    from concealed_truths import BASE, C_GAP, Truth, _build

NOVEL = ("fringe_field", "heating_resistance", "engaging_spring", "softening_stiffness", "drive_gain")
"""The cases, none of which a library candidate expresses."""
SIZES = {
    "fringe_field": {"f": 0.3},
    "heating_resistance": {"G0": 1.5e-10, "alpha": 1.0, "C_th": 3.3e-8, "R_th": 3e7},
    "engaging_spring": {"k_c": 30.0, "x_c": 6e-6, "w": 3e-7},
    "softening_stiffness": {"k_e": 20.0, "x_e": 4e-6},
    "drive_gain": {"x_g": 2e-5},
}
NATURE = {"fringe_field": ("conservative", "Q"), "heating_resistance": ("dissipative", "Q"),
          "engaging_spring": ("conservative", "x"), "softening_stiffness": ("conservative", "x"), "drive_gain": ("input map", "x")}
"""What discovery should say: conservative, dissipative or an input map, and on (or, for an input map, with) which state."""
INPUT = {"drive_gain": "U"}
"""The input whose map an input-map case changes."""


def truth(effect: str, size: float = 1.0) -> Truth:
    """The truth of a novel case (``system``: the PHSystem simulated, the plain actuator for
    ``heating_resistance``, which :func:`simulate` integrates as an ODE).

    Examples
    --------
    >>> truth("softening_stiffness").parameters
    {'k_e': 20.0, 'x_e': 4e-06}
    """
    from components import Potential, VariableCapacitor
    from phs import Param

    if effect not in NOVEL:
        raise InputDataError(f"unknown case {effect!r}; known: {', '.join(NOVEL)}")
    if not size > 0:
        raise InputDataError(f"effect size must be positive, got {size}")
    v = {k: float(x) for k, x in SIZES[effect].items()}
    if effect == "fringe_field":
        f = v["f"] * size

        def part(S):
            x, g0 = S["x"], BASE["g0"]
            C = S["C"] + f * C_GAP * sp.sqrt(g0 / (g0 - x))
            return {"electrical_components": [VariableCapacitor("C", C=C, C_typical=1e-10, state="Q", scale=1e-8)]}
        return Truth(effect, _build("truth_fringe_field", part), "fringe-field capacitance: C = eps A/(g0 - x) + f C_gap sqrt(g0/(g0 - x))",
                     {"f": f})
    if effect == "heating_resistance":
        return Truth(effect, _build("truth_heating_resistance"), "leakage conductance heating with its dissipated energy: "
                     "G = G0 (1 + alpha T), C_th dT/dt = G V^2 - T/R_th", {**v, "alpha": v["alpha"] * size})
    if effect == "engaging_spring":
        kc, xc, w = v["k_c"] * size, v["x_c"], v["w"]

        def part(S):
            K = Param("k_c", kc, "N/m", "stiffness of the stop")
            sp_ = w * sp.log(1 + sp.exp((S["x"] - xc) / w))
            return {"components": [Potential("stop", K.symbol * sp_**2 / 2, params=[K])]}
        return Truth(effect, _build("truth_engaging_spring", part), "one-sided spring engaging at x_c: F = k_c softplus_w(x - x_c)",
                     {"k_c": kc, "x_c": xc, "w": w})
    if effect == "drive_gain":
        from components.candidates.maps import scale_input

        xg = v["x_g"] / size
        X = Param("x_g", xg, "m", "stroke at which the drive's gain has fallen to one half")
        base = _build("truth_drive_gain")
        x = base.states[base.state_names.index("x")].symbol
        return Truth(effect, scale_input(base, "U", 1 / (1 + (x / X.symbol) ** 2), [X], "drive_gain"),
                     "drive gain falling with stroke: U reaches the electrodes as U / (1 + (x/x_g)^2)", {"x_g": xg})
    ke, xe = v["k_e"] * size, v["x_e"]

    def part(S):
        K = Param("k_e", ke, "N/m", "stiffness near rest that fades with stroke")
        a = sp.sqrt(S["x"] ** 2 + (1e-3 * xe) ** 2)
        return {"components": [Potential("soft", K.symbol * xe**2 * (sp.exp(-a / xe) - 1 + a / xe), params=[K])]}
    return Truth(effect, _build("truth_softening_stiffness", part),
                 "stiffness softening exponentially with stroke: k + k_e exp(-|x|/x_e)", {"k_e": ke, "x_e": xe})


def _heating(tr: Truth, t, U) -> dict:
    """The heating-resistance truth integrated as an ODE (states x, p, Q, T; U linear between samples)."""
    from scipy.integrate import solve_ivp

    m, k, b, eps, A, g0, Rs = (BASE[n] for n in ("m", "k", "b", "eps", "A", "g0", "R_s"))
    G0, alpha, Cth, Rth = (tr.parameters[n] for n in ("G0", "alpha", "C_th", "R_th"))

    def rhs(tt, z):
        x, p, Q, T = z
        V = Q * (g0 - x) / (eps * A)
        i = (np.interp(tt, t, U) - V) / Rs
        G = G0 * (1 + alpha * T)
        return [p / m, -k * x - b * p / m + Q**2 / (2 * eps * A), i - G * V, (G * V * V - T / Rth) / Cth]

    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0, 0.0, 0.0], t_eval=t, method="LSODA", rtol=1e-9, atol=[1e-13, 1e-13, 1e-17, 1e-9],
                    max_step=float(t[1] - t[0]))
    x, p, Q, T = sol.y
    i = (U - Q * (g0 - x) / (eps * A)) / Rs
    return {"position": x, "current": i, "temperature": T}


def simulate(tr: Truth, t, U) -> dict:
    """Noise-free ``position`` and ``current`` of a novel truth driven by ``U`` sampled at ``t``."""
    if tr.effect == "heating_resistance":
        out = _heating(tr, t, U)
        return {ch: out[ch] for ch in CHANNELS}
    return simulate_truth(tr, t, U)


def generate(effect: str, *, seconds: float = 20.0, seed: int = 0, validation: bool = False, size: float = 1.0):
    """A noisy 1 kHz recording of a novel truth, and what the truth was.

    Returns
    -------
    (Recording, dict)
        Signals ``U``, ``position``, ``current``; ``info``: ``effect``, ``form``, ``parameters``,
        ``nature``, ``state`` and ``input`` (what discovery should name), ``noise_std``, ``clean``, ``nominal_free``.
    """
    from phs.workflows.recording import Recording

    tr = truth(effect, size)
    t, U = program("none", seconds, validation)
    clean = simulate(tr, t, U)
    scale = {"position": float(np.ptp(clean["position"])), "current": float(np.std(clean["current"]))}
    noise_std = {ch: NOISE[ch] * scale[ch] for ch in CHANNELS}
    rng = np.random.default_rng([100 + NOVEL.index(effect), int(seed), int(bool(validation))])
    noisy = {ch: clean[ch] + noise_std[ch] * rng.standard_normal(len(t)) for ch in CHANNELS}
    split = "validation" if validation else "train"
    rec = Recording.from_arrays(t, {"U": U, **noisy}, source=f"concealed_novel:{effect}:{split}",
                                units={"U": "V", "position": "m", "current": "A"}, holds={"U": "linear"})
    nature, state = NATURE[effect]
    return rec, {"effect": effect, "form": tr.form, "parameters": dict(tr.parameters), "nature": nature, "state": state,
                 "input": INPUT.get(effect, ""),
                 "noise_std": noise_std, "clean": clean, "nominal_free": list(NOMINAL_FREE), "seed": int(seed),
                 "seconds": float(seconds), "validation": bool(validation)}


def truth_gain(nominal_validation_rss: float, validation, clean: dict, mask=None) -> float:
    """Validation residual of the nominal refit minus the noise-free truth's own, in the diagnosis'
    units (sum over channels of RSS over the channel's variance): the most any correction can gain.

    Examples
    --------
    >>> import numpy as np
    >>> rec = {"position": np.array([0.0, 1.0]), "current": np.array([1.0, 0.0])}
    >>> truth_gain(3.0, rec, rec)
    3.0
    """
    rss = 0.0
    for ch in CHANNELS:
        y = np.asarray(validation[ch], float)
        c = np.asarray(clean[ch], float)
        if mask is not None:
            y, c = y[mask], c[mask]
        rss += float(np.sum((y - c) ** 2)) / (float(np.var(y)) or 1.0)
    return float(nominal_validation_rss - rss)


__test__ = {"truth": truth}
