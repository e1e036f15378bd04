"""Local minima over the box with CasADi ``nlpsol`` (IPOPT): the Rayleigh quotient of D, and H."""

from __future__ import annotations

import casadi as ca
import numpy as np

from codegen.passivity._box import _Box, _groups, _Scale
from codegen.passivity._model import _Model

_IPOPT = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 300, "ipopt.tol": 1e-10,
          "ipopt.acceptable_iter": 0, "error_on_fail": False,
          "show_eval_warnings": False}


def _closure(model: _Model, box: _Box, xdeps, pdeps):
    """Box variables a quantity depends on, closed under the validity conditions that couple them; and those conditions."""
    nx = model.nx
    var_of_p = {k: nx + j for j, k in enumerate(box.pindex)}
    vars_ = set(xdeps) | {var_of_p[k] for k in pdeps if k in var_of_p}
    _, _, cvars = _groups(model, box)
    conds: set[int] = set()
    changed = True
    while changed:
        changed = False
        for c, vs in enumerate(cvars):
            if c not in conds and vs and vars_ & set(vs):
                conds.add(c)
                if not set(vs) <= vars_:
                    vars_ |= set(vs)
                changed = True
    return sorted(vars_), sorted(conds)


def _nlp(model: _Model, box: _Box, kind: str, vars_, conds, scale: _Scale | None = None):
    """IPOPT solver over normalised variables ``xi`` in [0, 1] (and, for ``eig``, a direction ``w``).

    Its parameter vector is ``[x (nx), p (np), lower bounds (nv), widths (nv), H reference, H scale]``: the
    variables not optimised keep their values in ``x``, ``p``.
    """
    key = ("nlp", kind, box.names, tuple(vars_), tuple(conds), None if scale is None else scale.Q.tobytes())
    hit = model.cache.get(key)
    if hit is not None:
        return hit
    nx, npar = model.nx, model.np
    nv = len(vars_)
    xi = ca.SX.sym("xi", nv)
    fixed = ca.SX.sym("fixed", nx + npar + 2 * nv + 2)
    full = [fixed[i] for i in range(nx + npar)]
    for j, v in enumerate(vars_):
        at = nx + box.pindex[v - nx] if v >= nx else v
        full[at] = fixed[nx + npar + j] + fixed[nx + npar + nv + j] * xi[j]
    X = ca.vertcat(*full[:nx])
    P = ca.vertcat(*full[nx:]) if npar else ca.SX(0, 1)
    if kind == "eig":
        w = ca.SX.sym("w", scale.Q.shape[1])
        Wd = np.diag(1 / np.sqrt(scale.d))
        M = ca.mtimes([ca.DM(scale.Q.T @ Wd), model.fD(X, P), ca.DM(Wd @ scale.Q)])
        ww = ca.dot(w, w)
        f = ca.mtimes([w.T, M, w]) / ww + (ww - 1) ** 2  # Rayleigh quotient; the penalty fixes |w| = 1
        z = ca.vertcat(xi, w)
    else:
        f = (model.fH(X, ca.DM.zeros(model.nu), P) - fixed[-2]) / fixed[-1]
        z = xi
    g = model.fcond(X, ca.DM(box.u), P)[conds] if conds else ca.SX(0, 1)
    solver = ca.nlpsol(f"{model.fH.name()}_{kind}_min", "ipopt", {"x": z, "p": fixed, "f": f, "g": g}, dict(_IPOPT))
    model.cache[key] = solver
    return solver


def _minimise(model: _Model, box: _Box, kind: str, V: np.ndarray, values: np.ndarray, starts: int, seed: int,
              deps, scale: _Scale | None = None, vectors: np.ndarray | None = None, ref: tuple = (0.0, 1.0)):
    """Local minima of ``kind`` (``eig``: the Rayleigh quotient of D; ``H``) from ``starts`` sample points.

    Starts are the best half of the sample and random others.  Returns the end points (rows of box
    variables) and the number of solver runs that reported success.
    """
    vars_, conds = _closure(model, box, *deps)
    finite = np.flatnonzero(np.isfinite(values))
    if not vars_ or starts <= 0 or len(finite) == 0:
        return np.zeros((0, V.shape[1])), 0, 0
    order = finite[np.argsort(values[finite], kind="stable")]
    best = list(order[: (starts + 1) // 2])
    rest = order[(starts + 1) // 2:]
    rng = np.random.default_rng(seed + 1)
    if len(rest):
        best += list(rng.choice(rest, size=min(starts - len(best), len(rest)), replace=False))
    solver = _nlp(model, box, kind, vars_, conds, scale)
    nx = model.nx
    lo, width = box.lo[vars_], box.hi[vars_] - box.lo[vars_]
    nv = len(vars_)
    ends, ok = [], 0
    for i in best:
        X, P = box.points(V[i: i + 1], nx)
        fixed = np.concatenate([X[0], P[0], lo, width, ref])
        xi0 = np.where(width > 0, (V[i, vars_] - lo) / np.where(width > 0, width, 1), 0.0)
        z0 = np.concatenate([xi0, vectors[i]]) if kind == "eig" else xi0
        r = len(z0) - nv
        lbx = np.concatenate([np.zeros(nv), -np.inf * np.ones(r)])
        ubx = np.concatenate([np.where(width > 0, 1.0, 0.0), np.inf * np.ones(r)])
        try:
            sol = solver(x0=z0, p=fixed, lbx=lbx, ubx=ubx, lbg=0.0, ubg=np.inf)
        except RuntimeError:
            continue
        ok += bool(solver.stats().get("success", False))
        z = np.asarray(sol["x"], dtype=float).reshape(-1)
        if not np.all(np.isfinite(z)):
            continue
        end = V[i].copy()
        end[vars_] = lo + width * np.clip(z[:nv], 0.0, 1.0)
        ends.append(end)
    return (np.array(ends) if ends else np.zeros((0, V.shape[1]))), ok, len(best)
