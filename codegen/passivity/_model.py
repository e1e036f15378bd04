"""The generated CasADi functions and symbol dependencies a certificate evaluates, cached per system."""

from __future__ import annotations

import weakref

import casadi as ca
import numpy as np
import sympy as sp

from codegen.functions import generate
from codegen.translate import Translator


class _Model:
    """Generated CasADi functions and symbol dependencies used by the certificate."""

    def __init__(self, system):
        self.system = system
        g = generate(system)
        self.generated = g
        sx = g.sx
        x, u, p = sx["x"], sx["u"], sx["p"]
        nx, nu = len(system.states), len(system.inputs)
        self.nx, self.nu, self.np = nx, nu, len(system.params)
        name = g.rhs.name()[: -len("_rhs")]
        symmap = {s: x[i] for i, s in enumerate(system.x)}
        symmap.update({s: u[i] for i, s in enumerate(system.u)})
        symmap.update({s: p[i] for i, s in enumerate(system.p)})
        tr = Translator(symmap)
        Dsym = system.dissipation_matrix
        N = nx + nu
        self.znames = system.state_names + system.input_names
        self.support = [i for i in range(N) if any(Dsym[i, j] != 0 for j in range(N))]
        Dsup = tr(Dsym.extract(self.support, self.support)) if self.support else ca.SX(0, 0)
        self.fD = ca.Function(f"{name}_dissipation", [x, p], [ca.densify(Dsup)], ["x", "p"], ["D"])
        self.fH = g.hamiltonian
        self.fcond = g.conditions
        entries = [(k, i, j, v) for k, (_label, ent) in enumerate(system.dissipators) for (i, j), v in ent.items()]
        self.diss_entries = [(k, i, j) for k, i, j, _ in entries]
        self.fdiss = ca.Function(f"{name}_dissipator_entries", [x, p],
                                 [ca.vertcat(*[tr(v) for *_, v in entries]) if entries else ca.SX(0, 1)])
        A, B = ca.jacobian(sx["xdot"], x), ca.jacobian(sx["xdot"], u)
        C, Dm = ca.jacobian(sx["y"], x), ca.jacobian(sx["y"], u)
        hess = ca.hessian(sx["H"], x)[0]
        struct = ca.horzcat(sx["J"] - sx["R"], sx["G"] - sx["P"]) if nu else sx["J"] - sx["R"]
        self.flin = ca.Function(f"{name}_linearization", [x, u, p], [A, B, C, Dm, hess, struct, sx["xdot"]],
                                ["x", "u", "p"], ["A", "B", "C", "D", "hess_H", "structure", "xdot"])
        # dependencies: which states / parameters each quantity involves
        sidx = {s: i for i, s in enumerate(system.x)}
        pidx = {s: i for i, s in enumerate(system.p)}

        def deps(expr):
            fs = expr.free_symbols
            return frozenset(sidx[s] for s in fs if s in sidx), frozenset(pidx[s] for s in fs if s in pidx)

        self.D_deps = deps(Dsym) if self.support else (frozenset(), frozenset())
        self.R_deps = deps(system.R)
        self.H_deps = deps(system.H)
        self.cond_deps = [deps(sp.sympify(c.expr)) for c in system.conditions]
        self._maps: dict = {}
        self.cache: dict = {}

    def batch(self, fn, *args) -> list[np.ndarray]:
        """Evaluate ``fn`` at the rows of ``args`` (each (k, n_i)) through one mapped call; outputs (k, ...)."""
        k = args[0].shape[0]
        key = (fn.name(), k)
        fm = self._maps.get(key)
        if fm is None:
            fm = self._maps[key] = fn.map(k) if k > 1 else fn
        with np.errstate(all="ignore"):
            outs = fm(*[np.asarray(a, dtype=float).T for a in args])
        outs = outs if isinstance(outs, (tuple, list)) else (outs,)
        res = []
        for o, i in zip(outs, range(fn.n_out())):
            o = np.asarray(o, dtype=float)
            r, c = fn.size_out(i)
            res.append(o.reshape(r, k, c).transpose(1, 0, 2) if c > 1 else o.reshape(r, k).T)
        return res

    def D(self, X, P) -> np.ndarray:
        """Dissipation matrices on the support, (k, m, m)."""
        m = len(self.support)
        if m == 0:
            return np.zeros((len(X), 0, 0))
        out = self.batch(self.fD, X, P)[0]
        return out.reshape(len(X), m, m)

    def conditions(self, X, U, P) -> np.ndarray:
        if not self.system.conditions:
            return np.zeros((len(X), 0))
        return self.batch(self.fcond, X, U, P)[0].reshape(len(X), -1)

    def H(self, X, P) -> np.ndarray:
        return self.batch(self.fH, X, np.zeros((len(X), self.nu)), P)[0].reshape(-1)


_MODELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

_BY_HASH: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def _model(system) -> _Model:
    hit = _MODELS.get(system)
    if hit is None:
        key = system.model_hash()
        hit = _BY_HASH.get(key)
        if hit is None:
            hit = _Model(system)
            _BY_HASH[key] = hit
        _MODELS[system] = hit
    return hit
