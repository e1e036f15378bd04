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
>>> terms = dictionary(s, Scales.of(s))
>>> sorted({t.kind for t in terms}), terms[0].label
(['damping', 'energy'], 'k.l:quartic')
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
from phs.params import Param
from phs.system import PHSystem

EFFECT = "discovered"
THETA_MAX = 30.0
"""Largest coefficient (in units of the state's own scale) a dictionary term may take."""
THETA_MIN = 1e-9
"""Smallest nonnegative coefficient: zero itself is refused for parameters declared positive."""
WIDTH = 0.05
"""Width (in ``z``) over which a one-sided spring engages (softplus smoothing)."""
ENGAGE_AT = (0.3, 0.45, 0.6, 0.75)
"""Where one-sided springs engage, as shares of the largest deflection reached on each side."""


def _slug(name: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in name)


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


def shape(term) -> sp.Expr:
    """The shape of ``term`` in the placeholders :data:`Z`, :data:`C`, :data:`E`, :data:`X`."""
    return (_ENERGY if term.kind == "energy" else _DAMPING)[term.shape][0]


@dataclass(frozen=True)
class Term:
    """One dictionary term: ``kind`` (``energy``/``damping``), the ``state`` it acts on, the ``shape``,
    the displacement ``via`` that modulates it (or ""), the engaging point ``c`` (in ``z``), the
    scales (``q_s`` of ``state``, ``v_s`` of ``via`` or of the effort, ``amplitude``: ``E_s`` or ``R_s``)
    and whether its coefficient is ``signed``."""

    kind: str
    state: str
    shape: str
    via: str = ""
    c: float = 0.0
    q_s: float = 1.0
    v_s: float = 1.0
    amplitude: float = 1.0
    signed: bool = False

    @property
    def label(self) -> str:
        tail = f"@{self.c:+.2f}" if self.shape.startswith("engage") else ""
        return f"{self.state}:{self.shape}" + (f"({self.via})" if self.via else "") + tail

    @property
    def parameter(self) -> str:
        """Name of the coefficient: ``discovered.theta_<state>_<shape>...`` (C-safe)."""
        raw = self.label.replace("@", "_at_").replace("+", "p").replace("-", "m").replace(".", "_")
        return f"{EFFECT}.theta_" + "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in raw).strip("_")

    def bounds(self) -> tuple[float, float]:
        return (-THETA_MAX, THETA_MAX) if self.signed else (THETA_MIN, THETA_MAX)

    def scales(self, system) -> list[Param]:
        """The fixed scale parameters the term reads (shared by every term on the same state): ``q_s``
        of its state (or of ``via``), and ``E_s`` [J] or ``e_s`` (its effort) and ``R_s`` (an ``R`` entry)."""
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
        return out

    def expression(self, system, theta, scales: dict) -> sp.Expr:
        """The added energy, or the added ``R[state, state]`` entry, with coefficient ``theta`` and the
        scale symbols ``scales`` (by parameter name, see :meth:`scales`)."""
        q = system.states[system.state_names.index(self.state)].symbol
        sym = {p.name: scales[p.name] for p in self.scales(system)}
        slug = _slug(self.state)
        if self.kind == "energy":
            z = q / sym[f"{EFFECT}.{slug}_scale"]
            x = system.states[system.state_names.index(self.via)].symbol / sym[f"{EFFECT}.{_slug(self.via)}_scale"] if self.via else 0
            return theta * sym[f"{EFFECT}.{slug}_energy"] * shape(self).subs({Z: z, C: self.c, X: x})
        e = system.grad_H[system.state_names.index(self.state)] / sym[f"{EFFECT}.{slug}_effort"]
        x = system.states[system.state_names.index(self.via)].symbol / sym[f"{EFFECT}.{_slug(self.via)}_scale"] if self.via else 0
        return theta * sym[f"{EFFECT}.{slug}_damping"] * shape(self).subs({E: e, X: x})

    def words(self, system, sign: float = 1.0) -> str:
        """What the term's shape means, for a coefficient of sign ``sign``."""
        if self.kind == "energy":
            unit = _unit_of(system, self.state)
            pos, neg = _ENERGY[self.shape][2:]
            return (neg if sign < 0 and neg else pos).format(state=self.state, via=self.via, at=f"{self.c * self.q_s:.3g} {unit}")
        return _DAMPING[self.shape][1].format(state=self.state, via=self.via)


def dictionary(system, scales, trajectory=None) -> list[Term]:
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
    return terms


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
        out = []
        for t in self.terms:
            lo, hi = t.bounds()
            v = self.start.get(t.parameter, 0.0 if t.signed else lo)
            out.append(Param(t.parameter, float(min(max(v, lo), hi)), "1", f"coefficient of {t.label} (in units of the state's scale)",
                             (lo, hi), positive=lo > 0))
        return out

    def apply(self, system: PHSystem) -> PHSystem:
        """``system`` with every term attached (coefficients at their start values, scales fixed)."""
        params = self.params()
        scale = {}
        for t in self.terms:
            for p in t.scales(system):
                scale.setdefault(p.name, p)
        sym = {k: p.symbol for k, p in scale.items()}
        s = _rebuild(system, params=list(scale.values()))
        for t, p in zip(self.terms, params, strict=True):
            if t.kind == "energy":
                s = add_energy(s, f"{EFFECT}@{t.label}", t.expression(s, p.symbol, sym), [p], EFFECT)
            else:
                # each term its own dissipating element, so the per-element balance names it
                s = _add_damping(s, s.state_names.index(t.state), t.expression(s, p.symbol, sym), f"{EFFECT}@{t.label}", [p], EFFECT)
        return s

    def augment(self, system, where, scales) -> Augmentation:
        params = self.params()
        neutral = {p.name: (0.0 if not p.positive else p.range[0]) for p in params}
        return Augmentation(EFFECT, where, " + ".join(t.label for t in self.terms), self.apply(system), [p.name for p in params],
                            {p.name: p.range for p in params}, [], neutral=neutral, summary=self.summary)

    def __repr__(self) -> str:
        return f"Discovered([{', '.join(t.label for t in self.terms)}])"
