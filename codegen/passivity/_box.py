"""The box of states (and parameters) a certificate covers, uniform samples of its valid part, and the scaling of D."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from codegen.passivity._model import _Model
from phs.errors import InputDataError

EIGENVALUE_TOL = 1e-9
"""A scaled eigenvalue of D above ``-EIGENVALUE_TOL`` counts as nonnegative (rounding of D's entries, ~1e-15
relative, with a wide safety factor; a real loss of passivity in a seed-sized model is orders larger)."""


# -- the box ----------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Box:
    names: tuple          # variables: every state, then the parameters varied
    pindex: tuple         # parameter index of each varied parameter
    lo: np.ndarray
    hi: np.ndarray
    p: np.ndarray         # parameter values (overrides applied)
    u: np.ndarray         # inputs at which the validity conditions are evaluated

    @property
    def key(self):
        return (self.names, tuple(self.lo), tuple(self.hi))

    def points(self, V: np.ndarray, nx: int, p: np.ndarray | None = None):
        """(X, P) of the variable values ``V`` (k, nvar)."""
        P = np.repeat((self.p if p is None else p)[None, :], len(V), axis=0)
        for j, k in enumerate(self.pindex):
            P[:, k] = V[:, nx + j]
        return V[:, :nx], P

    def as_dict(self) -> dict:
        return {n: (float(a), float(b)) for n, a, b in zip(self.names, self.lo, self.hi)}


def _bounds(name: str, value) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputDataError(f"box {name!r}: expected (lower, upper), got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputDataError(f"box {name!r}: bounds [{lo:g}, {hi:g}] are not finite")
    if lo > hi:
        raise InputDataError(f"box {name!r}: lower bound {lo:g} > upper bound {hi:g}")
    return lo, hi


def _resolve_box(system, box, params) -> _Box:
    """States over their declared ranges (or ``box``), parameters named in ``box`` over theirs, others fixed."""
    box = dict(box or {})
    p = system.param_vector(params, signs=False)  # a what-if value of the wrong sign is reported, not refused
    known = set(system.state_names) | set(system.param_names)
    for name in box:
        if name not in known:
            raise InputDataError(f"box: system {system.name!r} has no state or parameter {name!r} "
                                 f"(states: {', '.join(system.state_names)}; parameters: {', '.join(system.param_names)})")
    lo, hi, names, pindex = [], [], [], []
    for st in system.states:
        a, b = _bounds(st.name, box[st.name]) if box.get(st.name) is not None else _bounds(st.name, st.range)
        names.append(st.name)
        lo.append(a)
        hi.append(b)
    for k, q in enumerate(system.params):
        if q.name in box:
            a, b = _bounds(q.name, box[q.name]) if box[q.name] is not None else _bounds(q.name, q.range)
            names.append(q.name)
            pindex.append(k)
            lo.append(a)
            hi.append(b)
    u = np.array([min(max(0.0, i.range[0]), i.range[1]) if i.range else 0.0 for i in system.inputs])
    return _Box(tuple(names), tuple(pindex), np.array(lo), np.array(hi), p, u)


def _valid(model: _Model, box: _Box, X, P) -> np.ndarray:
    g = model.conditions(X, np.repeat(box.u[None, :], len(X), axis=0), P)
    return np.all(np.isfinite(g) & (g >= -1e-12), axis=1) if g.shape[1] else np.ones(len(X), dtype=bool)


def _point(box: _Box, v) -> dict:
    return {n: float(a) for n, a in zip(box.names, v)}


# -- sampling the valid part of the box --------------------------------------------------------------
def _groups(model: _Model, box: _Box):
    """Groups of box variables coupled by validity conditions: [(variable indices, condition indices)]."""
    nx = model.nx
    var_of_p = {k: nx + j for j, k in enumerate(box.pindex)}
    parent = list(range(len(box.names)))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    cvars = []
    for xs, ps in model.cond_deps:
        vs = sorted(set(xs) | {var_of_p[k] for k in ps if k in var_of_p})
        cvars.append(vs)
        for a in vs[1:]:
            parent[find(a)] = find(vs[0])
    groups: dict[int, tuple[list, list]] = {}
    for v in range(len(box.names)):
        groups.setdefault(find(v), ([], []))[0].append(v)
    fixed = []
    for c, vs in enumerate(cvars):
        if vs:
            groups[find(vs[0])][1].append(c)
        else:
            fixed.append(c)
    return list(groups.values()), fixed, cvars


def _keep_sample(model: _Model, key, value, most: int = 16) -> None:
    """Cache a sample, dropping the oldest samples beyond ``most`` (certificates at many parameter values)."""
    model.cache[key] = value
    samples = [k for k in model.cache if k[0] == "sample"]
    for k in samples[: max(0, len(samples) - most)]:
        del model.cache[k]


def _sample(model: _Model, box: _Box, k: int, seed: int, p=None):
    """``k`` points drawn uniformly from the valid part of the box, rejection per group of coupled variables.

    Returns ``(V, info)``; ``V`` has fewer rows when a group has no valid point.  The draw uses the box's
    parameter values (``p`` overrides them); callers re-check validity at their own parameter values.
    """
    key = ("sample", box.key, tuple(box.p if p is None else p), k, seed)
    hit = model.cache.get(key)
    if hit is not None:
        return hit
    rng = np.random.default_rng(seed)
    pvals = box.p if p is None else p
    nvar = len(box.names)
    centre = (box.lo + box.hi) / 2
    V = rng.uniform(box.lo, box.hi, size=(k, nvar))
    groups, fixed, _ = _groups(model, box)
    info = {"drawn": k, "groups": []}
    if fixed:
        X, P = box.points(centre[None, :], model.nx, pvals)
        g = model.conditions(X, box.u[None, :], P)[0, fixed]
        if not np.all(g >= 0):
            out = (np.zeros((0, nvar)), {**info, "empty": [model.system.conditions[c].label for c, v in zip(fixed, g) if not v >= 0]})
            _keep_sample(model, key, out)
            return out
    for vars_, conds in groups:
        if not conds:
            continue
        got, drawn = [], 0
        batch = max(4 * k, 256)
        for _ in range(25):
            C = np.repeat(centre[None, :], batch, axis=0)
            C[:, vars_] = rng.uniform(box.lo[vars_], box.hi[vars_], size=(batch, len(vars_)))
            X, P = box.points(C, model.nx, pvals)
            g = model.conditions(X, np.repeat(box.u[None, :], batch, axis=0), P)[:, conds]
            ok = np.all(np.isfinite(g) & (g >= 0), axis=1)
            got.append(C[ok][:, vars_])
            drawn += batch
            if sum(len(a) for a in got) >= k:
                break
        pts = np.concatenate(got) if got else np.zeros((0, len(vars_)))
        info["groups"].append({"variables": [box.names[v] for v in vars_], "acceptance": len(pts) / drawn})
        if len(pts) == 0:
            out = (np.zeros((0, nvar)), {**info, "empty": [model.system.conditions[c].label for c in conds]})
            _keep_sample(model, key, out)
            return out
        if len(pts) < k:  # rare: keep every valid point found, repeated
            pts = pts[rng.integers(0, len(pts), size=k)]
        V[:, vars_] = pts[:k]
    out = (V, info)
    _keep_sample(model, key, out)
    return out


# -- scaled dissipation matrix ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Scale:
    d: np.ndarray   # reference diagonal (support coordinates)
    Q: np.ndarray   # orthonormal basis of the support minus the structural null space (m x r)
    null: int


def _reference(model: _Model, box: _Box, p_own: np.ndarray) -> tuple[_Scale, _Scale]:
    """Reference diagonal and structural null spaces of D and of its state block R, for the state box at the
    system's own parameter values ``p_own``: the scalings of the full-form test and of the margin."""
    key = ("reference", box.names[: model.nx], tuple(box.lo[: model.nx]), tuple(box.hi[: model.nx]), tuple(p_own))
    hit = model.cache.get(key)
    if hit is not None:
        return hit
    m = len(model.support)
    sysbox = _Box(box.names[: model.nx], (), box.lo[: model.nx], box.hi[: model.nx], np.asarray(p_own, dtype=float), box.u)
    V, _ = _sample(model, sysbox, 64, 0)
    if len(V) == 0:
        V = np.random.default_rng(0).uniform(sysbox.lo, sysbox.hi, size=(64, model.nx))
    X, P = sysbox.points(V, model.nx)
    Dk = model.D(X, P)
    Dk = Dk[np.all(np.isfinite(Dk), axis=(1, 2))]
    d = np.sqrt(np.mean(np.diagonal(Dk, axis1=1, axis2=2) ** 2, axis=0)) if len(Dk) else np.ones(m)
    off = np.sqrt(np.mean(Dk**2, axis=0)).max(axis=1) if len(Dk) else np.ones(m)
    d = np.where(d > 0, d, np.where(off > 0, off, 1.0))
    # structural null space: common to D at the sample and with parameters drawn over their declared ranges
    rng = np.random.default_rng(1)
    Pr = np.array([[rng.uniform(*q.range) for q in model.system.params] for _ in range(len(X))]).reshape(len(X), -1)
    Dr = model.D(X, Pr)
    stack = [M / np.sqrt(np.outer(d, d)) for M in np.concatenate([Dk, Dr]) if np.all(np.isfinite(M))]

    def complement(idx):
        Q = np.zeros((m, len(idx)))
        Q[idx, np.arange(len(idx))] = 1.0
        if not stack or not idx:
            return Q, 0
        S = np.concatenate([M[np.ix_(idx, idx)] for M in stack])
        _, sv, Vt = np.linalg.svd(S, full_matrices=False)  # the left factor of a tall stack is never used
        r = int(np.sum(sv > 1e-9 * sv[0])) if sv.size and sv[0] > 0 else 0
        return Q @ Vt[:r].T, len(idx) - r

    QD, nD = complement(list(range(m)))
    QR, nR = complement([a for a, i in enumerate(model.support) if i < model.nx])
    out = (_Scale(d, QD, nD), _Scale(d, QR, nR))
    model.cache[key] = out
    return out


def _scaled(Dk: np.ndarray, scale: _Scale) -> np.ndarray:
    w = 1 / np.sqrt(scale.d)
    M = Dk * np.outer(w, w)
    return scale.Q.T @ M @ scale.Q


def _min_eig(Dk: np.ndarray, scale: _Scale, vectors: bool = True):
    """Smallest scaled eigenvalue and its eigenvector (in the reduced coordinates) of each matrix, (k,), (k, r)."""
    M = _scaled(Dk, scale)
    if M.shape[-1] == 0:
        return np.zeros(len(Dk)), np.zeros((len(Dk), 0))
    lam = np.full(len(Dk), np.nan)
    vec = np.zeros((len(Dk), M.shape[-1]))
    ok = np.all(np.isfinite(M), axis=(1, 2))
    if np.any(ok):
        if vectors:
            w, v = np.linalg.eigh(M[ok])
            vec[ok] = v[:, :, 0]
        else:
            w = np.linalg.eigvalsh(M[ok])
        lam[ok] = w[:, 0]
    return lam, vec
