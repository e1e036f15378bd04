"""The candidate interface and the machinery every candidate shares.

* :class:`Scales`: typical magnitudes along the nominal fit, to start and bound new parameters;
* :class:`Augmentation`: a model with one candidate attached;
* :class:`Candidate`: the one interface of candidate physics (drive elements, kind ``input``, take the
  form of :class:`components.candidates.elements.InputElement`);
* where candidates attach: :func:`momentum_states`, :func:`displacement_states`, :func:`charge_states`,
  :func:`stored_quantity_states`, :func:`with_groups` (repeated parts of identical segments as one point);
* how they change a model while keeping it port-Hamiltonian: rebuilding a system with parts replaced,
  appending states, adding a damping term (:func:`add_damping`), rewriting every element's dissipated
  power under a change of variables, and attaching to one state or a group of them with shared parameters.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> s = mass_spring_damper()
>>> momentum_states(s), displacement_states(s), Scales.of(s).duration
(['m.p'], ['k.l'], 1.0)
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import sympy as sp

from phs.errors import ModelError
from phs.params import Param
from phs.units import parse_unit

if TYPE_CHECKING:
    from phs.system import PHSystem

_MECHANICAL_POSITION = ("m", "rad")

NEGLIGIBLE = 1e-12
"""Relative size of a parameter standing for zero where zero itself is refused (a parameter declared
positive) or singular: its effect on a model is far below any integration tolerance."""


# -- context: typical magnitudes ------------------------------------------------------------------------
@dataclass(frozen=True)
class Scales:
    """Typical magnitudes along the nominal model's fit, used to start and bound new parameters.

    ``value[name]``: RMS deviation of a state, input or measured output from its mean;
    ``level[name]``: RMS value (about zero); ``coenergy[state]``: RMS of ∂H/∂x for that state
    (velocity of a momentum, voltage of a charge, force of a displacement); ``rate[state]``: RMS of the
    state's time derivative; ``force[momentum]``: the force a body feels (below); ``duration``: recording
    length [s]; ``dt``: sampling step [s].

    The force a body feels is the larger RMS of its inertia ``ṗ`` and of the net conservative and
    source force on it, ``J[p, :] ∇H + G[p, :] u`` (its damping lies between them: ``ṗ`` is their
    difference).  Springs and sources count by their sum: a position loop's virtual spring to the
    origin and its reference force ``K_p r`` pull the body apart by ``K_p (r − x)``, not by ``K_p x``.
    Without a trajectory the table is empty and a candidate falls back to the coenergy of the body's
    displacement.

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
    force: dict = field(default_factory=dict)
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
            return Scales(value, level, co, rate, {}, 1.0, 1e-3)
        force = _body_forces(system, xs[idx], us[idx], g, rate)
        t = np.asarray(t, float)
        return Scales(value, level, co, rate, force, float(t[-1] - t[0]) or 1.0,
                      float(np.median(np.diff(t))) if len(t) > 1 else 1e-3)

    def get(self, table: str, name: str, default: float = 1.0) -> float:
        v = getattr(self, table).get(name, 0.0)
        return float(v) if v and np.isfinite(v) and v > 0 else float(default)


def _body_forces(system, xs, us, grads, rate) -> dict:
    """RMS force each body (momentum state) feels along a trajectory: the larger of its inertia
    (``rate``) and its net conservative and source force ``J[p, :] ∇H + G[p, :] u``."""
    bodies = momentum_states(system)
    if not bodies:
        return {}
    rows = [system.state_names.index(b) for b in bodies]
    J, G = system.J, system.G
    # plain names: sympy renames dotted names one argument at a time, quadratic in a large model's size
    jg = system._lambdify(sp.Matrix([J[i, :] for i in rows]), False, plain_names=True)
    gg = system._lambdify(sp.Matrix([G[i, :] for i in rows]), False, plain_names=True) if G.shape[1] else None
    f = np.zeros((len(xs), len(rows)))
    for n, (x, gr) in enumerate(zip(xs, grads)):
        f[n] = np.asarray(jg(x), float).reshape(len(rows), -1) @ gr
        if gg is not None:
            f[n] += np.asarray(gg(x), float).reshape(len(rows), -1) @ np.asarray(us[n], float)
    return {b: max(_rms(f[:, k]), float(rate.get(b, 0.0))) for k, b in enumerate(bodies)}


def _rms(v) -> float:
    v = np.asarray(v, float)
    return float(np.sqrt(np.mean(v * v))) if v.size else 0.0


# -- result of attaching a candidate -----------------------------------------------------------------------
@dataclass(frozen=True)
class Augmentation:
    """A model with one candidate attached.

    ``system`` is the augmented PHSystem (for ``input`` elements, the unchanged system);
    ``free`` the new parameters to fit (``bounds`` and ``log_scale`` for them);
    ``x0`` initial values of new states; ``element`` the input element for ``input`` candidates
    (:class:`components.candidates.elements.InputElement`).
    """

    effect: str
    attached_to: str
    component: str
    system: object
    free: list
    bounds: dict
    log_scale: list
    x0: dict = field(default_factory=dict)
    element: object = None
    summary: str = ""
    """The candidate's phrase for explanations (filled in from :attr:`Candidate.summary` when empty)."""
    starts: tuple = ()
    """Alternative starting values ({parameter: value}) tried when screening, for parameters whose
    plausible values span decades (a retention capacitance, a time constant)."""
    neutral: dict = field(default_factory=dict)
    """Values of new parameters at which the augmented model is the nominal one (the element at zero
    strength).  Where zero is refused (a parameter declared positive) or singular, a value whose
    effect is negligible (:data:`NEGLIGIBLE` of its range's magnitude, or its inverse for an element
    that vanishes as a parameter grows; possibly outside the search range).  Parameters not named do
    not matter there.
    Empty: unknown (a user candidate that does not say)."""

    @property
    def n_params(self) -> int:
        return len(self.free)

    def neutral_start(self) -> dict:
        """:attr:`neutral` moved inside :attr:`bounds` (a point a fit can start from).

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> from components.candidates import CoulombFriction
        >>> s = mass_spring_damper()
        >>> aug = CoulombFriction().augment(s, "m.p", Scales.of(s))
        >>> aug.neutral_start() == {"coulomb_friction.F_c": aug.bounds["coulomb_friction.F_c"][0]}
        True
        """
        out = {}
        for k, v in self.neutral.items():
            lo, hi = self.bounds.get(k, (-np.inf, np.inf))
            out[k] = float(min(max(v, lo), hi))
        return out


def command_channels(system) -> list[str]:
    """The measured channels of ``system`` that are a controller's computed command (``Measured.command``).

    Examples
    --------
    >>> from systems.examples import pd_servo
    >>> servo = pd_servo()
    >>> command_channels(servo)
    ['u_c']
    """
    return [m.name for m in system.measured if m.command]


def controller_inputs(system) -> list[str]:
    """The inputs a controller's computed command (:func:`command_channels`) is computed from: its reference
    and any signal added to its output.  They are signals inside the controller, not drives: an element
    between a command and the plant sits at the command.

    Examples
    --------
    >>> from systems.examples import pd_servo
    >>> controller_inputs(pd_servo())
    ['r']
    """
    symbols = set()
    for m in system.measured:
        if m.command:
            symbols |= {s.name for s in getattr(m.expr, "free_symbols", ())}
    return [n for n in system.input_names if n in symbols]



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

    def places(self, system, signals) -> list[str]:
        """Where the candidate is tried, given the recorded ``signals`` (a mapping of name to samples): its
        attach points, less the model inputs a recorded controller command is computed from (its reference,
        a signal added to its output: :func:`~components.candidates.elements.controller_inputs`).  Those are
        signals inside the controller, not ports through which power enters the plant: an electrical or
        mechanical element at them models nothing that exists.  Input elements (drive physics) refine this
        (:meth:`components.candidates.elements.InputElement.places`).

        Examples
        --------
        >>> import numpy as np
        >>> from components.candidates import SeriesResistance
        >>> from systems.examples import pd_servo
        >>> servo = pd_servo()
        >>> t = np.linspace(0.0, 1.0, 5)
        >>> SeriesResistance().places(servo, {"r": t, "u_c": np.sin(t)})   # the reference is inside the loop
        []
        >>> SeriesResistance().places(servo, {"r": t})                     # no command recorded
        ['r']
        """
        recorded = any(c in signals and np.ptp(np.asarray(signals[c], float)) > 0 for c in command_channels(system))
        inside = set(controller_inputs(system)) if recorded else set()
        return [w for w in self.attach_points(system) if w not in inside]

    def _check_where(self, system, where: str) -> None:
        points = self.attach_points(system)
        if where not in points:
            raise ModelError(f"candidate {self.effect!r} cannot attach to {where!r} of {system.name!r}; "
                             f"possible: {points or 'none'}")

    def param(self, name: str, value: float, unit: str, description: str, rng) -> Param:
        """A new parameter ``{effect}.{name}`` starting at ``value`` (moved inside ``rng`` if needed),
        declared positive only when its whole range is (a sign-free one, such as a softening stiffness or
        an offset, may be fitted below zero)."""
        lo, hi = float(rng[0]), float(rng[1])
        value = min(max(float(value), lo + 1e-3 * (hi - lo)), hi - 1e-3 * (hi - lo))
        return Param(f"{self.effect}.{name}", value, unit, description, (lo, hi), positive=lo > 0)

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


def with_groups(names: list[str], units: dict | None = None) -> list[str]:
    """Attach points from state names: repeated parts of identical segments (``s1.Q2``, ``s2.Q2``)
    become one ``*.Q2`` entry (the effect on all of them, with one set of parameters, as the segments
    share their parameters); other names stay as they are.  With ``units`` (name to unit), names of one
    suffix in different units are no repeated parts (a rotating ``tail.p`` and a sliding ``body.p``: one
    parameter cannot serve both) and stay apart.

    Examples
    --------
    >>> with_groups(["s1.Q2", "s2.Q2", "Q"])
    ['Q', '*.Q2']
    >>> with_groups(["tail.p", "body.p"], {"tail.p": "kg*m**2/s", "body.p": "kg*m/s"})
    ['tail.p', 'body.p']
    """
    suffix = {}
    for n in names:
        if "." in n:
            suffix.setdefault(n.split(".", 1)[1], []).append(n)
    if units is not None:
        suffix = {k: v for k, v in suffix.items() if len({units.get(n) for n in v}) == 1}
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
             dissipators=None, measured=None, inputs=None, effect: str = "") -> object:
    """A new PHSystem from ``system`` with the given parts replaced and ``params`` added."""
    from phs.system import PHSystem

    return PHSystem(
        system.name,
        states=states if states is not None else system.states,
        H=H if H is not None else list(system.energy_terms),
        J=J if J is not None else system.J, R=R if R is not None else system.R,
        G=G if G is not None else system.G, P=P if P is not None else system.P,
        S=S if S is not None else system.S, N=N if N is not None else system.N,
        inputs=inputs if inputs is not None else system.inputs, params=tuple(system.params) + tuple(params),
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


def add_damping(system, state: str, coefficient: sp.Expr, params, effect: str) -> PHSystem:
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


def add_energy(system: PHSystem, label: str, energy: sp.Expr, params, effect: str) -> PHSystem:
    """``system`` with the energy term ``energy`` (an expression of the states and parameters, labelled
    ``label``) added to its Hamiltonian; ``params`` are the new parameters it uses.  The forces come
    from its gradient through the system's own ``J``: the building block of candidates that add a
    storage (a spring term, a nonlinear capacitance).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> from phs import Param
    >>> s = mass_spring_damper()
    >>> k3 = Param("k3", 1.0, "N/m**3", "cubic stiffness")
    >>> q = s.states[s.state_names.index("k.l")].symbol
    >>> add_energy(s, "k3@k.l", k3.symbol * q**4 / 4, [k3], "stiffening").energy_terms[-1].label
    'k3@k.l'
    """
    from phs.params import EnergyTerm

    return _rebuild(system, H=list(system.energy_terms) + [EnergyTerm(label, energy)], params=params, effect=effect)


def _smooth_abs(v: sp.Expr, eps: float) -> sp.Expr:
    return sp.sqrt(v**2 + sp.Float(eps) ** 2)


def _zero(param) -> float:
    """The value of ``param`` standing for zero: 0 itself, or for a parameter declared positive
    :data:`NEGLIGIBLE` times the largest magnitude of its range."""
    return 0.0 if not param.positive else NEGLIGIBLE * max(abs(param.range[0]), abs(param.range[1]))


def _log_range(ref: float, lo: float, hi: float) -> tuple[float, float]:
    return (ref * lo, ref * hi)


# -- attaching to one state or to a group of repeated ones ---------------------------------------------
class _AtStates(Candidate):
    """A candidate attached to one state or, for ``*.suffix``, to every repeated one with shared
    parameters.  Subclasses give ``states(system)``, ``new_params(system, first, scales)`` and
    ``apply(system, member, params, scales) -> (system, {new state: initial value})``."""

    component = ""

    def states(self, system) -> list[str]:  # pragma: no cover - abstract in practice
        raise NotImplementedError

    def attach_points(self, system) -> list[str]:
        return with_groups(self.states(system), {st.name: st.unit for st in system.states})

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
                            logs, x0, starts=tuple(self.starts(params, scales)), neutral=self.neutral(params))

    def starts(self, params, scales) -> list[dict]:
        """Alternative starting values tried when screening (none by default)."""
        return []

    def neutral(self, params) -> dict:
        """Values of ``params`` at which the element vanishes (see :attr:`Augmentation.neutral`); by
        default the first one, the element's strength, at zero (:func:`_zero`)."""
        return {params[0].name: _zero(params[0])} if params else {}


def _state_name(effect: str, local: str, tag: str) -> str:
    return f"{effect}.{tag}.{local}" if tag else f"{effect}.{local}"
