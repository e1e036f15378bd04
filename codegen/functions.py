"""Named CasADi functions generated from a PHSystem.

``generate(system)`` returns a :class:`GeneratedFunctions` holding
``{name}_rhs``, ``{name}_output``, ``{name}_hamiltonian``,
``{name}_grad_hamiltonian``, ``{name}_jac_rhs``, ``{name}_power_balance``,
``{name}_measured``, ``{name}_conditions`` and ``{name}_dissipators``, all
with named inputs ``x``, ``u``, ``p``.  Parameters stay symbolic inputs, so
fits and sweeps need no regeneration.  The gradient of H is obtained by
CasADi's automatic differentiation of the translated H (no symbolic
differentiation of large Hamiltonians); tests compare it with sympy's.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import casadi as ca
import sympy as sp

from codegen.translate import Translator
from phs.params import c_identifier
from phs.system import PHSystem


@dataclass(frozen=True)
class GeneratedFunctions:
    """The generated functions of one system structure and the symbols they were built from.

    ``system`` is the system they were first generated for; systems that differ from it only in
    parameter values share the functions (parameters are their input ``p``).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> f = generate(mass_spring_damper())
    >>> [fn.name() for fn in f.all()][:3]
    ['msd_rhs', 'msd_output', 'msd_hamiltonian']
    """

    system: PHSystem
    rhs: ca.Function
    output: ca.Function
    hamiltonian: ca.Function
    grad_hamiltonian: ca.Function
    jac_rhs: ca.Function
    power_balance: ca.Function
    measured: ca.Function
    conditions: ca.Function
    dissipators: ca.Function
    energy_terms: ca.Function
    sx: dict

    def all(self) -> list[ca.Function]:
        return [self.rhs, self.output, self.hamiltonian, self.grad_hamiltonian, self.jac_rhs, self.power_balance,
                self.measured, self.conditions, self.dissipators, self.energy_terms]


_CACHE: weakref.WeakKeyDictionary[PHSystem, GeneratedFunctions] = weakref.WeakKeyDictionary()
_BY_HASH: weakref.WeakValueDictionary[str, GeneratedFunctions] = weakref.WeakValueDictionary()
_HASHES: weakref.WeakKeyDictionary[PHSystem, str] = weakref.WeakKeyDictionary()


def _model_hash(system: PHSystem) -> str:
    """``system.model_hash()`` computed once per system object (hashing prints every expression)."""
    h = _HASHES.get(system)
    if h is None:
        h = _HASHES[system] = system.model_hash()
    return h


def generate(system: PHSystem) -> GeneratedFunctions:
    """Generate (once per system object) the named CasADi functions of ``system``.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> f = generate(rc_circuit())
    >>> f.rhs.name(), f.rhs.name_in(), f.rhs.name_out()
    ('rc_rhs', ['x', 'u', 'p'], ['xdot'])
    >>> float(f.hamiltonian([1e-6], [0], [1e3, 1e-6]))
    5e-07
    """
    hit = _CACHE.get(system)
    if hit is not None:
        return hit
    # parameters are inputs of the functions: systems differing only in parameter values
    # (``with_params``) share them
    key = _model_hash(system)
    hit = _BY_HASH.get(key)
    if hit is not None:
        _CACHE[system] = hit
        return hit
    name = c_identifier(system.name).replace("__", "_")  # CasADi function names may not hold '__'
    nx, nu, npar = len(system.states), len(system.inputs), len(system.params)
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", npar)
    symmap = {s: x[i] for i, s in enumerate(system.x)}
    symmap.update({s: u[i] for i, s in enumerate(system.u)})
    symmap.update({s: p[i] for i, s in enumerate(system.p)})
    tr = Translator(symmap)
    terms = [tr(t.expr) for t in system.energy_terms]
    H = ca.sum1(ca.vertcat(*terms)) if terms else ca.SX(0)
    dH = ca.gradient(H, x)
    J, R, G, P, S, N = (tr(M) for M in (system.J, system.R, system.G, system.P, system.S, system.N))
    xdot = ca.mtimes(J - R, dH) + (ca.mtimes(G - P, u) if nu else 0)
    y = ca.mtimes((G + P).T, dH) + ca.mtimes(S + N, u) if nu else ca.SX(0, 1)
    z = ca.vertcat(dH, u)
    D = ca.blockcat([[R, P], [P.T, S]]) if nu else R
    dissipated = ca.mtimes(z.T, ca.mtimes(D, z)) if nu else ca.mtimes(dH.T, ca.mtimes(R, dH))
    supplied = ca.dot(y, u) if nu else ca.SX(0)
    dHdt = ca.dot(dH, xdot)
    for k, inp in enumerate(system.inputs):  # measured outputs may refer to port outputs by name
        tr.memo[sp.Symbol(inp.output, real=True)] = y[k]
    meas = ca.vertcat(*[tr(m.expr) for m in system.measured]) if system.measured else ca.SX(0, 1)
    conds = ca.vertcat(*[tr(c.expr) for c in system.conditions]) if system.conditions else ca.SX(0, 1)
    dparts = []
    for _label, entries in system.dissipators:
        tot = ca.SX(0)
        for (i, j), v in entries.items():
            tot += (1 if i == j else 2) * tr(v) * z[i] * z[j]
        dparts.append(tot)
    diss = ca.vertcat(*dparts) if dparts else ca.SX(0, 1)
    ins, names = [x, u, p], ["x", "u", "p"]

    def F(kind, outs, onames):
        return ca.Function(f"{name}_{kind}", ins, outs, names, onames)

    out = GeneratedFunctions(
        system=system,
        rhs=F("rhs", [xdot], ["xdot"]),
        output=F("output", [y, meas], ["y", "measured"]),
        hamiltonian=F("hamiltonian", [H], ["H"]),
        grad_hamiltonian=F("grad_hamiltonian", [dH], ["dH"]),
        jac_rhs=F("jac_rhs", [ca.jacobian(xdot, x), ca.jacobian(xdot, u)], ["A", "B"]),
        power_balance=F("power_balance", [dHdt, dissipated, supplied], ["dHdt", "dissipated", "supplied"]),
        measured=F("measured", [meas], ["measured"]),
        conditions=F("conditions", [conds], ["g"]),
        dissipators=F("dissipators", [diss], ["power"]),
        energy_terms=F("energy_terms", [ca.vertcat(*terms) if terms else ca.SX(0, 1)], ["H_terms"]),
        sx={"x": x, "u": u, "p": p, "xdot": xdot, "H": H, "dH": dH, "y": y, "measured": meas, "conditions": conds,
            "dissipated": dissipated, "supplied": supplied, "dissipators": diss, "J": J, "R": R, "G": G, "P": P},
    )
    _CACHE[system] = out
    _BY_HASH[key] = out
    return out
