"""Candidate physics: effects a model may have left out, each attachable to a named part of a PHSystem.

Diagnosis (:func:`phs.diagnose`) tries each candidate on the fitted model and keeps the ones the
recording asks for.  A candidate is one small class with one idea (:class:`Candidate`):

* :meth:`Candidate.attach_points` lists where it can go in a given system (a state, an input or a
  measured output, by name);
* :meth:`Candidate.augment` returns an :class:`Augmentation`: the augmented system (still a
  port-Hamiltonian system: J skew, R symmetric positive semi-definite, H bounded below), its new
  parameters with starting values, bounds and scales, and the initial values of new states.

Three ways an effect enters a model:

``structure``
    New energy, new dissipation or new states added to J, R, H (friction, creep, hysteresis,
    stiffness, added mass, leakage, charge retention) or a resistor inserted at an input port
    (series resistance).  Elements in series with a storage are inserted by the congruence
    ``J' = TᵀJT``, ``R' = TᵀRT + diag(0, R_new)`` with ``T = [I, E]``: the storage's co-energy is
    replaced by the sum of its own and the new element's, which is what "in series" means.
``input``
    A transformation of an input signal before it reaches the model (saturation, slew-rate limit,
    delay): the amplifier or the actuator's drive, outside the port-Hamiltonian part.  Such an
    element has a numeric :meth:`InputElement.transform` and its parameters are fitted by a bounded
    search on the simulated output.
``measured``
    A change of a measured output (a sensor offset).

Register a new candidate by subclassing :class:`Candidate` (or :class:`InputElement`) and passing an
instance to ``diagnose(..., candidates=[...])``; :data:`LIBRARY` holds the built-in ones.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> s = mass_spring_damper()
>>> CoulombFriction().attach_points(s)
['m.p']
>>> aug = CoulombFriction().augment(s, "m.p", Scales.of(s))
>>> aug.free, aug.system.check().ok
(['coulomb_friction.F_c'], True)
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from phs.errors import ModelError
from phs.params import EnergyTerm, Measured, Param, StateInfo
from phs.units import parse_unit

_MECHANICAL_POSITION = ("m", "rad")


# -- context: typical magnitudes ------------------------------------------------------------------------
@dataclass(frozen=True)
class Scales:
    """Typical magnitudes along the nominal model's fit, used to start and bound new parameters.

    ``value[name]``: RMS deviation of a state, input or measured output from its mean;
    ``level[name]``: RMS value (about zero); ``coenergy[state]``: RMS of ∂H/∂x for that state
    (velocity of a momentum, voltage of a charge, force of a displacement); ``rate[state]``: RMS of the
    state's time derivative; ``duration``: recording length [s]; ``dt``: sampling step [s].

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> Scales.of(rc_circuit()).duration
    1.0
    """

    value: dict = field(default_factory=dict)
    level: dict = field(default_factory=dict)
    coenergy: dict = field(default_factory=dict)
    rate: dict = field(default_factory=dict)
    duration: float = 1.0
    dt: float = 1e-3

    @staticmethod
    def of(system, t=None, x=None, u=None, measured=None) -> Scales:
        """Scales from a trajectory (arrays ``x`` (N, n), ``u`` (N, m), ``measured`` dict), or, without
        one, from the states' declared typical magnitudes."""
        value, level, co, rate = {}, {}, {}, {}
        if x is None:
            for st in system.states:
                value[st.name] = level[st.name] = st.typical
            xs = np.array([[st.typical * 0.5 for st in system.states]])
            us = np.ones((1, len(system.inputs)))
            t = np.array([0.0, 1.0])
        else:
            xs, us = np.asarray(x, float), np.asarray(u, float).reshape(len(x), -1)
            for i, st in enumerate(system.states):
                value[st.name] = _rms(xs[:, i] - xs[:, i].mean())
                level[st.name] = _rms(xs[:, i])
            for j, name in enumerate(system.input_names):
                value[name] = _rms(us[:, j] - us[:, j].mean())
                level[name] = _rms(us[:, j])
            for k, v in (measured or {}).items():
                value[k] = _rms(np.asarray(v) - np.mean(v))
                level[k] = _rms(np.asarray(v))
        grad = system.lambdify(system.grad_H, with_u=False)
        idx = np.linspace(0, len(xs) - 1, min(len(xs), 400)).astype(int)
        g = np.array([np.asarray(grad(xs[i]), float).reshape(-1) for i in idx])
        for i, st in enumerate(system.states):
            co[st.name] = _rms(g[:, i])
        if len(xs) > 2:
            dxdt = np.gradient(xs, np.asarray(t, float), axis=0)
            for i, st in enumerate(system.states):
                rate[st.name] = _rms(dxdt[:, i])
        if x is None:
            return Scales(value, level, co, rate, 1.0, 1e-3)
        t = np.asarray(t, float)
        return Scales(value, level, co, rate, float(t[-1] - t[0]) or 1.0, float(np.median(np.diff(t))) if len(t) > 1 else 1e-3)

    def get(self, table: str, name: str, default: float = 1.0) -> float:
        v = getattr(self, table).get(name, 0.0)
        return float(v) if v and np.isfinite(v) and v > 0 else float(default)


def _rms(v) -> float:
    v = np.asarray(v, float)
    return float(np.sqrt(np.mean(v * v))) if v.size else 0.0


# -- result of attaching a candidate -----------------------------------------------------------------------
@dataclass(frozen=True)
class Augmentation:
    """A model with one candidate attached.

    ``system`` is the augmented PHSystem (for ``input`` elements, the unchanged system);
    ``free`` the new parameters to fit (``bounds`` and ``log_scale`` for them);
    ``x0`` initial values of new states; ``element`` the input element for ``input`` candidates.
    """

    effect: str
    attached_to: str
    component: str
    system: object
    free: list
    bounds: dict
    log_scale: list
    x0: dict = field(default_factory=dict)
    element: InputElement | None = None
    summary: str = ""
    """The candidate's phrase for explanations (filled in from :attr:`Candidate.summary` when empty)."""
    starts: tuple = ()
    """Alternative starting values ({parameter: value}) tried when screening, for parameters whose
    plausible values span decades (a retention capacitance, a time constant)."""

    @property
    def n_params(self) -> int:
        return len(self.free)


class Candidate(ABC):
    """One kind of physics a model may lack.  Subclasses set ``effect`` (its name), ``summary``
    (a phrase for explanations), ``kind`` (``structure``, ``input`` or ``measured``) and implement
    :meth:`attach_points` and :meth:`augment`."""

    effect: str = ""
    summary: str = ""
    kind: str = "structure"

    @abstractmethod
    def attach_points(self, system) -> list[str]:
        """Names of the states, inputs or measured outputs of ``system`` this candidate can attach to."""

    @abstractmethod
    def augment(self, system, where: str, scales: Scales) -> Augmentation:
        """The system with this candidate attached at ``where``."""

    def _check_where(self, system, where: str) -> None:
        points = self.attach_points(system)
        if where not in points:
            raise ModelError(f"candidate {self.effect!r} cannot attach to {where!r} of {system.name!r}; "
                             f"possible: {points or 'none'}")

    def param(self, name: str, value: float, unit: str, description: str, rng) -> Param:
        """A new parameter ``{effect}.{name}`` starting at ``value`` (moved inside ``rng`` if needed)."""
        lo, hi = float(rng[0]), float(rng[1])
        value = min(max(float(value), lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        return Param(f"{self.effect}.{name}", value, unit, description, (lo, hi))

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


# -- structural helpers --------------------------------------------------------------------------------------
def _unit_of(system, name: str) -> str:
    return system.states[system.state_names.index(name)].unit


def momentum_states(system) -> list[str]:
    """States of kind ``I`` (momenta) with a mechanical unit.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> momentum_states(mass_spring_damper())
    ['m.p']
    """
    out = []
    for st in system.states:
        if st.kind == "I" and _same_dimension(st.unit, ("kg*m/s", "kg*m**2/s")):
            out.append(st.name)
    return out


def displacement_states(system) -> list[str]:
    """Displacement-like states with a length or angle unit."""
    return [st.name for st in system.states if st.kind == "C" and _same_dimension(st.unit, _MECHANICAL_POSITION)]


def charge_states(system) -> list[str]:
    """Electrical charges (unit C)."""
    return [st.name for st in system.states if st.kind == "C" and _same_dimension(st.unit, ("C",))]


_STORED_QUANTITY = ("C", "m**3", "kg", "mol")


def stored_quantity_states(system) -> list[str]:
    """Conserved quantities held by a storage: electrical charge, fluid volume, gas mass or amount
    (states of kind ``C`` with unit C, m³, kg or mol) — what a leak can drain.

    Examples
    --------
    >>> from systems.lab import air_chamber
    >>> stored_quantity_states(air_chamber())
    ['V_a']
    """
    return [st.name for st in system.states if st.kind == "C" and _same_dimension(st.unit, _STORED_QUANTITY)]


def _same_dimension(unit: str, candidates) -> bool:
    try:
        d = parse_unit(unit)
        return any(d == parse_unit(c) for c in candidates)
    except Exception:  # an unparsable unit is simply not of this kind
        return False


def _position_partner(system, p_name: str) -> str | None:
    """The displacement state moved by momentum ``p_name`` (a nonzero J entry), if any."""
    i = system.state_names.index(p_name)
    for q in displacement_states(system):
        j = system.state_names.index(q)
        if system.J[j, i] != 0:
            return q
    return None


def with_groups(names: list[str]) -> list[str]:
    """Attach points from state names: repeated parts of identical segments (``s1.Q2``, ``s2.Q2``)
    become one ``*.Q2`` entry (the effect on all of them, with one set of parameters, as the segments
    share their parameters); other names stay as they are.

    Examples
    --------
    >>> with_groups(["s1.Q2", "s2.Q2", "Q"])
    ['Q', '*.Q2']
    """
    suffix = {}
    for n in names:
        if "." in n:
            suffix.setdefault(n.split(".", 1)[1], []).append(n)
    grouped = {n for v in suffix.values() if len(v) > 1 for n in v}
    return [n for n in names if n not in grouped] + [f"*.{k}" for k, v in suffix.items() if len(v) > 1]


def _members(system, where: str, names: list[str]) -> list[str]:
    if where.startswith("*."):
        return [n for n in names if "." in n and n.split(".", 1)[1] == where[2:]]
    return [where]


def _zsyms(n: int) -> list[sp.Symbol]:
    return [sp.Symbol(f"_z{i}", real=True) for i in range(n)]


def _power(entries: dict, z) -> sp.Expr:
    return sum(((1 if i == j else 2) * v * z[i] * z[j] for (i, j), v in entries.items()), sp.Integer(0))


def _entries(power: sp.Expr, z) -> dict:
    """Upper-triangle quadratic-form entries of ``power`` (quadratic in ``z``)."""
    power = sp.expand(power)
    out = {}
    for i in range(len(z)):
        for j in range(i, len(z)):
            c = power.coeff(z[i], 2) if i == j else power.coeff(z[i], 1).coeff(z[j], 1) / 2
            c = sp.simplify(c) if c.free_symbols & set(z) else c
            if c != 0:
                out[(i, j)] = c
    return out


def _rebuild(system, *, states=None, H=None, J=None, R=None, G=None, P=None, S=None, N=None, params=(),
             dissipators=None, measured=None, effect: str = "") -> object:
    """A new PHSystem from ``system`` with the given parts replaced and ``params`` added."""
    from phs.system import PHSystem

    return PHSystem(
        system.name,
        states=states if states is not None else system.states,
        H=H if H is not None else list(system.energy_terms),
        J=J if J is not None else system.J, R=R if R is not None else system.R,
        G=G if G is not None else system.G, P=P if P is not None else system.P,
        S=S if S is not None else system.S, N=N if N is not None else system.N,
        inputs=system.inputs, params=tuple(system.params) + tuple(params),
        measured=measured if measured is not None else system.measured,
        conditions=[c for c in system.conditions if not c.label.endswith(f"in {system.name}")],
        dissipators=dissipators if dissipators is not None else system.dissipators,
        definitions=system.definitions,
        description=(system.description + f" + {effect}") if effect else system.description,
        structure=system.structure,
    )


def _add_states(system, new_states, new_energy, J_extra, R_extra, params, new_dissipators=(), effect=""):
    """Append states: J, R grow by the given (n+k)x(n+k) additions; G, P get zero rows; dissipator
    indices of inputs shift by k."""
    n, k, m = len(system.states), len(new_states), len(system.inputs)
    J = sp.zeros(n + k, n + k)
    R = sp.zeros(n + k, n + k)
    J[:n, :n] = system.J
    R[:n, :n] = system.R
    J += J_extra
    R += R_extra
    G = sp.zeros(n + k, m)
    P = sp.zeros(n + k, m)
    if m:
        G[:n, :] = system.G
        P[:n, :] = system.P

    def shift(i):
        return i if i < n else i + k

    diss = [(lab, {(shift(i), shift(j)): v for (i, j), v in ent.items()}) for lab, ent in system.dissipators]
    diss += list(new_dissipators)
    return _rebuild(system, states=tuple(system.states) + tuple(new_states), H=list(system.energy_terms) + list(new_energy),
                    J=J, R=R, G=G, P=P, params=params, dissipators=diss, effect=effect)


def _add_damping(system, index: int, coefficient: sp.Expr, label: str, params, effect: str):
    """R[i, i] += coefficient (a nonnegative expression), with its own dissipator entry."""
    R = sp.Matrix(system.R)
    R[index, index] += coefficient
    diss = list(system.dissipators) + [(label, {(index, index): coefficient})]
    return _rebuild(system, R=R, params=params, dissipators=diss, effect=effect)


def add_damping(system, state: str, coefficient: sp.Expr, params, effect: str):
    """``system`` with ``R[state, state] += coefficient`` (a nonnegative expression of the states and
    parameters), recorded as its own dissipating element ``{effect}@{state}``; ``params`` are the new
    parameters the coefficient uses.  The building block of candidates that add a drain or a friction.

    Examples
    --------
    >>> from systems.lab import air_chamber
    >>> from phs import Param
    >>> G = Param("leak.G", 1e-12, "m**3/(s*Pa)", "conductance", (1e-15, 1e-9))
    >>> add_damping(air_chamber(), "V_a", G.symbol, [G], "leak").R
    Matrix([[leak.G]])
    """
    return _add_damping(system, system.state_names.index(state), coefficient, f"{effect}@{state}", params, effect)


def _smooth_abs(v: sp.Expr, eps: float) -> sp.Expr:
    return sp.sqrt(v**2 + sp.Float(eps) ** 2)


def _log_range(ref: float, lo: float, hi: float) -> tuple[float, float]:
    return (ref * lo, ref * hi)


# -- mechanical candidates ---------------------------------------------------------------------------------------
class _AtStates(Candidate):
    """A candidate attached to one state or, for ``*.suffix``, to every repeated one with shared
    parameters.  Subclasses give ``states(system)``, ``new_params(system, first, scales)`` and
    ``apply(system, member, params, scales) -> (system, {new state: initial value})``."""

    component = ""

    def states(self, system) -> list[str]:  # pragma: no cover - abstract in practice
        raise NotImplementedError

    def attach_points(self, system) -> list[str]:
        return with_groups(self.states(system))

    def augment(self, system, where, scales):
        self._check_where(system, where)
        members = _members(system, where, self.states(system))
        params = self.new_params(system, members[0], scales, where)
        s, x0 = system, {}
        for k, member in enumerate(members):
            s, new = self.apply(s, member, params, scales, declare=(k == 0), tag="" if len(members) == 1 else member.split(".", 1)[0])
            x0.update(new)
        logs = [q.name for q in params if q.range[0] > 0 and q.range[1] / q.range[0] >= 100]
        return Augmentation(self.effect, where, self.component, s, [q.name for q in params], {q.name: q.range for q in params},
                            logs, x0, starts=tuple(self.starts(params, scales)))

    def starts(self, params, scales) -> list[dict]:
        """Alternative starting values tried when screening (none by default)."""
        return []


def _state_name(effect: str, local: str, tag: str) -> str:
    return f"{effect}.{tag}.{local}" if tag else f"{effect}.{local}"


class _AtMomentum(_AtStates):
    def states(self, system) -> list[str]:
        return momentum_states(system)

    def _refs(self, system, where, scales):
        i = system.state_names.index(where)
        v = system.grad_H[i]
        v_ref = scales.get("coenergy", where, 1.0)
        q = _position_partner(system, where)
        f_ref = scales.get("coenergy", q, 0.0) if q else 0.0
        if not f_ref:
            f_ref = scales.get("rate", where, 1.0)
        x_ref = scales.get("value", q, 1.0) if q else v_ref * scales.duration
        return i, v, v_ref, f_ref, x_ref, q

    def _unit(self, system, member) -> str:
        """Unit of the body's displacement (m, or rad for a rotating body)."""
        q = _position_partner(system, member)
        return _unit_of(system, q) if q else ("rad" if _same_dimension(_unit_of(system, member), ("kg*m**2/s",)) else "m")


class CoulombFriction(_AtMomentum):
    """Smooth, passive Coulomb friction on a body: force ``-F_c v / sqrt(v² + v_s²)``.

    A dissipation ``R[p, p] += F_c / sqrt(v² + v_s²) ≥ 0`` with ``v = ∂H/∂p``; ``v_s`` is 2 % of the
    typical velocity (fixed)."""

    effect = "coulomb_friction"
    summary = "a velocity-independent friction force opposing motion (Coulomb/dry friction)"
    component = "smooth Coulomb friction F_c·v/sqrt(v²+v_s²)"

    def new_params(self, system, first, scales, where):
        _, _, _, f_ref, _, _ = self._refs(system, first, scales)
        return [self.param("F_c", 0.02 * f_ref, f"J/({self._unit(system, first)})",
                           f"Coulomb friction force on {where}", _log_range(f_ref, 1e-4, 10.0))]

    def apply(self, system, member, params, scales, declare, tag):
        i, v, v_ref, _, _, _ = self._refs(system, member, scales)
        coef = params[0].symbol / _smooth_abs(v, 0.02 * v_ref)
        return _add_damping(system, i, coef, f"{self.effect}@{member}", params if declare else [], self.effect), {}


class QuadraticDrag(_AtMomentum):
    """Quadratic (fluid) drag ``-c_d |v| v`` (smoothed): ``R[p, p] += c_d sqrt(v² + v_s²)``."""

    effect = "quadratic_drag"
    summary = "a drag force growing with the square of velocity (fluid drag)"
    component = "quadratic drag c_d·|v|·v"

    def new_params(self, system, first, scales, where):
        _, _, v_ref, f_ref, _, _ = self._refs(system, first, scales)
        ref = f_ref / v_ref**2
        return [self.param("c_d", 0.02 * ref, f"J*s**2/({self._unit(system, first)})**3",
                           f"quadratic drag coefficient on {where}", _log_range(ref, 1e-5, 100.0))]

    def apply(self, system, member, params, scales, declare, tag):
        i, v, v_ref, _, _, _ = self._refs(system, member, scales)
        coef = params[0].symbol * _smooth_abs(v, 0.02 * v_ref)
        return _add_damping(system, i, coef, f"{self.effect}@{member}", params if declare else [], self.effect), {}


def _arm(system, member, effect, local, unit, x_scale, k_sym, r_coef, declare_params, description):
    """A new displacement state on body ``member``: energy ``k z²/2``, ``ż = v − r_coef·k z`` and force
    ``−k z`` on the body (``J[z, p] = 1``, ``R[z, z] = r_coef``)."""
    i = system.state_names.index(member)
    st = StateInfo(local, unit, (-100 * x_scale, 100 * x_scale), description, "C", x_scale, effect)
    n = len(system.states)
    Jx = sp.zeros(n + 1, n + 1)
    Jx[n, i], Jx[i, n] = 1, -1
    Rx = sp.zeros(n + 1, n + 1)
    Rx[n, n] = r_coef
    s = _add_states(system, [st], [EnergyTerm(f"{effect}@{member}", k_sym * st.symbol**2 / 2)], Jx, Rx, declare_params,
                    [(f"{effect}@{member}", {(n, n): r_coef})], effect)
    return s, {local: 0.0}


class ViscoelasticCreep(_AtMomentum):
    """A Maxwell arm (spring ``k_m`` in series with a damper ``k_m·tau``) between the body and ground.

    New state ``δ`` (arm deflection), ``H += k_m δ²/2``, ``δ̇ = v − δ/tau``, force ``−k_m δ`` on the body:
    ``J[δ, p] = 1``, ``R[δ, δ] = 1/(k_m tau)``.  Together with the body's own spring it is a standard
    linear solid: a step of force gives an instantaneous deflection and a slow creep."""

    effect = "viscoelastic_creep"
    summary = "a slow creep/relaxation of the structure after each load change (viscoelasticity)"
    component = "Maxwell arm (spring k_m in series with damper k_m·tau) to ground"

    def new_params(self, system, first, scales, where):
        _, _, _, f_ref, x_ref, _ = self._refs(system, first, scales)
        k_ref = f_ref / x_ref
        tau0 = min(max(0.1 * scales.duration, 20 * scales.dt), 2.0)
        return [self.param("k_m", 0.1 * k_ref, f"J/({self._unit(system, first)})**2",
                           f"stiffness of the creep arm on {where}", _log_range(k_ref, 1e-4, 100.0)),
                self.param("tau", tau0, "s", "creep time constant", (5 * scales.dt, 10 * scales.duration))]

    def starts(self, params, scales):
        k, tau = params
        return [{tau.name: min(10 * tau.value, 0.9 * tau.range[1])}, {tau.name: max(0.1 * tau.value, 1.1 * tau.range[0])}]

    def apply(self, system, member, params, scales, declare, tag):
        _, _, _, _, x_ref, q = self._refs(system, member, scales)
        k, tau = params
        return _arm(system, member, self.effect, _state_name(self.effect, "delta", tag), self._unit(system, member), x_ref, k.symbol,
                    1 / (k.symbol * tau.symbol), params if declare else [], f"deflection of the creep arm on {member}")


class Hysteresis(_AtMomentum):
    """Rate-independent hysteresis in passive Bouc-Wen/Duhem form (exponent 1).

    New state ``z`` (elastic pre-sliding deflection), ``H += k_h z²/2``, element force ``k_h z`` on the
    body, and ``ż = (1 − eta k_h |z| / F_h) v − |v| k_h z / F_h``: loops whose shape does not depend on
    the rate, saturating near ``F_h``; ``eta`` skews them (Bouc-Wen's ``δ/γ``; ``eta = 0`` is Dahl's
    model).  PH form: ``J[z, p] = 1 − eta k_h |z| / F_h`` (skew with ``J[p, z]``), ``R[z, z] = |v| / F_h ≥ 0``."""

    effect = "hysteresis"
    summary = "a rate-independent hysteresis loop in force vs. displacement (Dahl/Bouc-Wen friction, plasticity)"
    component = "Bouc-Wen/Dahl hysteresis (k_h z²/2, ż = (1 − eta k_h|z|/F_h) v − |v| k_h z / F_h)"

    def new_params(self, system, first, scales, where):
        _, _, _, f_ref, x_ref, _ = self._refs(system, first, scales)
        k_ref = f_ref / x_ref
        unit = self._unit(system, first)
        return [self.param("k_h", 2.0 * k_ref, f"J/({unit})**2", f"pre-sliding stiffness of the hysteresis on {where}",
                           _log_range(k_ref, 1e-3, 1e3)),
                self.param("F_h", 0.05 * f_ref, f"J/({unit})", f"saturation force of the hysteresis on {where}",
                           _log_range(f_ref, 1e-4, 10.0)),
                self.param("eta", -0.2, "1", "asymmetry of loading and unloading (0: Dahl)", (-3.0, 0.9))]

    def starts(self, params, scales):
        k, F, _ = params  # a strong element (comparable to the spring's force), soft and stiff
        return [{k.name: 0.25 * k.value, F.name: 10 * F.value}, {k.name: 2.5 * k.value, F.name: 10 * F.value}]

    def apply(self, system, member, params, scales, declare, tag):
        i, v, v_ref, _, x_ref, q = self._refs(system, member, scales)
        k, F, eta = params
        local = _state_name(self.effect, "z", tag)
        s, x0 = _arm(system, member, self.effect, local, self._unit(system, member), 0.05 * x_ref, k.symbol,
                     _smooth_abs(v, 1e-3 * v_ref) / F.symbol, params if declare else [], f"pre-sliding deflection on {member}")
        z = s.states[-1].symbol
        n = len(s.states) - 1
        J = sp.Matrix(s.J)
        c = 1 - eta.symbol * k.symbol * _smooth_abs(z, 1e-3 * x_ref) / F.symbol
        J[n, i], J[i, n] = c, -c
        return _rebuild(s, J=J, params=[]), x0


class AddedMass(_AtMomentum):
    """Extra inertia moving with the body (entrained fluid, unmodelled parts): ``H(p) → H(p/√(1+μ))``,
    i.e. every kinetic term of ``p`` sees the mass times ``1 + μ``."""

    effect = "added_mass"
    summary = "more inertia than modelled (added/entrained mass)"
    component = "inertia scaled by (1 + mu)"

    def new_params(self, system, first, scales, where):
        return [self.param("mu", 0.05, "1", f"added mass as a fraction of the inertia of {where}", (1e-3, 20.0))]

    def apply(self, system, member, params, scales, declare, tag):
        p = system.states[system.state_names.index(member)].symbol
        sub = {p: p / sp.sqrt(1 + params[0].symbol)}
        H = [EnergyTerm(t.label, t.expr.subs(sub)) for t in system.energy_terms]
        return _rebuild(system, H=H, params=params if declare else [], effect=self.effect), {}


class CubicStiffness(_AtStates):
    """A hardening (or softening) spring term ``H += k3 q⁴/4``: a force ``k3 q³`` (Duffing).  It starts
    at 5 % of ``k_ref/q_ref²`` (typical stiffness and displacement along the nominal fit) and may
    go down to -0.3 of that (softening, bounded so H stays bounded below over the typical range)."""

    effect = "cubic_stiffness"
    summary = "a stiffness that changes with deflection (cubic, Duffing-type spring)"
    component = "quartic spring energy k3·q⁴/4"

    def states(self, system):
        return displacement_states(system)

    def new_params(self, system, first, scales, where):
        q_ref = scales.get("level", first, 1.0)
        ref = scales.get("coenergy", first, 1.0) / q_ref**3
        unit = _unit_of(system, first)
        return [self.param("k3", 0.05 * ref, f"J/({unit})**4", f"cubic stiffness coefficient of {where}", (-0.3 * ref, 100 * ref))]

    def apply(self, system, member, params, scales, declare, tag):
        q = system.states[system.state_names.index(member)].symbol
        H = list(system.energy_terms) + [EnergyTerm(f"{self.effect}@{member}", params[0].symbol * q**4 / 4)]
        return _rebuild(system, H=H, params=params if declare else [], effect=self.effect), {}


# -- electrical candidates ------------------------------------------------------------------------------------
class Leakage(Candidate):
    """A conductance across a storage of a conserved quantity (charge leaking through a dielectric,
    fluid through a leak): ``R[Q, Q] += G_l``, a drain proportional to the storage's effort
    (voltage, pressure)."""

    effect = "leakage"
    summary = "the stored charge or fluid leaking away (a conductance across the storage)"

    def attach_points(self, system):
        return with_groups(stored_quantity_states(system))

    def augment(self, system, where, scales):
        self._check_where(system, where)
        members = _members(system, where, stored_quantity_states(system))
        # the conductance that would carry the storage's typical rate at its typical effort, and at
        # least the one that would drain it over ten recording lengths (a storage the nominal model
        # holds still has no typical rate)
        c_ref = scales.get("level", members[0], 1.0) / scales.get("coenergy", members[0], 1.0)
        g_ref = max(scales.get("rate", members[0], 1.0) / scales.get("coenergy", members[0], 1.0), c_ref / (10 * scales.duration))
        unit = "S" if members[0] in charge_states(system) else f"({_unit_of(system, members[0])})/s per unit of effort"
        G = self.param("G_l", 0.02 * g_ref, unit, f"leakage conductance across {where}", _log_range(g_ref, 1e-5, 100.0))
        s = system
        for k, name in enumerate(members):
            s = _add_damping(s, s.state_names.index(name), G.symbol, f"{self.effect}@{name}", [G] if k == 0 else [], self.effect)
        # also from slow leaks (time constants of the order of the recording): a fast start drains a
        # held storage at once, and from there the fit cannot find the gentle decay of a slow leak
        starts = tuple({G.name: min(max(c_ref / (f * scales.duration), G.range[0] * 1.01), G.range[1] * 0.99)} for f in (0.3, 3.0))
        return Augmentation(self.effect, where, "conductance G_l across the storage", s, [G.name], {G.name: G.range}, [G.name],
                            starts=starts)


class ChargeRetention(Candidate):
    """An RC branch (``C_r`` parallel to ``R_r``) in series with a capacitor: charge retained in the
    dielectric that relaxes with ``tau = R_r C_r`` — the drift branch of the curling HASEL model.

    Inserted by congruence: the capacitor's voltage seen by the network becomes ``∂H/∂Q + Q_r/C_r``
    and the branch charge obeys ``Q̇_r = Q̇ − (Q_r/C_r)/R_r``."""

    effect = "charge_retention"
    summary = "a slow charge drift in the dielectric after each voltage change (charge retention, RC branch)"

    def attach_points(self, system):
        # capacitors, and voltage sources (the circuit's side of the electrodes)
        return with_groups(charge_states(system)) + [i.name for i in system.inputs
                                                      if i.kind == "effort" and _same_dimension(i.unit, ("V",))]

    def _at_input(self, system, where, scales):
        return _charge_retention_at_input(self, system, where, scales)

    def augment(self, system, where, scales):
        self._check_where(system, where)
        if where in system.input_names:
            return self._at_input(system, where, scales)
        members = _members(system, where, charge_states(system))
        first = members[0]
        c_ref = scales.get("level", first, 1.0) / scales.get("coenergy", first, 1.0)
        tau0 = min(max(0.1 * scales.duration, 20 * scales.dt), 2.0)
        C = self.param("C_r", 20 * c_ref, "F", f"retention capacitance in series with {where}", _log_range(c_ref, 0.1, 1e7))
        tau = self.param("tau", tau0, "s", "retention time constant R_r·C_r", (5 * scales.dt, 10 * scales.duration))
        q_ref = scales.get("level", first, 1.0)
        s, x0 = system, {}
        for k, member in enumerate(members):
            name = f"{self.effect}.Q" if len(members) == 1 else f"{self.effect}.{member.split('.', 1)[0]}.Q"
            st = StateInfo(name, "C", (-100 * q_ref, 100 * q_ref), f"charge of the retention branch at {member}", "C", q_ref,
                           self.effect)
            s = _series_with_storage(s, member, st, st.symbol**2 / (2 * C.symbol), 1 / (tau.symbol / C.symbol),
                                     [C, tau] if k == 0 else [], self.effect)
            x0[name] = 0.0
        starts = tuple({C.name: f * c_ref, tau.name: tt} for f in (1e3, 1e5) for tt in (tau0, min(10 * tau0, tau.range[1] * 0.9)))
        return Augmentation(self.effect, where, "RC branch (C_r ∥ R_r = tau/C_r) in series with the capacitor", s,
                            [C.name, tau.name], {C.name: C.range, tau.name: tau.range}, [C.name, tau.name], x0, starts=starts)


def _charge_retention_at_input(cand, system, where, scales):
    """ChargeRetention attached in series with an effort input (the source side of the circuit)."""
    j = system.input_names.index(where)
    driven = [system.state_names[k] for k in range(len(system.states)) if system.G[k, j] != 0 or system.P[k, j] != 0]
    q_ref = max([scales.get("level", q, 0.0) for q in driven] + [0.0]) or 1.0
    c_ref = q_ref / scales.get("level", where, 1.0)
    tau0 = min(max(0.1 * scales.duration, 20 * scales.dt), 2.0)
    C = cand.param("C_r", 20 * c_ref, "F", f"retention capacitance in series with input {where}", _log_range(c_ref, 0.1, 1e7))
    tau = cand.param("tau", tau0, "s", "retention time constant R_r·C_r", (5 * scales.dt, 10 * scales.duration))
    name = f"{cand.effect}.Q"
    st = StateInfo(name, "C", (-100 * q_ref, 100 * q_ref), f"charge of the retention branch at input {where}", "C", q_ref,
                   cand.effect)
    s = _series_with_input(system, j, st, st.symbol**2 / (2 * C.symbol), C.symbol / tau.symbol, [C, tau], cand.effect)
    starts = tuple({C.name: f * c_ref, tau.name: tt} for f in (1e3, 1e5) for tt in (tau0, min(10 * tau0, tau.range[1] * 0.9)))
    return Augmentation(cand.effect, where, "RC branch (C_r ∥ R_r = tau/C_r) in series with the source", s,
                        [C.name, tau.name], {C.name: C.range, tau.name: tau.range}, [C.name, tau.name], {name: 0.0},
                        starts=starts)


def _series_with_input(system, j: int, state: StateInfo, energy: sp.Expr, conductance: sp.Expr, params, effect):
    """Insert a one-state element (energy ``energy``, a conductance across it) in series with the
    effort input ``j``: the model sees ``u_j − e_r`` and the element's charge obeys
    ``Q̇_r = y_j − conductance·e_r`` with ``y_j`` the input's conjugate output (the source current)."""
    n, m = len(system.states), len(system.inputs)
    A, B = system.J - system.R, system.G - system.P
    C, D = (system.G + system.P).T, system.S + system.N
    ej = sp.zeros(m, 1)
    ej[j] = 1
    A2 = sp.zeros(n + 1, n + 1)
    A2[:n, :n] = A
    A2[:n, n] = -B * ej
    A2[n, :n] = ej.T * C
    A2[n, n] = -(ej.T * D * ej)[0, 0] - conductance
    B2 = B.col_join(ej.T * D)
    C2 = C.row_join(-D * ej)
    J = (A2 - A2.T) / 2
    R = -(A2 + A2.T) / 2
    G = (B2 + C2.T) / 2
    P = (C2.T - B2) / 2
    z_old, z_new = _zsyms(n + m), _zsyms(n + 1 + m)
    sub = {z_old[k]: (z_new[k] if k < n else z_new[k + 1]) for k in range(n + m)}
    sub[z_old[n + j]] = z_new[n + 1 + j] - z_new[n]
    diss = [(lab, _entries(_power(ent, z_old).xreplace(sub), z_new)) for lab, ent in system.dissipators]
    diss.append((f"{effect}@{system.input_names[j]}", {(n, n): conductance}))
    return _rebuild(system, states=tuple(system.states) + (state,),
                    H=list(system.energy_terms) + [EnergyTerm(f"{effect}@{system.input_names[j]}", energy)],
                    J=J, R=R, G=G, P=P, params=params, dissipators=diss, effect=effect)


def _series_with_storage(system, where, state: StateInfo, energy: sp.Expr, conductance: sp.Expr, params, effect):
    """Insert a one-state element (energy ``energy``, a conductance across it) in series with storage
    ``where`` by the congruence T = [I, E]."""
    n, m = len(system.states), len(system.inputs)
    i = system.state_names.index(where)
    T = sp.zeros(n, n + 1)
    T[:, :n] = sp.eye(n)
    T[i, n] = 1
    J = T.T * system.J * T
    R = T.T * system.R * T
    R[n, n] += conductance
    G = T.T * system.G if m else sp.zeros(n + 1, 0)
    P = T.T * system.P if m else sp.zeros(n + 1, 0)
    z_old, z_new = _zsyms(n + m), _zsyms(n + 1 + m)
    # old z = [dH; u] -> new: dH_i gets e_new added; u indices shift by one
    sub = {z_old[k]: (z_new[k] if k < n else z_new[k + 1]) for k in range(n + m)}
    sub[z_old[i]] = z_new[i] + z_new[n]
    diss = [(lab, _entries(_power(ent, z_old).xreplace(sub), z_new)) for lab, ent in system.dissipators]
    diss.append((f"{effect}@{where}", {(n, n): conductance}))
    return _rebuild(system, states=tuple(system.states) + (state,), H=list(system.energy_terms) + [EnergyTerm(f"{effect}@{where}", energy)],
                    J=J, R=R, G=G, P=P, params=params, dissipators=diss, effect=effect)


class SeriesResistance(Candidate):
    """A resistor ``R_a`` in series with an effort (voltage/force) input: the model sees
    ``u − R_a y`` where ``y`` is the port's conjugate output (the source current)."""

    effect = "series_resistance"
    summary = "an extra resistance in series with the source (leads, electrodes, amplifier output)"

    def attach_points(self, system):
        return [i.name for i in system.inputs if i.kind == "effort"]

    def augment(self, system, where, scales):
        self._check_where(system, where)
        j = system.input_names.index(where)
        n = len(system.states)
        out_rms = 0.0
        # typical conjugate flow: rate of the charges driven by this input, else 1
        for k in range(n):
            if system.G[k, j] != 0 or system.P[k, j] != 0:
                out_rms = max(out_rms, scales.get("rate", system.state_names[k], 0.0))
        r_ref = scales.get("level", where, 1.0) / (out_rms or 1.0)
        Ra = self.param("R_a", 0.02 * r_ref, "Ohm", f"series resistance at input {where}", _log_range(r_ref, 1e-5, 100.0))
        s = _series_resistor_at_input(system, j, Ra.symbol, [Ra], self.effect)
        return Augmentation(self.effect, where, "resistor R_a in series with the input", s, [Ra.name], {Ra.name: Ra.range}, [Ra.name])


def _series_resistor_at_input(system, j: int, Ra: sp.Expr, params, effect):
    n, m = len(system.states), len(system.inputs)
    A = system.J - system.R
    B = system.G - system.P
    C = (system.G + system.P).T
    D = system.S + system.N
    E = sp.zeros(m, m)
    E[j, j] = 1
    M = (sp.eye(m) + Ra * E * D).inv()
    M = M.applyfunc(sp.simplify)
    A2 = A - Ra * B * M * E * C
    B2 = B * M
    C2 = C - Ra * D * M * E * C
    D2 = D * M
    J = (A2 - A2.T) / 2
    R = -(A2 + A2.T) / 2
    G = (B2 + C2.T) / 2
    P = (C2.T - B2) / 2
    S = (D2 + D2.T) / 2
    N = (D2 - D2.T) / 2
    simp = lambda X: X.applyfunc(sp.simplify)  # noqa: E731
    z = _zsyms(n + m)
    grad, u = sp.Matrix(z[:n]), sp.Matrix(z[n:])
    u_old = M * (u - Ra * E * C * grad)
    sub = {z[n + k]: u_old[k] for k in range(m)}
    diss = [(lab, _entries(_power(ent, z).xreplace(sub), z)) for lab, ent in system.dissipators]
    y = C * grad + D * u_old
    diss.append((f"{effect}@{system.input_names[j]}", _entries(Ra * y[j] ** 2, z)))
    return _rebuild(system, J=simp(J), R=simp(R), G=simp(G), P=simp(P), S=simp(S), N=simp(N), params=params,
                    dissipators=diss, effect=effect)


# -- measured-output candidates ---------------------------------------------------------------------------------
class Offset(Candidate):
    """A constant offset on a measured output (sensor zero error): ``y_m → y_m + c``."""

    effect = "offset"
    summary = "a constant offset of the sensor reading"
    kind = "measured"

    def attach_points(self, system):
        return list(system.measured_names)

    def augment(self, system, where, scales):
        self._check_where(system, where)
        k = system.measured_names.index(where)
        mo = system.measured[k]
        ref = max(scales.get("value", where, 1.0), 1e-12)
        c = self.param(f"{where}", 0.01 * ref, mo.unit, f"offset of the measured output {where}", (-100 * ref, 100 * ref))
        measured = list(system.measured)
        measured[k] = Measured(mo.name, mo.expr + c.symbol, mo.unit, mo.description)
        s = _rebuild(system, measured=measured, params=[c], effect=self.effect)
        return Augmentation(self.effect, where, "constant added to the reading", s, [c.name], {c.name: c.range}, [])


# -- input elements ------------------------------------------------------------------------------------------------
class InputElement(Candidate):
    """An element between the recorded input and the model's input (drive electronics, transport):
    :meth:`transform` maps the sampled input with parameter values ``theta`` (one per entry of
    :meth:`parameters`).  The model itself is unchanged."""

    kind = "input"

    def attach_points(self, system):
        return list(system.input_names)

    @abstractmethod
    def parameters(self, t, u) -> list[tuple[str, float, float, float]]:
        """``(name, start, lo, hi)`` per parameter, given the recorded input."""

    @abstractmethod
    def transform(self, t: np.ndarray, u: np.ndarray, theta) -> np.ndarray:
        """The input the model receives."""

    def augment(self, system, where, scales):
        self._check_where(system, where)
        return Augmentation(self.effect, where, self.component, system, [], {}, [], {}, self)

    component = ""


class TimeDelay(InputElement):
    """A transport delay ``u(t − tau_d)`` (linear interpolation; the input holds its first value before 0)."""

    effect = "time_delay"
    summary = "a delay between the commanded input and the response"
    component = "delay u(t − tau_d)"

    def parameters(self, t, u):
        T = float(t[-1] - t[0])
        dt = float(np.median(np.diff(t)))
        return [("tau_d", 5 * dt, 0.0, min(0.2 * T, 200 * dt))]

    def transform(self, t, u, theta):
        return np.interp(t - float(theta[0]), t, u)


class InputSaturation(InputElement):
    """A saturation of the input at ``U_hi`` above and ``-U_lo`` below (possibly asymmetric), with
    corners rounded over 5 % of the input's peak: ``u − sp(u − U_hi) + sp(−u − U_lo)``, ``sp`` the
    softplus, shifted to pass through zero.  The limits are searched below the recorded peaks (a limit above them has no effect)."""

    effect = "input_saturation"
    summary = "the input saturating at large amplitude (drive or actuator limit)"
    component = "soft clip of u to [-U_lo, U_hi]"

    def parameters(self, t, u):
        hi = float(np.max(u)) if np.max(u) > 0 else float(np.max(np.abs(u))) or 1.0
        lo = float(-np.min(u)) if np.min(u) < 0 else float(np.max(np.abs(u))) or 1.0
        return [("U_hi", 1.05 * hi, 0.2 * hi, 1.05 * hi), ("U_lo", 1.05 * lo, 0.2 * lo, 1.05 * lo)]

    def transform(self, t, u, theta):
        u = np.asarray(u, float)
        w = 0.05 * (float(np.max(np.abs(u))) or 1.0)

        def sp_(x):
            return w * np.logaddexp(0.0, x / w)

        hi, lo = float(theta[0]), float(theta[1])
        # minus its value at zero: the rounded corners must not turn a zero input into a small constant one
        return u - sp_(u - hi) + sp_(-u - lo) + sp_(-hi) - sp_(-lo)


class SlewRateLimit(InputElement):
    """A limit ``r`` on the rate of change of the input (amplifier slew rate): the model's input
    follows the command at most at ``r`` units per second.  Searched between the rate that would
    take the whole recording to cross the input's span and the command's own steepest slope."""

    effect = "slew_rate_limit"
    summary = "the input rising no faster than a maximum rate (amplifier slew-rate limit)"
    component = "rate limiter |du/dt| <= r"

    def parameters(self, t, u):
        span = float(np.ptp(u)) or 1.0
        steepest = float(np.max(np.abs(np.diff(u) / np.diff(t)))) or span / float(t[-1] - t[0])
        lo = min(span / float(t[-1] - t[0]), 0.5 * steepest)
        return [("r", steepest, lo, steepest)]

    def transform(self, t, u, theta):
        r = float(theta[0])
        out = np.empty_like(np.asarray(u, float))
        out[0] = u[0]
        dts = np.diff(t) * r
        cur = float(u[0])
        for k in range(1, len(u)):
            step = u[k] - cur
            lim = dts[k - 1]
            cur += step if -lim <= step <= lim else (lim if step > 0 else -lim)
            out[k] = cur
        return out


LIBRARY: tuple[Candidate, ...] = (
    ChargeRetention(), Leakage(), SeriesResistance(), CoulombFriction(), ViscoelasticCreep(), CubicStiffness(),
    Hysteresis(), QuadraticDrag(), AddedMass(), InputSaturation(), SlewRateLimit(), TimeDelay(), Offset(),
)
"""The built-in candidates, one per effect name."""

EFFECTS: tuple[str, ...] = tuple(c.effect for c in LIBRARY)

__all__ = [
    "Scales", "Augmentation", "Candidate", "InputElement", "LIBRARY", "EFFECTS", "momentum_states", "displacement_states",
    "charge_states", "stored_quantity_states", "add_damping", "with_groups", "ChargeRetention", "Leakage", "SeriesResistance",
    "CoulombFriction", "ViscoelasticCreep",
    "CubicStiffness", "Hysteresis", "QuadraticDrag", "AddedMass", "InputSaturation", "SlewRateLimit", "TimeDelay", "Offset",
]
