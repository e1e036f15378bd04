"""Electrical candidates, and leaks of any stored quantity.

A leak through a dielectric (:class:`Leakage`), charge retained in it (:class:`ChargeRetention`, an RC
branch in series with a capacitor or a voltage source) and a resistance in series with a source
(:class:`SeriesResistance`).  :class:`Leakage` drains any conserved quantity held by a storage —
charge, fluid volume, gas mass or amount — through a conductance across it, a drain proportional to
the storage's effort (voltage, pressure): the circuit element applied to whichever storage has the
quantity, so it lives here for every domain.

Elements in series with a storage are inserted by the congruence ``J' = TᵀJT``,
``R' = TᵀRT + diag(0, R_new)`` with ``T = [I, E]``; elements in series with an effort input by
eliminating the input's conjugate output.  Every existing element's dissipated power is rewritten in
the new variables, so the per-element balance still adds up to the total.

Examples
--------
>>> from systems.examples import rlc_circuit
>>> from components.candidates.base import Scales
>>> s = rlc_circuit()
>>> SeriesResistance().attach_points(s), Leakage().attach_points(s)
(['U'], ['C.Q'])
"""

from __future__ import annotations

import sympy as sp

from components.candidates.base import (
    NEGLIGIBLE,
    Augmentation,
    Candidate,
    _add_damping,
    _entries,
    _log_range,
    _members,
    _power,
    _rebuild,
    _same_dimension,
    _unit_of,
    _zero,
    _zsyms,
    charge_states,
    stored_quantity_states,
    with_groups,
)
from phs.params import EnergyTerm, StateInfo


class Leakage(Candidate):
    """A conductance across a storage of a conserved quantity (charge leaking through a dielectric,
    fluid through a leak): ``R[Q, Q] += G_l``, a drain proportional to the storage's effort
    (voltage, pressure)."""

    effect = "leakage"
    summary = "the stored charge or fluid leaking away (a conductance across the storage)"

    def attach_points(self, system) -> list[str]:
        return with_groups(stored_quantity_states(system))

    def augment(self, system, where, scales) -> Augmentation:
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
                            starts=starts, neutral={G.name: _zero(G)})


class ChargeRetention(Candidate):
    """An RC branch (``C_r`` parallel to ``R_r``) in series with a capacitor: charge retained in the
    dielectric that relaxes with ``tau = R_r C_r`` — the drift branch of the curling HASEL model.

    Inserted by congruence: the capacitor's voltage seen by the network becomes ``∂H/∂Q + Q_r/C_r``
    and the branch charge obeys ``Q̇_r = Q̇ − (Q_r/C_r)/R_r``."""

    effect = "charge_retention"
    summary = "a slow charge drift in the dielectric after each voltage change (charge retention, RC branch)"

    def attach_points(self, system) -> list[str]:
        # capacitors, and voltage sources (the circuit's side of the electrodes)
        return with_groups(charge_states(system)) + [i.name for i in system.inputs
                                                      if i.kind == "effort" and _same_dimension(i.unit, ("V",))]

    def _at_input(self, system, where, scales):
        return _charge_retention_at_input(self, system, where, scales)

    def augment(self, system, where, scales) -> Augmentation:
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
                            [C.name, tau.name], {C.name: C.range, tau.name: tau.range}, [C.name, tau.name], x0, starts=starts,
                            neutral=_no_retention(C))


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
                        starts=starts, neutral=_no_retention(C))


def _no_retention(C) -> dict:
    """The neutral point of a retention branch: ``C_r → ∞`` (its voltage ``Q_r/C_r`` vanishes while
    ``Q̇_r = Q̇ − Q_r/tau`` keeps ``Q_r`` bounded; ``tau → 0`` would short it too but is stiff)."""
    return {C.name: C.range[1] / NEGLIGIBLE}


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
    R = sp.Matrix(T.T * system.R * T)  # a new matrix: the model's own R is immutable
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

    def attach_points(self, system) -> list[str]:
        return [i.name for i in system.inputs if i.kind == "effort"]

    def augment(self, system, where, scales) -> Augmentation:
        self._check_where(system, where)
        j = system.input_names.index(where)
        n = len(system.states)
        out_rms = 0.0
        # typical conjugate flow: rate of the charges driven by this input, else 1
        for k in range(n):
            if system.G[k, j] != 0 or system.P[k, j] != 0:
                out_rms = max(out_rms, scales.get("rate", system.state_names[k], 0.0))
        r_ref = scales.get("level", where, 1.0) / (out_rms or 1.0)
        info = system.inputs[j]  # effort over its conjugate flow: Ohm for a voltage, N*s/m for a force
        unit = "Ohm" if (info.unit, info.output_unit) == ("V", "A") else f"({info.unit})/({info.output_unit})"
        Ra = self.param("R_a", 0.02 * r_ref, unit, f"series resistance at input {where}", _log_range(r_ref, 1e-5, 100.0))
        s = _series_resistor_at_input(system, j, Ra.symbol, [Ra], self.effect)
        return Augmentation(self.effect, where, "resistor R_a in series with the input", s, [Ra.name], {Ra.name: Ra.range}, [Ra.name],
                            neutral={Ra.name: _zero(Ra)})


def _series_resistor_at_input(system, j: int, Ra: sp.Expr, params, effect):
    n, m = len(system.states), len(system.inputs)
    A = system.J - system.R
    B = system.G - system.P
    C = (system.G + system.P).T
    D = system.S + system.N
    E = sp.zeros(m, m)
    E[j, j] = 1
    # without a feedthrough at the input (E D = 0) M is the identity and every new entry a polynomial in
    # R_a: nothing to simplify (a 20-state curling HASEL spent 101 s simplifying its entries one by one)
    plain = (E * D).is_zero_matrix
    M = sp.eye(m) if plain else (sp.eye(m) + Ra * E * D).inv().applyfunc(sp.simplify)
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
    def simp(X, old=None):  # the entries R_a changed, simplified where M divides them
        if plain:
            return X
        return sp.Matrix(X.rows, X.cols, lambda i, k: X[i, k] if old is not None and X[i, k] == old[i, k] else sp.cancel(X[i, k]))

    z = _zsyms(n + m)
    grad, u = sp.Matrix(z[:n]), sp.Matrix(z[n:])
    u_old = M * (u - Ra * E * C * grad)
    sub = {z[n + k]: u_old[k] for k in range(m)}
    diss = [(lab, _entries(_power(ent, z).xreplace(sub), z)) for lab, ent in system.dissipators]
    y = C * grad + D * u_old
    diss.append((f"{effect}@{system.input_names[j]}", _entries(Ra * y[j] ** 2, z)))
    return _rebuild(system, J=simp(J, system.J), R=simp(R, system.R), G=simp(G, system.G), P=simp(P, system.P), S=simp(S, system.S),
                    N=simp(N, system.N), params=params,
                    dissipators=diss, effect=effect)

