"""The dictionary of passive corrections a model may lack, built from the model itself.

Every term is one shape on one state of the fitted model, scaled by that state's range along the fit
(``z = q / q_s``, ``q_s`` the largest ``|q|`` reached), with one dimensionless coefficient ``theta``:

``energy``
    ``H += theta · E_s · phi(z)``: an added storage on one state (or, for a multi-port storage, the
    stored electrical energy ``(Q/Q_s)² z^k`` modulated by a displacement).  Its force comes from
    the gradient through the model's own ``J``: no energy is created.  Shapes that grow faster than
    ``z²`` (``z⁴``, ``z⁶``, ``|z|³``, one-sided engaging springs) take ``theta ≥ 0`` only, so the
    added energy is itself bounded below; bounded or slower shapes (``log cosh``, the Gaussian well)
    and the modulated electrical energy may take either sign, and the augmented model's ``H`` is
    checked to be bounded below over the declared state box before it is kept.
``damping``
    ``R[i, i] += theta · R_s · psi(·)`` with ``theta ≥ 0`` and ``psi ≥ 0`` (``|e|``, ``e²`` of the
    state's own effort, ``z²``, ``|z|`` of a displacement): ``R`` stays positive semi-definite, the
    added dissipated power ``e² R`` is nonnegative — passive by construction.

``memory``
    A dissipation with a memory: ``R[i, i] += theta · R_s`` on a momentum or charge whose conductance
    rises with the heat it releases, held in one new state ``z`` (``ż = G e² − z/τ``,
    ``G = theta R_s (1 + s z / E)``; :func:`components.candidates.maps.add_heated_dissipation`: a
    power-conserving coupling into a storage of its own, passive by construction).  Its sensitivity ``s``
    and time constant ``τ`` are fitted with it (log-scaled).
``input``
    A state-dependent gain of an input, ``u → (1 + theta φ(x)) u`` with ``φ`` = ``x²``, ``|x|``, ``x`` of
    a displacement or charge (scaled): a modulated transformer at the port
    (:func:`components.candidates.maps.scale_input`), so the conjugate output changes with it and
    ``yᵀu`` stays the power the model receives; ``theta`` in [-0.9, 3].
``sensor``
    A measured output that reads one state (``position = x``) reading it nonlinearly:
    ``y_m + theta · y_s · φ(x)``, ``φ`` = ``x²``, ``x³`` (:func:`components.candidates.maps.correct_measured`):
    the sensor, not a power port.  Outputs that are port outputs or mix states (the source current)
    get none: a correction there could stand in for any missing current.

``mode``, ``drift``, ``limit``
    Terms that append states (:mod:`~phs.workflows.diagnose.discover.families`): a second mass joined to
    a body by a spring and a damper, a slow clock state that scales a stiffness, a dissipation or an
    input's gain, and a limit on the flow through an electrical input.

``E_s`` (typical co-energy times ``q_s``) and ``R_s`` (typical rate over typical effort) make
``theta ~ 1`` an effect of the size of the model's own terms, so every coefficient shares one range.

:class:`Discovered` is a :class:`components.candidates.Candidate` holding a selection of terms: it
attaches them the way every candidate does, so discovered corrections are fitted, scored and checked by
the same machinery as the library.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> from components.candidates import Scales
>>> s = mass_spring_damper()
>>> terms = dictionary(s, Scales.of(s), outputs=["position"])
>>> sorted({t.kind for t in terms}), terms[0].label
(['damping', 'energy', 'input', 'memory', 'mode', 'sensor'], 'k.l:quartic')
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from components.candidates import (
    Augmentation,
    Candidate,
    add_energy,
    charge_states,
    displacement_states,
    momentum_states,
)
from components.candidates.base import _add_damping, _rebuild, _unit_of
from components.candidates.maps import add_heated_dissipation, correct_measured, scale_input
from phs.params import Param, StateInfo
from phs.system import PHSystem, assembling
from phs.workflows.diagnose.discover.families import (
    KINDS,
    _slug,
    added_terms,
    attach,
    fit_start,
    label,
    log_parameters,
    parameters,
    params,
    scales,
    states,
    words,
)

EFFECT = "discovered"
THETA_MAX = 30.0
"""Largest coefficient (in units of the state's own scale) a dictionary term may take.  Not chosen on a measurement."""
THETA_MIN = 1e-9
"""Smallest nonnegative coefficient: zero itself is refused for parameters declared positive.
A numerical floor, not a measurement."""
WIDTH = 0.05
"""Width (in ``z``) over which a one-sided spring engages (softplus smoothing).  Not chosen on a measurement."""
ENGAGE_AT = (0.3, 0.45, 0.6, 0.75)
"""Where one-sided springs engage, as shares of the largest deflection reached on each side.
Not chosen on a measurement."""


Z, C, E, X = sp.symbols("z c e x", real=True)
"""Placeholders of the shapes: the scaled state ``z``, the engaging point ``c``, the scaled effort ``e``
and the scaled displacement ``x`` that modulates a dissipation."""


def _softplus(u):
    return WIDTH * sp.log(1 + sp.exp(u / WIDTH))


def _sabs(u):
    return sp.sqrt(u**2 + sp.Float(1e-6))


# energy shapes: (phi(z, c), sign, words for a positive coefficient, words for a negative one)
_ENERGY = {
    "quartic": (Z**4 / 4, "nonnegative", "a stiffness that rises with the square of the deflection (hardening, quartic energy)", ""),
    "sextic": (Z**6 / 6, "nonnegative", "a stiffness that rises steeply at large deflection (sextic energy)", ""),
    "abs_cubic": ((_sabs(Z) ** 3 - sp.Float(1e-9)) / 3, "nonnegative", "a stiffness that rises in proportion to |deflection|", ""),
    "log_cosh": (sp.log(sp.cosh(2 * Z)) / 4, "signed",
                 "an extra stiffness near rest that softens exponentially with stroke (sech², a saturating spring force)",
                 "a stiffness lowered near rest that recovers exponentially with stroke (sech²)"),
    "gauss": ((1 - sp.exp(-2 * Z**2)) / 4, "signed",
              "an extra stiffness near rest that fades exponentially with stroke (a Gaussian energy well)",
              "a stiffness lowered near rest that recovers exponentially with stroke (a Gaussian energy hill)"),
    "engage_up": (_softplus(Z - C) ** 2 / 2, "nonnegative", "a one-sided spring that engages when {state} exceeds {at}", ""),
    "engage_down": (_softplus(C - Z) ** 2 / 2, "nonnegative", "a one-sided spring that engages when {state} falls below {at}", ""),
    "quadratic": (Z**2 / 2, "signed", "an added series elastance of {state} (a quadratic energy: a capacitance in series)",
                  "a capacitance in parallel with {state} (a negative quadratic energy)"),
    "charge_z": (Z**2 * X / 2, "signed", "a stored energy of {state} that grows with {via} (its capacitance falls as {via} grows)",
                 "a stored energy of {state} that falls as {via} grows (its capacitance grows with {via})"),
    "charge_z2": (Z**2 * X**2 / 2, "signed", "a stored energy of {state} that grows with {via}² (capacitance falling away from {via} = 0)",
                  "a stored energy of {state} that falls with {via}² (its capacitance grows away from {via} = 0)"),
}
# dissipation shapes psi(e, x) >= 0 and their words
_DAMPING = {
    "abs_effort": (_sabs(E), "a dissipation on {state} that rises with its effort (|∂H/∂{state}|)"),
    "square_effort": (E**2, "a dissipation on {state} that rises with the square of its effort ((∂H/∂{state})²)"),
    "square_position": (X**2, "a dissipation on {state} that rises with the square of {via}"),
    "abs_position": (_sabs(X), "a dissipation on {state} that rises with |{via}|"),
}


# input-gain shapes phi(x) (the gain is 1 + theta phi), sensor-reading shapes (the reading gains theta y_s phi)
_GAIN = {
    "gain_square": (X**2, "{via}²"),
    "gain_abs": (_sabs(X), "|{via}|"),
    "gain_linear": (X, "{via}"),
}
_READING = {
    "reading_square": (X**2, "{via}²"),
    "reading_cube": (X**3, "{via}³"),
}
GAIN_BOUNDS = (-0.9, 3.0)
"""Range of an input-gain coefficient (the gain ``1 + θ φ`` stays positive over the fitted range, ``|φ| ≤ 1``).
Chosen by that positivity, not on a measurement: ``1 + θ φ ≥ 0.1`` holds for ``0 ≤ φ ≤ 1`` (the square and
magnitude shapes); the linear shape with ``φ < 0`` and ``θ > 1`` is not covered."""
SENSITIVITY = (1e-4, 1e6, 1.0)
"""Range and start of a heat state's sensitivity ``s`` (the conductance's relative rise per typical heat).
Not chosen on a measurement."""
TAU_SPAN = (1 / 50, 100.0)
"""Range of a heat state's time constant, as factors of its start (a tenth of the recording, within 20
samples and 2 s).  Not chosen on a measurement."""


def shape(term) -> sp.Expr:
    """The shape of ``term`` in the placeholders :data:`Z`, :data:`C`, :data:`E`, :data:`X` (1 for a
    heated dissipation: a constant conductance before it heats)."""
    table = {"energy": _ENERGY, "damping": _DAMPING, "input": _GAIN, "sensor": _READING}.get(term.kind)
    return table[term.shape][0] if table else sp.Integer(1)


@dataclass(frozen=True)
class Term:
    """One dictionary term: ``kind`` (``energy``, ``damping``, ``memory``: a dissipation with its own heat
    state, ``input``: a state-dependent input gain, ``sensor``: a correction of a measured output, and the
    families ``mode``, ``drift``, ``limit``), the ``state`` it acts on (for ``input`` the input's name, for
    ``sensor`` the measured output's), the ``shape``, the state ``via`` that modulates it (or ""), the
    engaging point ``c`` (in ``z``; a mode's dictionary frequency [Hz], a drift's shortest time constant
    [s]), the scales (``q_s`` of ``state`` or of ``via``, ``v_s`` of ``via`` or of the effort,
    ``amplitude``: ``E_s``, ``R_s`` or the output's level ``y_s``), the heat state's starting time constant
    ``tau`` and whether its coefficient is ``signed``."""

    kind: str
    state: str
    shape: str
    via: str = ""
    c: float = 0.0
    q_s: float = 1.0
    v_s: float = 1.0
    amplitude: float = 1.0
    signed: bool = False
    tau: float = 0.0

    @property
    def label(self) -> str:
        if self.kind in KINDS:
            return label(self)
        tail = f"@{self.c:+.2f}" if self.shape.startswith("engage") else ""
        return f"{self.state}:{self.shape}" + (f"({self.via})" if self.via else "") + tail

    @property
    def parameter(self) -> str:
        """Name of the coefficient: ``discovered.theta_<state>_<shape>...`` (C-safe)."""
        raw = self.label.replace("@", "_at_").replace("+", "p").replace("-", "m").replace(".", "_")
        return f"{EFFECT}.theta_" + "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in raw).strip("_")

    @property
    def parameters(self) -> list[str]:
        """Every coefficient the term fits: :attr:`parameter`, and for a heated dissipation its heat
        state's sensitivity and time constant."""
        if self.kind in KINDS:
            return parameters(self)
        if self.kind != "memory":
            return [self.parameter]
        slug = _slug(self.state)
        return [self.parameter, f"{EFFECT}.sensitivity_{slug}", f"{EFFECT}.tau_{slug}"]

    @property
    def heat_state(self) -> str:
        """Name of the heat state a ``memory`` term adds."""
        return f"{EFFECT}.heat_{_slug(self.state)}"

    @property
    def log_parameters(self) -> list[str]:
        """The parameters fitted on a log scale (a heated dissipation's sensitivity and time constant, a
        mode's frequency and damping ratio, a drift's time constant)."""
        if self.kind in KINDS:
            return log_parameters(self)
        return self.parameters[1:] if self.kind == "memory" else []

    @property
    def new_states(self) -> list[str]:
        """The states the term appends to the model (each starts at 0)."""
        if self.kind in KINDS:
            return states(self)
        return [self.heat_state] if self.kind == "memory" else []

    def fit_start(self, first_order: float) -> float:
        """The coefficient a forward step's fit starts at, given the term's first-order coefficient."""
        return fit_start(self, first_order)

    def bounds(self) -> tuple[float, float]:
        if self.kind == "input" or self.shape == "drift_gain":
            return GAIN_BOUNDS
        return (-THETA_MAX, THETA_MAX) if self.signed else (THETA_MIN, THETA_MAX)

    def params(self, start: dict | None = None) -> list[Param]:
        """The term's fitted parameters (:attr:`parameters`) at ``start`` (moved inside their bounds;
        the main coefficient by default at its neutral point: zero, or :data:`THETA_MIN`)."""
        start = start or {}
        if self.kind in KINDS:
            return params(self, start)
        lo, hi = self.bounds()
        v = start.get(self.parameter, 0.0 if self.signed else lo)
        out = [Param(self.parameter, float(min(max(v, lo), hi)), "1", f"coefficient of {self.label} (in units of the state's scale)",
                     (lo, hi), positive=lo > 0)]
        if self.kind == "memory":
            s_lo, s_hi, s0 = SENSITIVITY
            t_lo, t_hi = self.tau * TAU_SPAN[0], self.tau * TAU_SPAN[1]
            sens, tau = self.parameters[1:]
            out.append(Param(sens, float(min(max(start.get(sens, s0), s_lo), s_hi)), "1",
                             f"relative rise of the dissipation of {self.state} per typical heat", (s_lo, s_hi), positive=True))
            out.append(Param(tau, float(min(max(start.get(tau, self.tau), t_lo), t_hi)), "s",
                             f"time constant of the heat state of {self.state}", (t_lo, t_hi), positive=True))
        return out

    def scales(self, system) -> list[Param]:
        """The fixed scale parameters the term reads (shared by every term on the same state): ``q_s``
        of its state (or of ``via``), and ``E_s`` [J] or ``e_s`` (its effort) and ``R_s`` (an ``R`` entry);
        a heated dissipation also its heat scale ``R_s e_s² tau`` [J], a sensor term the output's level."""
        if self.kind in KINDS:
            return scales(self, system)
        if self.kind in ("input", "sensor"):
            v = _slug(self.via)
            out = [Param(f"{EFFECT}.{v}_scale", self.q_s, _unit_of(system, self.via), f"largest |{self.via}| along the fit")]
            if self.kind == "sensor":
                unit = system.measured[system.measured_names.index(self.state)].unit
                out.append(Param(f"{EFFECT}.{_slug(self.state)}_level", self.amplitude, unit, f"typical |{self.state}| along the fit"))
            return out
        unit = _unit_of(system, self.state)
        slug = _slug(self.state)
        if self.kind == "energy":
            out = [Param(f"{EFFECT}.{slug}_scale", self.q_s, unit, f"largest |{self.state}| along the fit"),
                   Param(f"{EFFECT}.{slug}_energy", self.amplitude, "J", f"typical energy of {self.state} along the fit")]
            if self.via:
                v = _slug(self.via)
                out.append(Param(f"{EFFECT}.{v}_scale", self.v_s, _unit_of(system, self.via), f"largest |{self.via}| along the fit"))
            return out
        out = [Param(f"{EFFECT}.{slug}_effort", self.v_s, f"J/({unit})", f"typical effort ∂H/∂{self.state} along the fit"),
               Param(f"{EFFECT}.{slug}_damping", self.amplitude, f"({unit})**2/(J*s)",
                     f"typical dissipation coefficient of {self.state} (its rate over its effort)")]
        if self.via:
            v = _slug(self.via)
            out.append(Param(f"{EFFECT}.{v}_scale", self.q_s, _unit_of(system, self.via), f"largest |{self.via}| along the fit"))
        if self.kind == "memory":
            out.append(Param(f"{EFFECT}.{slug}_heat", self.heat_scale, "J", f"typical heat dissipated on {self.state} in {self.tau:.3g} s"))
        return out

    @property
    def heat_scale(self) -> float:
        """``E = R_s e_s² tau``: the heat a dissipation of unit coefficient releases in ``tau`` at the typical effort."""
        return self.amplitude * self.v_s**2 * self.tau

    def expression(self, system, theta, scales: dict) -> sp.Expr:
        """The added energy, or the added ``R[state, state]`` entry, with coefficient ``theta`` and the
        scale symbols ``scales`` (by parameter name, see :meth:`scales`)."""
        sym = {p.name: scales[p.name] for p in self.scales(system)}
        slug = _slug(self.state)
        if self.kind == "energy":
            z = system.states[system.state_names.index(self.state)].symbol / sym[f"{EFFECT}.{slug}_scale"]
            x = system.states[system.state_names.index(self.via)].symbol / sym[f"{EFFECT}.{_slug(self.via)}_scale"] if self.via else 0
            return theta * sym[f"{EFFECT}.{slug}_energy"] * shape(self).subs({Z: z, C: self.c, X: x})
        x = system.states[system.state_names.index(self.via)].symbol / sym[f"{EFFECT}.{_slug(self.via)}_scale"] if self.via else 0
        if self.kind == "input":
            return 1 + theta * shape(self).subs({X: x})
        if self.kind == "sensor":
            return theta * sym[f"{EFFECT}.{slug}_level"] * shape(self).subs({X: x})
        e = system.grad_H[system.state_names.index(self.state)] / sym[f"{EFFECT}.{slug}_effort"]
        return theta * sym[f"{EFFECT}.{slug}_damping"] * shape(self).subs({E: e, X: x})

    def attach(self, system, params: list, scales: dict, new: list) -> PHSystem:
        """``system`` with the term attached: ``params`` its own (:meth:`params`), ``scales`` the scale
        symbols by name, ``new`` the parameters the new system declares."""
        if self.kind in KINDS:
            return attach(self, system, params, scales, new)
        p = params[0]
        label = f"{EFFECT}@{self.label}"
        expr = self.expression(system, p.symbol, scales)
        if self.kind == "energy":
            return add_energy(system, label, expr, new, EFFECT)
        if self.kind == "damping":  # each term its own dissipating element, so the per-element balance names it
            return _add_damping(system, system.state_names.index(self.state), expr, label, new, EFFECT)
        if self.kind == "input":
            return scale_input(system, self.state, expr, new, EFFECT)
        if self.kind == "sensor":
            return correct_measured(system, self.state, expr, new, EFFECT)
        E_h = self.heat_scale
        heat = StateInfo(self.heat_state, "J", (-1e3 * E_h, 1e3 * E_h), f"heat dissipated on {self.state} not yet relaxed", "C", E_h,
                         EFFECT)
        return add_heated_dissipation(system, self.state, expr, heat, params[1], params[2], scales[f"{EFFECT}.{_slug(self.state)}_heat"],
                                      new, EFFECT, label)

    def words(self, system, sign: float = 1.0, values: dict | None = None) -> str:
        """What the term's shape means, for a coefficient of sign ``sign`` (``values``: the fitted
        coefficients, for the sizes a heated dissipation, an input gain or a sensor term states)."""
        values = values or {}
        if self.kind in KINDS:
            return words(self, system, {self.parameter: sign, **values})
        theta = float(values.get(self.parameter, sign))
        if self.kind == "memory":
            sens, tau = (float(values.get(k, 0.0)) for k in self.parameters[1:])
            what = "a leakage (conductance across {0})" if self.state in charge_states(system) else "a dissipation on {0}"
            # T = sens z / E: the conductance doubles once the heat state holds E / sens
            doubled = self.heat_scale / sens if sens > 0 else float("inf")
            return (what.format(self.state) + f" that rises with the heat it dissipates (its resistance falls as it heats): an internal "
                    f"heat state fed by the power it dissipates, relaxing with time constant τ ≈ {tau:.3g} s; the conductance "
                    f"doubles once {doubled:.3g} J of heat are held")
        if self.kind == "input":
            verb = "falls" if theta < 0 else "rises"
            return (f"a gain of input {self.state} that {verb} with {_GAIN[self.shape][1].format(via=self.via)} "
                    f"(by {100 * abs(theta):.0f} % at the largest |{self.via}| along the fit)")
        if self.kind == "sensor":
            unit = system.measured[system.measured_names.index(self.state)].unit
            return (f"a reading of {self.state} that deviates with {_READING[self.shape][1].format(via=self.via)} "
                    f"({theta * self.amplitude:+.3g} {unit} at the largest |{self.via}| along the fit)")
        if self.kind == "energy":
            unit = _unit_of(system, self.state)
            pos, neg = _ENERGY[self.shape][2:]
            return (neg if sign < 0 and neg else pos).format(state=self.state, via=self.via, at=f"{self.c * self.q_s:.3g} {unit}")
        return _DAMPING[self.shape][1].format(state=self.state, via=self.via)


def dictionary(system, scales, trajectory=None, outputs=None) -> list[Term]:
    """The terms of ``system`` (with its fitted values) that discovery may choose from.

    Parameters
    ----------
    system : PHSystem
        The fitted model.
    scales : components.candidates.Scales
        Typical magnitudes along the fit (co-energies, rates).
    trajectory : dict of str -> array, optional
        States along the fit: their largest magnitude is the scale ``q_s`` and their range on each
        side places the one-sided springs (default: the typical magnitudes of ``scales``).
    outputs : sequence of str, optional
        The measured outputs recorded (sensor terms go on these; default: none).

    Returns
    -------
    list of Term
    """
    traj = trajectory or {}

    def span(name):
        v = np.asarray(traj.get(name, []), float)
        if v.size:
            return float(np.max(np.abs(v))) or 1.0, float(np.max(v)), float(np.min(v))
        ref = scales.get("level", name, 1.0)
        return ref, ref, -ref

    terms = []
    disp, charges, momenta = displacement_states(system), charge_states(system), momentum_states(system)
    for q in disp + charges:
        q_s, hi, lo = span(q)
        E_s = scales.get("coenergy", q, 1.0) * q_s
        shapes = ["quartic", "sextic", "abs_cubic", "log_cosh", "gauss"] if q in disp else ["quadratic", "quartic", "log_cosh"]
        for sh in shapes:
            terms.append(Term("energy", q, sh, q_s=q_s, amplitude=E_s, signed=_ENERGY[sh][1] == "signed"))
        if q in disp:
            for share in ENGAGE_AT:
                if hi > 0.2 * q_s:
                    terms.append(Term("energy", q, "engage_up", c=share * hi / q_s, q_s=q_s, amplitude=E_s))
                if lo < -0.2 * q_s:
                    terms.append(Term("energy", q, "engage_down", c=share * lo / q_s, q_s=q_s, amplitude=E_s))
    for Q in charges:  # a multi-port storage: its stored energy modulated by a displacement
        Q_s, _, _ = span(Q)
        E_s = scales.get("coenergy", Q, 1.0) * Q_s
        for x in disp:
            x_s, _, _ = span(x)
            for sh in ("charge_z", "charge_z2"):
                terms.append(Term("energy", Q, sh, via=x, q_s=Q_s, v_s=x_s, amplitude=E_s, signed=True))
    for s in momenta + charges:
        e_s = scales.get("coenergy", s, 1.0)
        R_s = scales.get("rate", s, 1.0) / e_s
        terms.append(Term("damping", s, "abs_effort", v_s=e_s, amplitude=R_s))
        terms.append(Term("damping", s, "square_effort", v_s=e_s, amplitude=R_s))
        for x in disp:
            x_s, _, _ = span(x)
            for sh in ("square_position", "abs_position"):
                terms.append(Term("damping", s, sh, via=x, q_s=x_s, v_s=e_s, amplitude=R_s))
        # a dissipation with a memory: its own heat state, relaxing in tau (freed in the fit)
        tau = min(max(0.1 * scales.duration, 20 * scales.dt), 2.0)
        terms.append(Term("memory", s, "heated", v_s=e_s, amplitude=R_s, tau=tau))
    for u in system.input_names:  # an input gain changing with a state
        for x in disp + charges:
            x_s, _, _ = span(x)
            terms.extend(Term("input", u, sh, via=x, q_s=x_s, signed=True) for sh in _GAIN)
    for y in outputs or ():  # a sensor reading a state nonlinearly: its error a function of what it reads
        x = _read_state(system, y)
        if x is None:
            continue
        x_s, _, _ = span(x)
        terms.extend(Term("sensor", y, sh, via=x, q_s=x_s, amplitude=scales.get("level", y, 1.0), signed=True) for sh in _READING)
    return terms + added_terms(system, scales, span, make=Term, trajectory=traj)


def _read_state(system, output: str) -> str | None:
    """The one state the measured output ``output`` reads (its expression depends on that state alone and
    on parameters: no input, no port output), or None."""
    if output not in system.measured_names:
        return None
    expr = system.measured[system.measured_names.index(output)].expr
    states = {st.symbol: st.name for st in system.states}
    used = [states[sym] for sym in expr.free_symbols if sym in states]
    params = {p.symbol for p in system.params}
    if len(used) != 1 or any(sym not in states and sym not in params for sym in expr.free_symbols):
        return None
    return used[0] if used[0] in displacement_states(system) + charge_states(system) else None


class Discovered(Candidate):
    """A selection of dictionary terms as one candidate (effect ``discovered``): energy terms are added
    to ``H``, damping terms to ``R`` each as its own dissipating element, every coefficient a new
    parameter starting at ``start`` (its neutral point: zero, or :data:`THETA_MIN` for a nonnegative one).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> from components.candidates import Scales
    >>> s = mass_spring_damper()
    >>> aug = Discovered(dictionary(s, Scales.of(s))[:1]).augment(s, "k.l", Scales.of(s))
    >>> aug.free, aug.system.check().ok
    (['discovered.theta_k_l_quartic'], True)
    """

    effect = EFFECT
    summary = "a correction found by sparse regression over the model's own states (not a library effect)"

    def __init__(self, terms, start: dict | None = None):
        self.terms = tuple(terms)
        self.start = dict(start or {})

    def attach_points(self, system) -> list[str]:
        return list(dict.fromkeys(t.state for t in self.terms))[:1]

    def params(self) -> list[Param]:
        return [p for t in self.terms for p in t.params(self.start)]

    def apply(self, system: PHSystem) -> PHSystem:
        """``system`` with every term attached (coefficients at their start values, scales fixed; heat
        states appended in the order of the terms), its structure checked once, whole (the models in
        between are not: :func:`~phs.system.assembling`)."""
        scale = {}
        for t in self.terms:
            for p in t.scales(system):
                scale.setdefault(p.name, p)
        sym = {k: p.symbol for k, p in scale.items()}
        with assembling():
            s = _rebuild(system, params=list(scale.values()))
            for t in self.terms:
                own = t.params(self.start)
                s = t.attach(s, own, sym, own)
        return _rebuild(s)

    def augment(self, system, where, scales) -> Augmentation:
        params = self.params()
        # the main coefficients at zero (or their least value) remove every term; a heat state's
        # sensitivity and time constant then do not matter
        main = {t.parameter for t in self.terms}
        neutral = {p.name: (0.0 if not p.positive else p.range[0]) for p in params if p.name in main}
        log = [n for t in self.terms for n in t.log_parameters]
        return Augmentation(EFFECT, where, " + ".join(t.label for t in self.terms), self.apply(system), [p.name for p in params],
                            {p.name: p.range for p in params}, log, {x: 0.0 for t in self.terms for x in t.new_states}, neutral=neutral,
                            summary=self.summary)

    def __repr__(self) -> str:
        return f"Discovered([{', '.join(t.label for t in self.terms)}])"
