"""Dictionary families that add states: a second mechanical mode, a slow drift, a limit at an electrical port.

Each family is one :class:`~phs.workflows.diagnose.discover.dictionary.Term` kind whose model is built
with a building block of :mod:`components.candidates.maps`, passive by construction:

``mode``
    A second mass ``μ m`` joined to a body (momentum ``p``) by a spring and a damper
    (:func:`components.candidates.maps.add_mode`): two new states, the mode's deflection and momentum.
    The coefficient is the mass ratio ``μ ≥ 0`` (``μ → 0`` removes the mode); its natural frequency and
    damping ratio are fitted with it (log-scaled).  The dictionary holds one mode per body at each of
    :data:`MODE_POINTS` frequencies spaced evenly in ``log f`` between ten periods per recording and a
    fifth of the sampling rate; each fit frees its frequency over :data:`MODE_SPAN` either side.
``drift``
    A slow state ``s`` relaxing from 0 towards 1 in ``τ`` (:func:`components.candidates.maps.add_clock`)
    that scales a parameter: an added stiffness ``θ s E_s z²/2`` on a displacement or charge (a spring
    softening as it heats, a dielectric ageing), an added dissipation ``θ s R_s`` on a momentum or charge
    (``θ ≥ 0``), or an input's gain ``1 + θ s`` (a drive weakening).  ``τ`` is fitted with ``θ``
    (log-scaled, :data:`DRIFT_TAU` of the recording's length, and never shorter than :data:`DRIFT_SLOWER`
    times the fitted model's slowest decay, :func:`slowest_decay`: a faster drift is the shape of the
    model's own start transient; a recording shorter than that floor gets no drift); ``θ = 0`` removes
    the drift.
``limit``
    A limit on the flow through an electrical effort input (a drive's current limit,
    :func:`components.candidates.maps.limit_input_current`): ``i = I tanh(e/e_k)`` through an element in
    series with the source, ``I = i_s/θ`` with ``i_s`` the typical flow along the fit; ``θ → 0`` removes
    it.  A limit acts only where the flow reaches it, so its first-order screen cannot rank it: the
    forward selection always fits the best one (as it does a heated dissipation) from ``θ`` =
    :data:`LIMIT_START`.

Examples
--------
>>> from systems.electrostatic_actuator import electrostatic_actuator
>>> from components.candidates import Scales
>>> from phs.workflows.diagnose.discover.dictionary import Term
>>> s = electrostatic_actuator()
>>> sorted({t.kind for t in added_terms(s, Scales.of(s), kinds=KINDS, make=Term)})
['drift', 'limit', 'mode']
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp

from components.candidates import charge_states, displacement_states, momentum_states
from components.candidates.base import _unit_of
from components.candidates.maps import add_clock, add_mode, limit_input_current, scale_input
from phs.errors import PHSError
from phs.params import Param, StateInfo

KINDS = ("mode", "drift", "limit")
"""The term kinds of this module."""
DEFAULT_KINDS = ("mode", "drift")
"""The kinds discovery's dictionary holds unless asked for others: the mode and the drift.  Each family
is built, passive and checked against an independent integration of its physics
(``tests/workflows/test_discover_families.py``).  On the 20 s recordings of
:mod:`examples.concealed_outside` (``python bench/discover.py --only outside --cases
flexible_mode,current_limit,stiffness_drift,second_mode --seconds 20``; truths integrated by scipy) the
concealed 38 Hz appendage was named a mode at 38 Hz of mass ratio 0.106 (truth 0.1, damping ratio 0.01 as
the truth's), beside two small terms, and the drifting stiffness a drift of ``x``'s stiffness by 9.2 N/m
in 8.1 s (truth 9.2 N/m in 8 s), each recovering the truth's whole validation gain; the current limit was
taken by the library's slew-rate limit (0.78 of the gain) and the heavy second mode by the added mass
(1.00), so discovery did not run there.  A drift is kept slower than :data:`DRIFT_SLOWER` times the
model's own slowest decay: before that floor, on the 0.37 s Silverbox window a drift with ``τ`` = 0.034 s
stood for the start's transient and the verdict became ``discovered`` instead of ``cubic_stiffness``.
The port limit stays out: discovery alone on the nominal fit of the current-limit case (``--alone``)
spent 841 s (under load) and found nothing (the limit's fits did not lower BIC and the validation
residual enough), so it has recovered nothing on any case yet."""
DRIFT_SLOWER = 10.0
"""A drift's shortest time constant in units of the fitted model's slowest decay ``τ_m``
(:func:`slowest_decay`): when the model's own transient has fallen to ``e⁻³`` (5 %), a drift that slow
has run less than ``1 − e^(−0.3)`` = 26 % of its course, so the fit cannot trade one for the other; a
recording shorter than ``DRIFT_SLOWER τ_m`` gets no drift.  Chosen by that bound, not on a measurement."""
MODE_POINTS = 5
"""Frequencies at which the dictionary places a mode on each body.  Five points over the band of a 20 s,
1 kHz recording (0.5–200 Hz) are a factor 4.5 apart: each fit frees its frequency over :data:`MODE_SPAN`,
so neighbouring ranges overlap.  Not chosen on a measurement."""
MODE_SPAN = 4.0
"""Factor either side of its dictionary frequency over which a mode's frequency is fitted.  Not chosen on a measurement."""
MODE_ZETA = (0.005, 1.0, 0.05)
"""Range and start of a mode's damping ratio: from a lightly damped metal part to critical damping.
Not chosen on a measurement."""
DRIFT_TAU = (0.05, 20.0, 0.3)
"""Range and start of a drift's time constant, as shares of the recording's length: from a twentieth (a
drift that settles early is a changed constant, which the nominal refit absorbs) to twenty lengths (a
straight-line drift).  Not chosen on a measurement."""
CLOCK_ENERGY = 1e4
"""The drift clock's energy scale over the typical energy of the term it scales: the clock's own rate
``(1 − s)/τ`` then differs from its course with the coupling by at most ``|θ|/(2·10⁴)``.  Chosen by
that bound, not on a measurement."""
CLOCK_SMOOTH = 1e-6
"""``ε²`` of ``√(s² + ε²)``, the clock's magnitude a drifting dissipation is scaled by (``R ⪰ 0`` over the
clock's whole declared range, which reaches slightly below 0); a numerical floor, not a measurement."""
KNEE = 0.02
"""The limit's knee voltage ``e_k`` as a share of the input's typical level: below the limit the element
is a resistance ``e_k/I`` (at ``I`` equal to the typical flow, 2 % of the input's level over its flow).
A knee of 1e-3 made the limit so sharp that the integrator failed at its corners on the electrostatic
actuator (a 6 s recording, three of three fits); not otherwise chosen on a measurement."""
LIMIT_FAST = 0.01
"""The charge the capacitance across the limit element holds at the input's typical level, in units of
the limit's flow times the sampling step: ``C = LIMIT_FAST · I dt / u_s``.  The flow that bypasses the
limit through it while the voltage across it swings by the input's level is then the limit for a
hundredth of a sample; below the limit the element follows the flow in ``C e_k / I`` = 2e-4 samples.
Chosen by that bound, not on a measurement: with the capacitance sized on the knee instead of the level
the bypass let an RC circuit's current exceed its limit by 16 %."""
LIMIT_START = 1.0
"""Coefficient a limit's fit starts at: the limit at the typical flow along the fit.  Not chosen on a measurement."""


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)


def slowest_decay(system, trajectory=None) -> float:
    """The slowest decay time ``1/min |Re λ|`` [s] over the decaying poles ``λ`` of ``system``
    linearised at the mean of ``trajectory`` (``{state: array}``; other states at rest, inputs at 0):
    ``0.0`` when no pole decays, ``inf`` when the model cannot be linearised there.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> round(slowest_decay(mass_spring_damper()), 6)   # poles -0.2 ± 1.99j
    5.0
    """
    from codegen.linearize import linearize

    x_eq = {n: float(np.mean(v)) for n, v in (trajectory or {}).items() if n in system.state_names and np.size(v)}
    try:
        poles = np.asarray(linearize(system, x_eq=x_eq or None).poles())
    except (PHSError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return math.inf
    if not poles.size or not np.all(np.isfinite(poles)):
        return math.inf if poles.size else 0.0
    rate = -poles.real[poles.real < -1e-12 * max(1.0, float(np.max(np.abs(poles))))]
    return float(1.0 / np.min(rate)) if rate.size else 0.0


def added_terms(system, scales, span=None, kinds=None, *, make, trajectory=None) -> list:
    """The ``mode``, ``drift`` and ``limit`` terms of ``system`` (see the module).

    Parameters
    ----------
    system : PHSystem
    scales : components.candidates.Scales
    span : callable, optional
        ``span(state) -> (largest |q|, max q, min q)`` along the fit (default: the scales' levels).
    kinds : sequence of str, optional
        The kinds to build (default :data:`DEFAULT_KINDS`).
    make : type
        The term class (:class:`~phs.workflows.diagnose.discover.dictionary.Term`).
    trajectory : dict of str -> array, optional
        States along the fit, where the model's slowest decay is taken (:func:`slowest_decay`): a drift's
        time constant is at least :data:`DRIFT_SLOWER` times it (kept in the drift's ``c``), and there is
        no drift when that exceeds the recording.
    """
    Term = make
    kinds = DEFAULT_KINDS if kinds is None else tuple(kinds)
    span = span or (lambda q: (scales.get("level", q, 1.0),) * 3)
    terms = []
    duration, dt = float(scales.duration), float(scales.dt)
    f_lo, f_hi = 10.0 / duration, 0.2 / dt
    freqs = np.geomspace(f_lo, f_hi, MODE_POINTS) if f_hi > f_lo and "mode" in kinds else np.array([])
    disp, charges, momenta = displacement_states(system), charge_states(system), momentum_states(system)
    for p in momenta:
        v_s = scales.get("coenergy", p, 1.0)
        m_s = scales.get("level", p, 1.0) / v_s
        terms.extend(Term("mode", p, "mode", c=float(f), q_s=float(v_s / (2 * math.pi * f)), v_s=v_s, amplitude=m_s) for f in freqs)
    slowest = slowest_decay(system, trajectory) if "drift" in kinds else 0.0
    tau, floor = DRIFT_TAU[2] * duration, max(DRIFT_TAU[0] * duration, DRIFT_SLOWER * slowest)
    if "drift" not in kinds or not floor <= duration:
        disp = charges = momenta = []
    for q in disp + charges:
        q_s = span(q)[0]
        E_s = scales.get("coenergy", q, 1.0) * q_s
        terms.append(Term("drift", q, "drift_stiffness", c=floor, q_s=q_s, amplitude=E_s, signed=True, tau=tau))
    for s in momenta + charges:
        e_s = scales.get("coenergy", s, 1.0)
        R_s = scales.get("rate", s, 1.0) / e_s
        terms.append(Term("drift", s, "drift_damping", c=floor, v_s=e_s, amplitude=R_s, tau=tau))
    typical = max([scales.get("coenergy", q, 0.0) * scales.get("level", q, 0.0) for q in system.state_names] + [0.0]) or 1.0
    for u in system.input_names if "drift" in kinds and floor <= duration else ():
        terms.append(Term("drift", u, "drift_gain", c=floor, amplitude=typical, signed=True, tau=tau))
    for j, inp in enumerate(system.inputs):
        if inp.kind != "effort" or inp.unit != "V" or "limit" not in kinds:
            continue
        flow = max([scales.get("rate", system.state_names[k], 0.0) for k in range(len(system.states))
                    if system.G[k, j] != 0 or system.P[k, j] != 0] + [0.0]) or 1.0
        terms.append(Term("limit", inp.name, "current_limit", v_s=scales.get("level", inp.name, 1.0), amplitude=flow, tau=dt))
    return terms


def label(t) -> str:
    """A term's label: ``m.p:mode@25.3Hz``, ``k.l:drift_stiffness``, ``U:current_limit``."""
    return f"{t.state}:mode@{t.c:.3g}Hz" if t.kind == "mode" else f"{t.state}:{t.shape}"


def _base(t) -> str:
    return t.parameter.split(".theta_", 1)[1]


def _effect(t) -> str:
    return t.parameter.split(".", 1)[0]


def parameters(t) -> list[str]:
    """The term's fitted parameters: its coefficient, then a mode's frequency and damping ratio or a
    drift's time constant (the ones :func:`log_parameters` lists)."""
    return [t.parameter, *log_parameters(t)]


def log_parameters(t) -> list[str]:
    """The parameters fitted on a log scale: a mode's frequency and damping ratio, a drift's time constant."""
    e, b = _effect(t), _base(t)
    if t.kind == "mode":
        return [f"{e}.freq_{b}", f"{e}.zeta_{b}"]
    if t.kind == "drift":
        return [f"{e}.tau_{b}"]
    return []


def states(t) -> list[str]:
    """Names of the states the term appends, in order."""
    e, b = _effect(t), _base(t)
    if t.kind == "mode":
        return [f"{e}.mode_{b}.delta", f"{e}.mode_{b}.w"]
    if t.kind == "drift":
        return [f"{e}.clock_{b}"]
    return [f"{e}.limit_{b}.Q"]


def fit_start(t, first_order: float) -> float:
    """The coefficient a forward step's fit of ``t`` starts at, given its first-order coefficient."""
    return LIMIT_START if t.kind == "limit" else float(np.clip(first_order, -1.0, 1.0))


def params(t, start: dict) -> list[Param]:
    """The term's fitted parameters at ``start`` (moved inside their ranges)."""
    lo, hi = t.bounds()

    def at(name, default, rng):
        return float(min(max(start.get(name, default), rng[0]), rng[1]))

    main = Param(t.parameter, at(t.parameter, 0.0 if t.signed else lo, (lo, hi)), "1",
                 f"coefficient of {t.label} (in units of its scale)", (lo, hi), positive=lo > 0)
    extra = log_parameters(t)
    if t.kind == "mode":
        f_rng = (t.c / MODE_SPAN, t.c * MODE_SPAN)
        z_lo, z_hi, z0 = MODE_ZETA
        return [main,
                Param(extra[0], at(extra[0], t.c, f_rng), "Hz", f"natural frequency of the mode on {t.state}", f_rng, positive=True),
                Param(extra[1], at(extra[1], z0, (z_lo, z_hi)), "1", f"damping ratio of the mode on {t.state}", (z_lo, z_hi),
                      positive=True)]
    if t.kind == "drift":
        T = t.tau / DRIFT_TAU[2]  # the recording's length
        rng = (max(DRIFT_TAU[0] * T, t.c), DRIFT_TAU[1] * T)
        return [main, Param(extra[0], at(extra[0], t.tau, rng), "s", f"time constant of the drift of {t.state}", rng, positive=True)]
    return [main]


def scales(t, system) -> list[Param]:
    """The fixed scale parameters the term reads (shared by name with the other terms on the same state)."""
    e, slug = _effect(t), _slug(t.state)
    if t.kind == "mode":
        unit = _unit_of(system, t.state)
        return [Param(f"{e}.{slug}_mass", t.amplitude, f"({unit})**2/J", f"typical mass of the body of {t.state} (momentum over velocity)")]
    if t.kind == "limit":
        inp = system.inputs[system.input_names.index(t.state)]
        return [Param(f"{e}.{slug}_flow", t.amplitude, inp.output_unit, f"typical flow through input {t.state} along the fit"),
                Param(f"{e}.{slug}_knee", KNEE * t.v_s, inp.unit, f"knee of the limit at input {t.state}"),
                Param(f"{e}.{slug}_step", t.tau, "s", "sampling step")]
    out = [Param(f"{e}.{_base(t)}_clock_energy", CLOCK_ENERGY * t.amplitude, "J", f"energy scale of the drift clock of {t.label}")]
    if t.shape == "drift_stiffness":
        unit = _unit_of(system, t.state)
        out += [Param(f"{e}.{slug}_scale", t.q_s, unit, f"largest |{t.state}| along the fit"),
                Param(f"{e}.{slug}_energy", t.amplitude, "J", f"typical energy of {t.state} along the fit")]
    elif t.shape == "drift_damping":
        unit = _unit_of(system, t.state)
        out += [Param(f"{e}.{slug}_damping", t.amplitude, f"({unit})**2/(J*s)",
                      f"typical dissipation coefficient of {t.state} (its rate over its effort)")]
    return out


def state_infos(t, system) -> list[StateInfo]:
    """The states the term appends (names from :func:`states`), with their units, ranges and scales."""
    e = _effect(t)
    names = states(t)
    if t.kind == "mode":
        unit = _unit_of(system, t.state)
        p_s = t.amplitude * t.v_s
        return [StateInfo(names[0], f"J*s/({unit})", (-1e4 * t.q_s, 1e4 * t.q_s), f"deflection of the mode on {t.state}", "C", t.q_s, e),
                StateInfo(names[1], unit, (-1e4 * p_s, 1e4 * p_s), f"momentum of the mode on {t.state} per unit mass ratio", "I", p_s, e)]
    if t.kind == "limit":
        inp = system.inputs[system.input_names.index(t.state)]
        q_s = LIMIT_FAST * t.tau * t.amplitude
        return [StateInfo(names[0], f"({inp.output_unit})*s", (-1e12 * q_s, 1e12 * q_s), f"charge across the limit at input {t.state}",
                          "C", q_s, e)]
    return [StateInfo(names[0], "1", (-0.05, 1.05), f"drift clock of {t.label} (0 at the start, 1 once drifted)", "C", 1.0, e)]


def attach(t, system, own: list, sym: dict, new: list):
    """``system`` with ``t`` attached: ``own`` its parameters (:func:`params`), ``sym`` the scale symbols
    by name, ``new`` the parameters the new system declares."""
    e, slug, b = _effect(t), _slug(t.state), _base(t)
    label = f"{e}@{t.label}"
    added = state_infos(t, system)
    theta = own[0].symbol
    if t.kind == "mode":
        return add_mode(system, t.state, theta, own[1].symbol, own[2].symbol, sym[f"{e}.{slug}_mass"], *added, new, e, label)
    if t.kind == "limit":
        flow, knee, step = (sym[f"{e}.{slug}_{k}"] for k in ("flow", "knee", "step"))
        limit = flow / theta
        return limit_input_current(system, t.state, limit, knee, LIMIT_FAST * KNEE * step * limit / knee, added[0], new, e)
    s = add_clock(system, added[0], own[1].symbol, sym[f"{e}.{b}_clock_energy"], new, e, f"{label}:clock")
    c = added[0].symbol
    if t.shape == "drift_stiffness":
        from components.candidates import add_energy

        z = system.states[system.state_names.index(t.state)].symbol / sym[f"{e}.{slug}_scale"]
        return add_energy(s, label, theta * c * sym[f"{e}.{slug}_energy"] * z**2 / 2, [], e)
    if t.shape == "drift_damping":
        from components.candidates.base import _add_damping

        coef = theta * sym[f"{e}.{slug}_damping"] * sp.sqrt(c**2 + sp.Float(CLOCK_SMOOTH))
        return _add_damping(s, s.state_names.index(t.state), coef, label, [], e)
    return scale_input(s, t.state, 1 + theta * c, [], e)


def words(t, system, values: dict) -> str:
    """What the term means, with its fitted sizes."""
    theta = float(values.get(t.parameter, 0.0))
    extra = [float(values.get(n, 0.0)) for n in log_parameters(t)]
    if t.kind == "mode":
        f, z = extra
        return (f"a second mass ({100 * theta:.3g} % of the body's) joined to {t.state} by a spring and a damper: a mode at "
                f"{f:.3g} Hz with damping ratio {z:.2g}")
    if t.kind == "limit":
        inp = system.inputs[system.input_names.index(t.state)]
        limit = t.amplitude / theta if theta > 0 else math.inf
        return (f"a limit of {limit:.3g} {inp.output_unit} on the flow through input {t.state} (a drive's current limit: "
                "a nonlinear resistance in series with the source)")
    tau = extra[0]
    verb = "rising" if theta > 0 else "falling"
    unit = _unit_of(system, t.state) if t.shape != "drift_gain" else ""
    size = {"drift_stiffness": f"{abs(theta) * t.amplitude / t.q_s**2:.3g} J/({unit})**2",
            "drift_damping": f"{abs(theta) * t.amplitude:.3g} ({unit})**2/(J*s)", "drift_gain": f"{100 * abs(theta):.3g} %"}[t.shape]
    what = {"drift_stiffness": f"the stiffness of {t.state}", "drift_damping": f"the dissipation coefficient on {t.state}",
            "drift_gain": f"the gain of input {t.state}"}[t.shape]
    return (f"{what} drifting during the recording, {verb} by {size} with time constant τ ≈ {tau:.3g} s "
            "(a slow state of its own: heating, fatigue or ageing)")


def retuned(t, frequency: float):
    """The mode term ``t`` placed at ``frequency`` [Hz] (its label, parameters and deflection scale with it)."""
    from dataclasses import replace

    return replace(t, c=float(frequency), q_s=float(t.v_s / (2 * math.pi * float(frequency))))


def refine_mode(t, share) -> tuple:
    """The frequency of the mode term ``t`` that maximises ``share(term)`` (its first-order share of the
    residual, :func:`~phs.workflows.diagnose.discover.selection.screen`) within ``√MODE_SPAN`` of its
    dictionary frequency (a bounded search in ``log f`` to within 3 %, at most ten evaluations), as
    ``(term, share)``.

    The dictionary's frequencies are a factor of several apart; a fit of a few evaluations cannot move a
    mode's frequency that far (a mode's output changes sharply with its frequency), so it starts from
    the frequency its screen prefers.  On a concealed 110 Hz mode (6 s electrostatic-actuator recording)
    the fits from the grid's 60 and 200 Hz were rejected, from the refined 118 and 243 Hz one was kept."""
    from scipy.optimize import minimize_scalar

    ratio = MODE_SPAN**0.5
    seen = {}

    def cost(logf):
        cand = retuned(t, math.exp(logf))
        seen[cand] = share(cand)
        return -seen[cand]

    minimize_scalar(cost, bounds=(math.log(t.c / ratio), math.log(t.c * ratio)), method="bounded", options={"xatol": 0.03, "maxiter": 10})
    best = max(seen, key=seen.get) if seen else t
    return best, seen.get(best, 0.0)
