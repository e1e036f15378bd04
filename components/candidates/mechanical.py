"""Mechanical candidates: effects on a moving body or a deflection that the model left out.

Friction (:class:`CoulombFriction`), fluid drag (:class:`QuadraticDrag`), viscoelastic creep
(:class:`ViscoelasticCreep`), hysteresis (:class:`Hysteresis`) and extra inertia (:class:`AddedMass`)
attach to a body's momentum; a nonlinear spring term (:class:`CubicStiffness`) attaches to a
displacement.  Each adds dissipation ``R ⪰ 0``, bounded-below energy or a new deflection state coupled
to the body by a skew ``J`` entry, so the augmented model stays port-Hamiltonian.

Examples
--------
>>> from systems.examples import mass_spring_damper
>>> from components.candidates.base import Scales
>>> s = mass_spring_damper()
>>> aug = ViscoelasticCreep().augment(s, "m.p", Scales.of(s))
>>> aug.system.state_names, aug.free
(['m.p', 'k.l', 'viscoelastic_creep.delta'], ['viscoelastic_creep.k_m', 'viscoelastic_creep.tau'])
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import sympy as sp

from components.candidates.base import (
    _add_damping,
    _add_states,
    _AtStates,
    _log_range,
    _position_partner,
    _rebuild,
    _same_dimension,
    _smooth_abs,
    _state_name,
    _unit_of,
    displacement_states,
    momentum_states,
)
from phs.params import EnergyTerm, Param, StateInfo

if TYPE_CHECKING:
    from phs.system import PHSystem


class _AtMomentum(_AtStates):
    def states(self, system) -> list[str]:
        return momentum_states(system)

    def _refs(self, system, where, scales):
        i = system.state_names.index(where)
        v = system.grad_H[i]
        v_ref = scales.get("coenergy", where, 1.0)
        q = _position_partner(system, where)
        f_ref = scales.get("force", where, 0.0)  # the force the body feels (Scales), else its spring's
        if not f_ref:
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

    def new_params(self, system, first, scales, where) -> list[Param]:
        _, _, _, f_ref, _, _ = self._refs(system, first, scales)
        return [self.param("F_c", 0.02 * f_ref, f"J/({self._unit(system, first)})",
                           f"Coulomb friction force on {where}", _log_range(f_ref, 1e-4, 10.0))]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
        i, v, v_ref, _, _, _ = self._refs(system, member, scales)
        coef = params[0].symbol / _smooth_abs(v, 0.02 * v_ref)
        return _add_damping(system, i, coef, f"{self.effect}@{member}", params if declare else [], self.effect), {}


class QuadraticDrag(_AtMomentum):
    """Quadratic (fluid) drag ``-c_d |v| v`` (smoothed): ``R[p, p] += c_d sqrt(v² + v_s²)``."""

    effect = "quadratic_drag"
    summary = "a drag force growing with the square of velocity (fluid drag)"
    component = "quadratic drag c_d·|v|·v"

    def new_params(self, system, first, scales, where) -> list[Param]:
        _, _, v_ref, f_ref, _, _ = self._refs(system, first, scales)
        ref = f_ref / v_ref**2
        return [self.param("c_d", 0.02 * ref, f"J*s**2/({self._unit(system, first)})**3",
                           f"quadratic drag coefficient on {where}", _log_range(ref, 1e-5, 100.0))]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
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
    linear solid: a step of force gives an instantaneous deflection and a slow creep.

    Neutral point: ``k_m → 0`` (``k_m = 0`` itself is singular, the damper's conductance being
    ``1/(k_m tau)``): the arm's force ``k_m δ`` vanishes while ``δ`` stays bounded (``δ̇ = v − δ/tau``),
    so a negligible ``k_m`` is the nominal model."""

    effect = "viscoelastic_creep"
    summary = "a slow creep/relaxation of the structure after each load change (viscoelasticity)"
    component = "Maxwell arm (spring k_m in series with damper k_m·tau) to ground"

    def new_params(self, system, first, scales, where) -> list[Param]:
        _, _, _, f_ref, x_ref, _ = self._refs(system, first, scales)
        k_ref = f_ref / x_ref
        tau0 = min(max(0.1 * scales.duration, 20 * scales.dt), 2.0)
        return [self.param("k_m", 0.1 * k_ref, f"J/({self._unit(system, first)})**2",
                           f"stiffness of the creep arm on {where}", _log_range(k_ref, 1e-4, 100.0)),
                self.param("tau", tau0, "s", "creep time constant", (5 * scales.dt, 10 * scales.duration))]

    def starts(self, params, scales) -> list[dict[str, float]]:
        k, tau = params
        return [{tau.name: min(10 * tau.value, 0.9 * tau.range[1])}, {tau.name: max(0.1 * tau.value, 1.1 * tau.range[0])}]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
        _, _, _, _, x_ref, q = self._refs(system, member, scales)
        k, tau = params
        return _arm(system, member, self.effect, _state_name(self.effect, "delta", tag), self._unit(system, member), x_ref, k.symbol,
                    1 / (k.symbol * tau.symbol), params if declare else [], f"deflection of the creep arm on {member}")


class Hysteresis(_AtMomentum):
    """Rate-independent hysteresis in passive Bouc-Wen/Duhem form (exponent 1).

    New state ``z`` (elastic pre-sliding deflection), ``H += k_h z²/2``, element force ``k_h z`` on the
    body, and ``ż = (1 − eta k_h |z| / F_h) v − |v| k_h z / F_h``: loops whose shape does not depend on
    the rate, saturating near ``F_h``; ``eta`` skews them (Bouc-Wen's ``δ/γ``; ``eta = 0`` is Dahl's
    model).  PH form: ``J[z, p] = 1 − eta k_h |z| / F_h`` (skew with ``J[p, z]``), ``R[z, z] = |v| / F_h ≥ 0``.
    Neutral point: ``k_h → 0`` (a negligible ``k_h``): the element's force ``k_h z`` vanishes and ``z``
    follows the displacement."""

    effect = "hysteresis"
    summary = "a rate-independent hysteresis loop in force vs. displacement (Dahl/Bouc-Wen friction, plasticity)"
    component = "Bouc-Wen/Dahl hysteresis (k_h z²/2, ż = (1 − eta k_h|z|/F_h) v − |v| k_h z / F_h)"

    def new_params(self, system, first, scales, where) -> list[Param]:
        _, _, _, f_ref, x_ref, _ = self._refs(system, first, scales)
        k_ref = f_ref / x_ref
        unit = self._unit(system, first)
        return [self.param("k_h", 2.0 * k_ref, f"J/({unit})**2", f"pre-sliding stiffness of the hysteresis on {where}",
                           _log_range(k_ref, 1e-3, 1e3)),
                self.param("F_h", 0.05 * f_ref, f"J/({unit})", f"saturation force of the hysteresis on {where}",
                           _log_range(f_ref, 1e-4, 10.0)),
                self.param("eta", -0.2, "1", "asymmetry of loading and unloading (0: Dahl)", (-3.0, 0.9))]

    def starts(self, params, scales) -> list[dict[str, float]]:
        k, F, _ = params  # a strong element (comparable to the spring's force), soft and stiff
        return [{k.name: 0.25 * k.value, F.name: 10 * F.value}, {k.name: 2.5 * k.value, F.name: 10 * F.value}]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
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
    i.e. every kinetic term of ``p`` sees the mass times ``1 + μ``, and the body's velocity is
    ``p / (m (1 + μ))`` wherever the model reads it from ``p``: in the dissipation (a friction, drag or
    hysteresis attached before reads the new velocity, as one attached after does) and in the measured
    outputs (a velocity sensor).  Next to a free mass only ``m (1 + μ)`` is then determined, whatever was
    attached before."""

    effect = "added_mass"
    summary = "more inertia than modelled (added/entrained mass)"
    component = "inertia scaled by (1 + mu)"

    def new_params(self, system, first, scales, where) -> list[Param]:
        return [self.param("mu", 0.05, "1", f"added mass as a fraction of the inertia of {where}", (1e-3, 20.0))]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
        p = system.states[system.state_names.index(member)].symbol
        sub = {p: p / sp.sqrt(1 + params[0].symbol)}
        H = [EnergyTerm(t.label, t.expr.subs(sub)) for t in system.energy_terms]
        # elsewhere p enters through the velocity p/m, now p/(m (1 + mu)); the structure J keeps p (a
        # gyroscopic term is a momentum, not a velocity)
        vel = {p: p / (1 + params[0].symbol)}
        R = sp.Matrix(system.R).xreplace(vel)
        dissipators = [(label, {k: _at(v, vel) for k, v in entries.items()}) for label, entries in system.dissipators]
        measured = [dataclasses.replace(m, expr=_at(m.expr, vel)) for m in system.measured]
        return _rebuild(system, H=H, R=R, dissipators=dissipators, measured=measured, params=params if declare else [],
                        effect=self.effect), {}


def _at(expr, sub: dict):
    """``expr`` (a model's expression, or a plain number) with ``sub`` replaced in it."""
    return expr.xreplace(sub) if isinstance(expr, sp.Basic) else expr


class CubicStiffness(_AtStates):
    """A hardening (or softening) spring term ``H += k3 q⁴/4``: a force ``k3 q³`` (Duffing).  It starts
    at 5 % of ``k_ref/q_ref²`` (typical stiffness and displacement along the nominal fit) and may
    go down to -0.3 of that (softening, bounded so H stays bounded below over the typical range)."""

    effect = "cubic_stiffness"
    summary = "a stiffness that changes with deflection (cubic, Duffing-type spring)"
    component = "quartic spring energy k3·q⁴/4"

    def states(self, system) -> list[str]:
        return displacement_states(system)

    def new_params(self, system, first, scales, where) -> list[Param]:
        q_ref = scales.get("level", first, 1.0)
        ref = scales.get("coenergy", first, 1.0) / q_ref**3
        unit = _unit_of(system, first)
        return [self.param("k3", 0.05 * ref, f"J/({unit})**4", f"cubic stiffness coefficient of {where}", (-0.3 * ref, 100 * ref))]

    def apply(self, system, member, params, scales, declare, tag) -> tuple[PHSystem, dict[str, float]]:
        q = system.states[system.state_names.index(member)].symbol
        H = list(system.energy_terms) + [EnergyTerm(f"{self.effect}@{member}", params[0].symbol * q**4 / 4)]
        return _rebuild(system, H=H, params=params if declare else [], effect=self.effect), {}

