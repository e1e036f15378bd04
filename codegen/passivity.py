"""Passivity certificates for nonlinear port-Hamiltonian models.

A system ``x' = (J - R) dH/dx + (G - P) u``, ``y = (G + P)^T dH/dx + (S + N) u``
is passive with storage ``H - min H`` when ``J = -J^T``, ``N = -N^T``, H is
bounded below and the dissipation matrix ``D = [[R, P], [P^T, S]]`` is positive
semidefinite: then ``dH/dt = -z^T D z + y^T u <= y^T u`` with
``z = [dH/dx; u]``.  :func:`certify` checks each of these over a box of states
(and optionally parameters) and reports, for a failure, the point and the
element responsible:

``interconnection``
    J and N skew-symmetric (symbolic; the model is refused at construction
    otherwise, so this records the proof).
``dissipation``
    D ⪰ 0: symbolically where decidable (every principal minor of each block,
    or of each resistive element's form when they sum to D, is a sum of
    products of positive parameters), and numerically over the box: the
    minimum eigenvalue over a dense sample and from several starts of CasADi
    ``nlpsol`` (IPOPT) minimising the Rayleigh quotient ``w^T D(x, p) w /
    w^T w`` jointly over the point and the direction.  The worst point, the
    eigenvector and the resistive element with the most negative share of
    ``w^T D w`` are reported.
``feedthrough``
    For the full form with P, S, N: N skew, S ⪰ 0 and P in the range that
    ``[[R, P], [P^T, S]] ⪰ 0`` requires (``P (I - S S^+) = 0``).
``storage``
    H bounded below on the box: its minimum (dense sample + ``nlpsol``) and argmin.
``trajectory`` (optional)
    The dissipation inequality ``∫ y^T u dt - (H(T) - H(0)) >= 0`` along a
    simulation, with the dissipated energy split per resistive element
    (:func:`dissipation_inequality`).
``local`` (optional)
    Input- and output-strict passivity indices of the linearisation at an
    equilibrium, with conserved directions of J removed (:func:`local_passivity`).

Points outside the model's validity domain (its conditions, e.g. an arcsin
argument above 1) are not part of the box: samples are drawn uniformly from
the valid part (rejection per group of coupled coordinates) and the
optimisations carry the conditions as constraints.

The margin
----------
``margin`` (:attr:`PassivityReport.margin`, :func:`dissipation_margin`) is the
smallest eigenvalue over the box of the state block R of D, made
dimensionless: coordinate ``i`` is divided by ``sqrt(d_i)``, where ``d_i`` is
the root mean square of ``D_ii`` over a fixed 64-point reference sample of the
state box at the system's own parameter values (so overrides and swept
parameters change the margin, the scale does not), and directions in which D
vanishes identically (a source in series with a resistor: the rc circuit's
``z = (1, 1)``) are removed.  A lone resistive element at its declared value
scores 1, half its value 0.5, 0 means a lossless direction somewhere in the
box.  When the full form ``[[R, P], [P^T, S]]`` has a negative eigenvalue
anywhere in the box, the margin is that (scaled, negative) eigenvalue instead,
so its sign is the verdict.  The full form is not used for a positive margin:
the HASEL models' input map ``gamma1 cos(gamma2 theta)`` vanishes at the edge
of their validity domain, where the port's row of D vanishes for every
parameter set.  Coordinates on which D has no entry at all (pure storage) are
not counted: they are lossless by construction.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import time
import weakref
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.linalg
import scipy.optimize
import sympy as sp

from codegen._named import find_named
from codegen.functions import generate
from codegen.translate import Translator
from phs.errors import EquilibriumError, InputDataError
from phs.io import write_atomic

__all__ = ["certify", "dissipation_margin", "dissipation_inequality", "local_passivity", "PassivityReport",
           "PassivityTest", "LocalPassivity"]

EIGENVALUE_TOL = 1e-9
"""A scaled eigenvalue of D above ``-EIGENVALUE_TOL`` counts as nonnegative (rounding of D's entries, ~1e-15
relative, with a wide safety factor; a real loss of passivity in a seed-sized model is orders larger)."""

ENERGY_TOL = 1e-6
"""Relative tolerance of the dissipation inequality along a trajectory (at least twice the run's own energy-balance
error): CVODES runs at ``rtol=1e-8`` close the balance to ~1e-6 of the energy exchanged (2e-7 to 1.2e-6 measured on
the 4-segment curling HASEL under square waves)."""

EQUILIBRIUM_TOL = 1e-7
"""A claimed equilibrium's scaled rate ``max_i |x'_i| / s_i``, divided by the norm of the scaled Jacobian (the
fastest rate), must be below this."""

_VERDICTS = ("pass", "fail", "undecided")
_IPOPT = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.max_iter": 300, "ipopt.tol": 1e-10,
          "ipopt.acceptable_iter": 0, "error_on_fail": False,
          "show_eval_warnings": False}


# -- results --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PassivityTest:
    """One test of a passivity certificate: verdict, method, numbers, worst point and the element responsible.

    Attributes
    ----------
    name : str
        ``interconnection``, ``dissipation``, ``feedthrough``, ``storage``, ``trajectory`` or ``local``.
    verdict : str
        ``pass``, ``fail`` or ``undecided``.
    method : str
        How it was decided (symbolic, sampled, optimised, simulated, frequency sweep ...).
    summary : str
        One sentence with the numbers.
    numbers : dict
        The numbers by name (JSON-ready).
    worst : dict
        The state/parameter point where the test is tightest (or fails).
    element : str
        The element responsible for a failure (or the tightest one), else ``""``.
    series : dict
        Arrays for the report's plots (not part of :meth:`to_dict`).

    Examples
    --------
    >>> t = PassivityTest("storage", "pass", "sampled", "H >= 0 J", {"H_min": 0.0})
    >>> t.to_dict()["verdict"], t.passed
    ('pass', True)
    """

    name: str
    verdict: str
    method: str
    summary: str
    numbers: dict = field(default_factory=dict)
    worst: dict = field(default_factory=dict)
    element: str = ""
    series: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        if self.verdict not in _VERDICTS:
            raise ValueError(f"verdict must be one of {_VERDICTS}, got {self.verdict!r}")

    @property
    def passed(self) -> bool:
        return self.verdict == "pass"

    def to_dict(self) -> dict:
        return _jsonable({"name": self.name, "verdict": self.verdict, "method": self.method, "summary": self.summary,
                          "numbers": self.numbers, "worst": self.worst, "element": self.element})

    def line(self) -> str:
        out = f"  [{self.verdict:^9}] {self.name}: {self.summary}"
        if self.element and self.verdict != "pass":
            out += f"\n              element responsible: {self.element}"
        if self.worst:
            out += "\n              at " + _fmt_point(self.worst)
        return out + f"\n              ({self.method})"


class PassivityReport:
    """Passivity certificate of one system: the tests, their verdicts and the margin.

    Attributes
    ----------
    passive : bool
        True when no test failed and the interconnection, dissipation, feedthrough and storage tests passed.
    tests : list of PassivityTest
    margin : float
        Smallest scaled eigenvalue of R over the box, or the (negative) one of ``[[R, P], [P^T, S]]`` when that
        has one: its sign is the dissipation verdict (scaling in the module docstring).

    Examples
    --------
    >>> from systems.examples import rlc_circuit
    >>> rep = certify(rlc_circuit(), samples=64, starts=1)
    >>> rep.passive, [t.verdict for t in rep.tests], round(rep.margin, 6)
    (True, ['pass', 'pass', 'pass', 'pass'], 1.0)
    >>> rep.to_dict()["tests"]["dissipation"]["verdict"]
    'pass'
    """

    REQUIRED = ("interconnection", "dissipation", "feedthrough", "storage")

    def __init__(self, system, tests, margin: float, box: dict, params: dict, info: dict | None = None):
        self.system = system
        self.tests = list(tests)
        self.margin = float(margin)
        self.box = dict(box)
        self.params = dict(params)
        self.info = dict(info or {})

    @property
    def passive(self) -> bool:
        names = {t.name: t for t in self.tests}
        return (all(t.verdict != "fail" for t in self.tests)
                and all(names[n].verdict == "pass" for n in self.REQUIRED if n in names))

    def __getitem__(self, name: str) -> PassivityTest:
        return find_named(self.tests, name, "test")

    def to_dict(self) -> dict:
        """JSON-ready summary: top-level ``passive`` and ``margin``, one entry per test under ``tests``."""
        from phs._version import __version__

        return _jsonable({
            "system": self.system.name, "model_hash": self.system.model_hash(), "passive": self.passive,
            "margin": self.margin, "box": {k: list(v) for k, v in self.box.items()}, "params": self.params,
            "tests": {t.name: t.to_dict() for t in self.tests},
            "provenance": {"phs_version": __version__, "casadi_version": ca.__version__, **self.info},
        })

    def text(self) -> str:
        head = (f"Passivity of {self.system.name!r} (model {self.system.model_hash()}): "
                f"{'PASSIVE' if self.passive else 'NOT CERTIFIED PASSIVE'}; margin {self.margin:.4g}")
        varied = [k for k in self.box if k not in self.system.state_names]
        box = (f"box: {len(self.system.states)} states" + (f" and parameters {', '.join(varied)}" if varied else "")
               + " (declared ranges unless given); other parameters at their values")
        return "\n".join([head, "  " + box] + [t.line() for t in self.tests])

    def __str__(self) -> str:
        return self.text()

    def __repr__(self) -> str:
        verdicts = ", ".join(f"{t.name}={t.verdict}" for t in self.tests)
        return f"PassivityReport({self.system.name!r}, passive={self.passive}, margin={self.margin:.4g}, {verdicts})"

    _repr_pretty_ = lambda self, p, cycle: p.text(self.text())  # noqa: E731

    def figures(self) -> dict[str, bytes]:
        """PNG figures of the tests that have data to plot, by file name."""
        return _figures(self)

    def write_report(self, directory) -> list[str]:
        """Write ``report.html`` (with the figures inline), ``report.json``, ``report.txt`` and the PNG figures.

        Everything is rendered in memory first and each file is written atomically; the directory is
        created if its parent exists.  Returns the paths written.
        """
        import os

        directory = os.fspath(directory)
        parent = os.path.dirname(os.path.abspath(directory))
        if not os.path.isdir(parent):
            raise InputDataError(f"cannot write the report into {directory!r}: directory {parent!r} does not exist")
        if os.path.exists(directory) and not os.path.isdir(directory):
            raise InputDataError(f"cannot write the report into {directory!r}: it exists and is not a directory")
        figs = self.figures()
        files = {"report.json": json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n",
                 "report.txt": self.text() + "\n", "report.html": _html(self, figs), **figs}
        os.makedirs(directory, exist_ok=True)
        paths = []
        for name, data in files.items():
            path = os.path.join(directory, name)
            write_atomic(path, data)
            paths.append(path)
        return paths


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
    p = system.param_vector(params)
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


# -- numeric machinery of one model (cached per system object, shared by structure) --------------------
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
        _, sv, Vt = np.linalg.svd(S)
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


# -- optimisation over the box ------------------------------------------------------------------------
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


def _valid(model: _Model, box: _Box, X, P) -> np.ndarray:
    g = model.conditions(X, np.repeat(box.u[None, :], len(X), axis=0), P)
    return np.all(np.isfinite(g) & (g >= -1e-12), axis=1) if g.shape[1] else np.ones(len(X), dtype=bool)


def _point(box: _Box, v) -> dict:
    return {n: float(a) for n, a in zip(box.names, v)}


# -- symbolic part ------------------------------------------------------------------------------------
def _sign_violations(system, box: _Box) -> list[str]:
    """Parameters declared positive whose value (or box lower bound) is not: the symbolic proofs do not apply."""
    out = []
    for k, q in enumerate(system.params):
        if not q.positive:
            continue
        v = box.p[k]
        if k in box.pindex:
            v = box.lo[len(system.states) + box.pindex.index(k)]
        if not v > 0:
            out.append(f"{q.name} = {v:g}")
    return out


def _symbolic_dissipation(system, checks, violations):
    """(True/False/None, how): D ⪰ 0 proved symbolically (principal minors of its blocks, or of each resistive
    element's form when they sum to D), refuted, or undecided."""
    from phs.checks import _symbolic_psd

    if violations:
        return None, f"symbolic proof not applicable: declared positive but {', '.join(violations)}"
    item = checks["R positive semidefinite"]
    if item.method == "symbolic":
        return (item.verdict == "pass"), "principal minors of every block are nonnegative for positive parameters"
    if not system.dissipators:
        return None, "undecided symbolically (blocks too large for principal minors)"
    D = system.dissipation_matrix
    total = sp.zeros(*D.shape)
    forms = []
    for label, entries in system.dissipators:
        idx = sorted({i for ij in entries for i in ij})
        M = sp.zeros(len(idx), len(idx))
        for (i, j), v in entries.items():
            a, b = idx.index(i), idx.index(j)
            M[a, b] = M[b, a] = v
            total[i, j] += v
            if i != j:
                total[j, i] += v
        forms.append((label, M))
    if any(sp.expand(e) != 0 for e in (total - D)):
        return None, "undecided symbolically (the resistive elements' forms do not sum to D)"
    for label, M in forms:
        verdict = _symbolic_psd(M)
        if verdict is not True:
            return None, f"undecided symbolically (the form of {label!r} is not provably PSD)"
    return True, f"D is the sum of {len(forms)} resistive elements' forms, each with nonnegative principal minors"


# -- the tests ------------------------------------------------------------------------------------------
def _eig_search(model: _Model, box: _Box, V, Dk, valid, starts, seed, scale: _Scale, deps):
    """Smallest scaled eigenvalue over the sample and from ``nlpsol`` starts: (value, point, direction, sample
    values, optimised end points, runs, converged)."""
    lam, vec = _min_eig(Dk, scale)
    lam = np.where(valid, lam, np.nan)
    ends, ok, runs = _minimise(model, box, "eig", V, lam, starts, seed, deps, scale, vec)
    allV, allL, allW = V, lam, vec
    if len(ends):
        Xe, Pe = box.points(ends, model.nx)
        le, ve = _min_eig(model.D(Xe, Pe), scale)
        le = np.where(_valid(model, box, Xe, Pe), le, np.nan)
        allV, allL, allW = np.concatenate([V, ends]), np.concatenate([lam, le]), np.concatenate([vec, ve])
    if not np.any(np.isfinite(allL)):
        return float("nan"), None, None, lam, ends, runs, ok
    k = int(np.nanargmin(allL))
    return float(allL[k]), allV[k], allW[k], lam, ends, runs, ok


def _dissipation(model: _Model, box: _Box, V, X, P, valid, starts, seed, symbolic, p_own):
    """The dissipation and feedthrough tests and the margin (scaled at the system's own parameter values ``p_own``)."""
    system = model.system
    sym, how = symbolic
    if not model.support:
        t = PassivityTest("dissipation", "pass", "symbolic", "lossless: R = P = S = 0", {"margin": 0.0})
        return t, _feedthrough(model, box, None, None, None), 0.0
    sD, sR = _reference(model, box, p_own)
    Dk = model.D(X, P)
    lamD, worstD, wD, lam, ends, runs, ok = _eig_search(model, box, V, Dk, valid, starts, seed, sD, model.D_deps)
    if worstD is None:
        t = PassivityTest("dissipation", "undecided", "sampled", "D is not finite at any valid point of the box",
                          {"samples": int(len(V)), "valid_samples": int(np.sum(valid))})
        return t, _feedthrough(model, box, None, None, None), float("nan")
    negative = lamD < -EIGENVALUE_TOL or sym is False
    margin, worst, w, scale = lamD, worstD, wD, sD
    if not negative:
        margin = 0.0  # no dissipative state direction: all dissipation is at the ports
        if sR.Q.shape[1]:
            mR, pR, wR, *_ = _eig_search(model, box, V, Dk, valid, starts, seed, sR, model.R_deps)
            if pR is not None:
                margin, worst, w, scale = mR, pR, wR, sR
    Xw, Pw = box.points(worst[None, :], model.nx)
    Dw = model.D(Xw, Pw)[0]
    q = scale.Q @ w                             # direction in scaled support coordinates
    vz = np.zeros(model.nx + model.nu)
    vz[model.support] = q / np.sqrt(scale.d)    # the same direction in z = [dH/dx; u]
    shares = _shares(model, Xw, Pw, vz)
    coords = [model.znames[model.support[i]] for i in np.argsort(-np.abs(q)) if abs(q[i]) >= 0.3 * np.max(np.abs(q))]
    constant = not _closure(model, box, *model.D_deps)[0]
    numbers = {"margin": margin, "full_form_min_eigenvalue": lamD, "full_form_point": _point(box, worstD),
               "min_eigenvalue_unscaled": float(np.linalg.eigvalsh(Dw)[0]),
               "samples": int(len(V)), "valid_samples": int(np.sum(valid)), "sample_minimum": float(np.nanmin(lam)),
               "nlp_starts": runs, "nlp_converged": ok, "structural_null_directions": sD.null,
               "direction": coords, "shares": shares, "unattributed_share": float(float(w @ _scaled(Dw[None], scale)[0] @ w)
                                                                                 - sum(shares.values())),
               "symbolic": {True: "proved", False: "refuted", None: "undecided"}[sym]}
    method = f"{how}; " + (f"D is constant over the box ({len(V)} valid sample points)" if constant else
                           f"sampled {len(V)} valid points of the box and minimised with nlpsol (IPOPT) from {runs} starts")
    series = {"lambda": lam, "V": V, "names": box.names, "ends": ends}
    if negative:
        neg = {k: v for k, v in shares.items() if v < 0}
        element = ", ".join(sorted(neg, key=neg.get)) if neg else "R as given (no resistive element declared for it)"
        bad = _sign_violations(system, box)
        if bad:
            element += f" (declared positive but {', '.join(bad)})"
        summary = (f"[[R, P], [P^T, S]] has a negative eigenvalue: {lamD:.4g} (scaled; unscaled "
                   f"{numbers['min_eigenvalue_unscaled']:.4g}) in the direction of {', '.join(coords)}")
        test = PassivityTest("dissipation", "fail", method, summary, numbers, _point(box, worst), element, series)
    else:
        r_constant = scale is sR and not _closure(model, box, *model.R_deps)[0]
        summary = ("[[R, P], [P^T, S]] ⪰ 0 over the box" + (" (proved symbolically)" if sym else "")
                   + f" (smallest scaled eigenvalue {lamD:.3g}); margin {margin:.4g}: weakest dissipation of R in the "
                   f"direction of {', '.join(coords)}" + (" (R is constant over the box)" if r_constant else ""))
        test = PassivityTest("dissipation", "pass", method, summary, numbers, {} if r_constant else _point(box, worst), "",
                             series)
    return test, _feedthrough(model, box, Dk, valid, sD), margin


def _shares(model: _Model, X, P, vz) -> dict[str, float]:
    """Each resistive element's share ``v^T D_k v`` of the quadratic form in the direction ``vz``."""
    system = model.system
    if not system.dissipators:
        return {}
    vals = np.asarray(model.fdiss(X[0], P[0]), dtype=float).reshape(-1)
    out = {label: 0.0 for label, _ in system.dissipators}
    for (k, i, j), v in zip(model.diss_entries, vals):
        out[system.dissipators[k][0]] += (1.0 if i == j else 2.0) * v * vz[i] * vz[j]
    return out


def _feedthrough(model: _Model, box: _Box, Dk, valid, scale) -> PassivityTest:
    system = model.system
    nx = model.nx
    zero = all(M.is_zero_matrix for M in (system.P, system.S, system.N))
    if zero:
        return PassivityTest("feedthrough", "pass", "symbolic", "no feedthrough (P = S = N = 0): the full-form "
                             "condition reduces to R ⪰ 0", {})
    nskew = all(sp.simplify(e) == 0 for e in (system.N + system.N.T))
    numbers: dict = {"N_skew": bool(nskew)}
    s_idx = [a for a, i in enumerate(model.support) if i >= nx]
    r_idx = [a for a, i in enumerate(model.support) if i < nx]
    s_min = range_res = float("nan")
    if Dk is not None and s_idx:
        w = 1 / np.sqrt(scale.d)
        M = (Dk * np.outer(w, w))[valid]
        M = M[np.all(np.isfinite(M), axis=(1, 2))]
        if len(M):
            Sb = M[:, s_idx][:, :, s_idx]
            s_min = float(np.min(np.linalg.eigvalsh(Sb)[:, 0]))
            if r_idx:
                Pb = M[:, r_idx][:, :, s_idx]
                proj = np.eye(len(s_idx)) - Sb @ np.linalg.pinv(Sb, rcond=1e-10, hermitian=True)
                range_res = float(np.max(np.abs(Pb @ proj)))
    elif not s_idx and any(system.P):
        range_res = float("inf")  # P != 0 with S = 0: [[R, P], [P^T, 0]] is indefinite wherever P is nonzero
    numbers.update({"S_min_scaled_eigenvalue": s_min, "P_range_residual": range_res})
    fails = []
    if not nskew:
        fails.append("N is not skew-symmetric")
    if s_min < -EIGENVALUE_TOL:
        fails.append(f"S has a negative eigenvalue ({s_min:.4g}, scaled)")
    if range_res > 1e-6:
        fails.append(f"P is not in the range of S (residual {range_res:.3g}): [[R, P], [P^T, S]] cannot be PSD")
    if fails:
        return PassivityTest("feedthrough", "fail", "symbolic (N) and sampled (S, P)", "; ".join(fails), numbers,
                             element="feedthrough of " + ", ".join(system.input_names))
    if np.isnan(s_min):
        return PassivityTest("feedthrough", "undecided", "sampled", "S could not be evaluated at a valid point", numbers)
    return PassivityTest("feedthrough", "pass", "symbolic (N) and sampled (S, P)",
                         f"N skew-symmetric, S ⪰ 0 (smallest scaled eigenvalue {s_min:.4g}), P in the range of S "
                         f"(residual {range_res:.2g}); the Schur-complement condition is the dissipation test's", numbers)


def _storage(model: _Model, box: _Box, V, X, P, valid, starts, seed, checks) -> PassivityTest:
    """H bounded below on the box: its minimum over the sample and from ``nlpsol`` starts, with the argmin."""
    system = model.system
    Hs = np.where(valid, model.H(X, P), np.nan)
    units = checks["units"]
    note = "" if units.verdict == "pass" else f"; units: {units.detail}"
    broken = np.flatnonzero(valid & ((Hs == -np.inf) | np.isnan(Hs)))
    finite = np.isfinite(Hs)
    numbers = {"samples": int(len(V)), "valid_samples": int(np.sum(valid))}
    if len(broken) or not np.any(finite):
        at = V[broken[0]] if len(broken) else V[0]
        Xw, Pw = box.points(at[None, :], model.nx)
        terms = model.batch(model.generated.energy_terms, Xw, np.zeros((1, model.nu)), Pw)[0].reshape(-1)
        culprits = [t.label for t, v in zip(system.energy_terms, terms) if not np.isfinite(v) or v == -np.inf]
        return PassivityTest("storage", "fail", f"sampled {len(V)} valid points of the box",
                             f"H is not finite (or -inf) at {len(broken)} valid point(s) of the box{note}", numbers,
                             _point(box, at), "energy term(s) " + ", ".join(culprits or [t.label for t in system.energy_terms]))
    ref = float(np.min(Hs[finite]))
    # objective scale: the spread of the lower quarter of the sample (a stiff wall's energy elsewhere in the box,
    # 2e4 J for the MSD HASEL, would otherwise flatten the objective below IPOPT's tolerance)
    spread = float(np.quantile(Hs[finite] - ref, 0.25))
    hscale = spread if spread > 0 else max(float(np.max(Hs[finite]) - ref), abs(ref), 1e-300)
    ends, ok, runs = _minimise(model, box, "H", V, Hs, starts, seed, model.H_deps, ref=(ref, hscale))
    allV, allH = V[finite], Hs[finite]
    if len(ends):
        Xe, Pe = box.points(ends, model.nx)
        He = np.where(_valid(model, box, Xe, Pe), model.H(Xe, Pe), np.nan)
        keep = np.isfinite(He)
        allV, allH = np.concatenate([allV, ends[keep]]), np.concatenate([allH, He[keep]])
    k = int(np.argmin(allH))
    hmin, argmin = float(allH[k]), allV[k]
    width = box.hi - box.lo
    on_edge = [n for n, v, a, b, w in zip(box.names, argmin, box.lo, box.hi, width) if w > 0 and min(v - a, b - v) <= 1e-6 * w]
    Xw, Pw = box.points(argmin[None, :], model.nx)
    terms = model.batch(model.generated.energy_terms, Xw, np.zeros((1, model.nu)), Pw)[0].reshape(-1)
    numbers.update({"H_min": hmin, "H_max_sampled": float(np.max(Hs[finite])), "nlp_starts": runs, "nlp_converged": ok,
                    "argmin_on_boundary": on_edge,
                    "energy_terms_at_argmin": {t.label: float(v) for t, v in zip(system.energy_terms, terms)}})
    method = f"sampled {len(V)} valid points of the box and minimised with nlpsol (IPOPT) from {runs} starts"
    edge = (f"; the minimum lies on the box boundary in {', '.join(on_edge)} (H may decrease further outside the box)"
            if on_edge else "")
    return PassivityTest("storage", "pass", method,
                         f"H ≥ H_min = {hmin:.6g} J on the box, so H − H_min is a nonnegative storage function{edge}{note}",
                         numbers, _point(box, argmin), "", {"H": Hs, "V": V, "names": box.names, "ends": ends})


# -- the margin alone ------------------------------------------------------------------------------------
def dissipation_margin(system, params: dict | None = None, box: dict | None = None, samples: int = 256,
                       seed: int = 0) -> float:
    """Smallest scaled eigenvalue of ``[[R, P], [P^T, S]]`` over a sample of the box (no optimisation).

    The cheap form of :attr:`PassivityReport.margin` for design sweeps: the sample points (drawn once from
    the valid part of the box at the system's own parameter values) and the generated function of D are
    cached, so each further call is one mapped CasADi evaluation and a batch of small eigenvalue problems.
    The scaling is that of the module docstring (fixed by the system's own parameter values), so the
    margins of variants with different ``params`` compare directly.

    Parameters
    ----------
    system : PHSystem
    params : dict, optional
        Parameter overrides by name.
    box : dict, optional
        ``{name: (lower, upper)}`` for states (default: declared ranges) and parameters to vary.
    samples : int
        Number of sample points.
    seed : int
        Seed of the sample.

    Returns
    -------
    float
        The margin; ``nan`` when no sample point is inside the validity domain at these parameters.

    Raises
    ------
    InputDataError
        For a malformed box (unknown name, lower > upper bound).
    ParameterError
        For an unknown parameter in ``params``.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> msd = mass_spring_damper()
    >>> round(dissipation_margin(msd), 12), round(dissipation_margin(msd, params={"b.b": 0.2}), 12)  # half the damping
    (1.0, 0.5)
    >>> dissipation_margin(msd, params={"b.b": -0.4}) < 0                        # an active damper
    True
    """
    if not isinstance(samples, int) or samples < 1:
        raise InputDataError(f"dissipation_margin: samples must be a positive integer, got {samples!r}")
    model = _model(system)
    b = _resolve_box(system, box, params)
    if not model.support:
        return 0.0
    sD, sR = _reference(model, b, system.param_vector())
    V, _ = _sample(model, b, samples, seed, p=system.param_vector())
    if len(V) == 0:
        return float("nan")
    X, P = b.points(V, model.nx)
    Dk = model.D(X, P)
    valid = _valid(model, b, X, P)
    lamD = np.where(valid, _min_eig(Dk, sD, vectors=False)[0], np.nan)
    if not np.any(np.isfinite(lamD)):
        return float("nan")
    if np.nanmin(lamD) < -EIGENVALUE_TOL or sR.Q.shape[1] == 0:
        return float(min(np.nanmin(lamD), 0.0)) if np.nanmin(lamD) < -EIGENVALUE_TOL else 0.0
    lam = np.where(valid, _min_eig(Dk, sR, vectors=False)[0], np.nan)
    return float(np.nanmin(lam)) if np.any(np.isfinite(lam)) else float("nan")


# -- the dissipation inequality along a trajectory ------------------------------------------------------
def dissipation_inequality(source, t=None, *, u=None, x0=None, params=None, rtol: float = 1e-8) -> PassivityTest:
    """Check ``∫ y^T u dt - (H(t) - H(0)) >= 0`` along a trajectory, with the dissipated energy split per element.

    The supplied energy, the dissipated energy and each resistive element's dissipated energy are
    quadratures of generated CasADi functions integrated by the same CVODES run as the states
    (:class:`codegen.Simulator`); the inequality is checked at every output time.

    Parameters
    ----------
    source : SimulationResult or PHSystem
        A simulation result, or a system to simulate on ``t`` with ``u``, ``x0``, ``params``.
    t : array, optional
        Time grid (required when ``source`` is a system).
    u : dict, signal or array, optional
        Inputs, as for :func:`codegen.simulate` (e.g. a recording's input columns as arrays on ``t``).
    x0 : dict or array, optional
        Initial state.
    params : dict, optional
        Parameter overrides.
    rtol : float
        Relative tolerance of the simulation.

    Returns
    -------
    PassivityTest
        Named ``trajectory``; ``numbers`` holds the energies at the final time (``supplied``,
        ``stored`` = H(T) - H(0), ``dissipated``, ``dissipated_by`` per element, ``unattributed``), the
        smallest slack ``min_t [E_supplied(t) - (H(t) - H(0))]`` absolute and relative to the energy
        exchanged, the relative error of the per-element split and the energy-balance error.

    Raises
    ------
    InputDataError
        When ``source`` is a system and ``t`` is missing (and for malformed inputs, from the simulator).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rlc_circuit
    >>> test = dissipation_inequality(rlc_circuit(), np.linspace(0, 2e-3, 201), u={"U": 1.0})
    >>> test.verdict, sorted(test.numbers["dissipated_by"])
    ('pass', ['R'])
    >>> abs(test.numbers["supplied"] - test.numbers["stored"] - test.numbers["dissipated"]) < 1e-6 * test.numbers["supplied"]
    True
    """
    from codegen.results import SimulationResult
    from codegen.simulator import simulate

    if isinstance(source, SimulationResult):
        res = source
    else:
        if t is None:
            raise InputDataError("dissipation_inequality: give the time grid t to simulate the system on")
        res = simulate(source, t, u=u, x0=x0, params=params, rtol=rtol)
    s = res.system
    q = res.quadratures or {}
    labels = [label for label, _ in s.dissipators]
    if "E_supplied" in q:
        Es, Ed = np.asarray(q["E_supplied"]), np.asarray(q["E_dissipated"])
        parts = {label: np.asarray(q[f"E_dissipated[{label}]"]) for label in labels}
        method = "energy accounts integrated as quadratures by the simulation's CVODES run"
    else:
        def cum(f):
            return np.concatenate([[0.0], np.cumsum(np.diff(res.t) * (f[1:] + f[:-1]) / 2)])

        Es, Ed = cum(res.supplied), cum(res.dissipated)
        parts = {label: cum(v) for label, v in res.dissipator_powers.items()}
        method = "energy accounts by the trapezoidal rule on the output grid"
    dH = res.H - res.H[0]
    slack = Es - dH
    scale = max(float(np.max(np.abs(Es))), float(np.max(np.abs(dH))), float(np.max(np.abs(Ed))), 1e-300)
    split = np.sum(list(parts.values()), axis=0) if parts else np.zeros_like(Ed)
    unattributed = Ed - split
    split_error = float(np.max(np.abs(unattributed)) / max(float(np.max(np.abs(Ed))), 1e-300)) if parts else float("nan")
    balance = float(np.max(np.abs(dH - (Es - Ed))) / scale)
    k = int(np.argmin(slack[1:])) + 1 if len(slack) > 1 else 0  # the slack is 0 at the start
    numbers = {"T": float(res.t[-1] - res.t[0]), "supplied": float(Es[-1]), "stored": float(dH[-1]),
               "dissipated": float(Ed[-1]), "dissipated_by": {label: float(v[-1]) for label, v in parts.items()},
               "unattributed": float(unattributed[-1]), "split_relative_error": split_error,
               "balance_error": balance, "min_slack": float(slack[k]), "min_slack_relative": float(slack[k] / scale),
               "min_slack_time": float(res.t[k])}
    worst = {"t": float(res.t[k]), **{n: float(v) for n, v in zip(s.state_names, res.x[k])}}
    series = {"t": res.t, "supplied": Es, "stored": dH, "dissipated": Ed, "parts": parts, "unattributed": unattributed}
    if balance > 1e-3:
        return PassivityTest("trajectory", "undecided", method,
                             f"the simulation's energy balance error {balance:.3g} is too large to decide (tighten rtol)",
                             numbers, worst, "", series)
    tol = max(ENERGY_TOL, 2 * balance)  # a violation below the run's own balance error cannot be told from it
    numbers["tolerance_relative"] = tol
    if slack[k] < -tol * scale:
        negative = {label: float(v[k]) for label, v in parts.items() if v[k] < 0}
        element = ", ".join(sorted(negative, key=negative.get)) if negative else "unattributed dissipation (R as given)"
        return PassivityTest("trajectory", "fail", method,
                             f"the dissipation inequality is violated: supplied − stored energy = {slack[k]:.4g} J "
                             f"< 0 at t = {res.t[k]:.6g} s (dissipated {Ed[k]:.4g} J)", numbers, worst, element, series)
    top = max(parts, key=lambda n: parts[n][-1]) if parts else ""
    worst = {}  # the slack's minimum of a passing run is its start, not a point worth reporting
    return PassivityTest("trajectory", "pass", method,
                         f"∫ yᵀu dt − ΔH ≥ 0 over [0, {numbers['T']:.6g}] s: supplied {Es[-1]:.6g} J = stored {dH[-1]:.6g} J "
                         f"+ dissipated {Ed[-1]:.6g} J" + (f" (largest: {top}, {parts[top][-1]:.4g} J; per-element split "
                                                           f"error {split_error:.2g})" if parts else ""),
                         numbers, worst, top, series)


# -- local passivity at an equilibrium ------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LocalPassivity:
    """Passivity of the linearisation at an equilibrium (see :func:`local_passivity`).

    Attributes
    ----------
    statespace : control.StateSpace
        The linearisation in reduced, scaled and balanced state coordinates ``z`` (``δx = T z``);
        inputs and outputs in the model's units.
    T : ndarray
        Map from ``z`` to the state deviation ``δx`` (n x r).
    removed : int
        Conserved directions of J removed before linearising (Casimirs).
    eigenvalues : ndarray
        Eigenvalues of the reduced state matrix.
    stability : str
        ``stable``, ``marginal`` or ``unstable``.
    input_index, output_index : float
        Input-feedforward index ``ν = inf_ω λ_min(He G(jω))`` and output-feedback index
        ``ρ = inf_ω λ_min(He G(jω)^-1)``: ``y^T u >= dV/dt + ν |u|^2`` and ``>= dV/dt + ρ |y|^2``.
    units : tuple of str
        Units of ν and ρ.
    verdict : str
        ``pass``, ``fail`` or ``undecided``.
    details : dict
        Frequencies, the Hamiltonian-matrix verification and its conditioning, the storage-function
        (Hessian of H) KYP residual and, where cvxopt is installed, python-control's LMI indices.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> loc = local_passivity(mass_spring_damper(b=0.4), u_eq={"F": 1.0})
    >>> loc.verdict, round(loc.output_index, 6), abs(loc.input_index) < 1e-9   # rho = b, nu = 0
    ('pass', 0.4, True)
    """

    system_name: str
    x_eq: dict
    u_eq: dict
    statespace: object
    T: np.ndarray
    removed: int
    eigenvalues: np.ndarray
    stability: str
    input_index: float
    output_index: float
    units: tuple
    verdict: str
    summary: str
    details: dict = field(default_factory=dict)
    element: str = ""

    def test(self) -> PassivityTest:
        """This result as the ``local`` test of a :class:`PassivityReport`."""
        d = self.details
        numbers = {"input_index": self.input_index, "output_index": self.output_index,
                   "input_index_unit": self.units[0], "output_index_unit": self.units[1],
                   "stability": self.stability, "spectral_abscissa": float(np.max(self.eigenvalues.real))
                   if len(self.eigenvalues) else 0.0, "states_after_reduction": int(self.T.shape[1]),
                   "conserved_directions_removed": self.removed, "u_eq": self.u_eq,
                   **{k: v for k, v in d.items() if k not in ("omega", "nu_curve", "rho_curve")}}
        return PassivityTest("local", self.verdict, d.get("method", ""), self.summary, numbers, dict(self.x_eq),
                             self.element, {k: d[k] for k in ("omega", "nu_curve", "rho_curve") if k in d})


def _conserved(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Orthonormal conserved directions (in scaled states x / s) of ``x' = M(x) [...]``: the left null space of
    ``diag(1/s) M``, columns equilibrated so only structural dependences fall below the threshold."""
    Ms = M / s[:, None]
    cn = np.linalg.norm(Ms, axis=0)
    Ms = Ms[:, cn > 0] / cn[cn > 0]
    if Ms.shape[1] == 0:
        return np.eye(len(s))
    U, sv, _ = np.linalg.svd(Ms)
    r = int(np.sum(sv > 1e-12 * sv[0])) if sv.size and sv[0] > 0 else 0
    return U[:, r:]


def _frequency_response(A, B, C, D, w) -> np.ndarray:
    n = A.shape[0]
    if n == 0:
        return np.repeat(D[None, :, :].astype(complex), len(w), axis=0)
    M = 1j * np.asarray(w)[:, None, None] * np.eye(n)[None] - A[None]
    X = np.linalg.solve(M, np.repeat(B[None].astype(complex), len(w), axis=0))
    return C[None] @ X + D[None]


def _nu_of(G) -> np.ndarray:
    He = (G + np.conj(np.swapaxes(G, -1, -2))) / 2
    return np.linalg.eigvalsh(He)[..., 0]


def _rho_of(G, floor: float = 0.0) -> np.ndarray:
    """Largest ρ with ``He G - ρ G^H G ⪰ 0`` at each frequency: ``λ_min(Σ_r^-1 V_r^H He(G) V_r Σ_r^-1)`` on the
    range of ``G^H`` (SVD ``G = U Σ V^H``, rank r); -inf where He G couples the null space of G to the rest."""
    out = np.full(G.shape[0], np.inf)
    for k, Gk in enumerate(G):
        if not np.all(np.isfinite(Gk)):
            continue
        _, sv, Vh = np.linalg.svd(Gk)
        r = int(np.sum(sv > 1e-10 * sv[0])) if sv.size and sv[0] > floor else 0
        if r == 0:  # G(jω) = 0 (to rounding): no constraint on ρ at this frequency
            continue
        He = (Gk + Gk.conj().T) / 2
        V = Vh.conj().T
        if r < len(sv):
            Vn = V[:, r:]
            if np.max(np.abs(He @ Vn)) > 1e-9 * sv[0]:
                out[k] = -np.inf
                continue
        Vr = V[:, :r] / sv[:r][None, :]
        out[k] = np.linalg.eigvalsh(Vr.conj().T @ He @ Vr)[0]
    return out


def _hamiltonian_crossings(A, B, C, D, Mq) -> tuple[np.ndarray, dict]:
    """Frequencies where the Popov function ``[G; I]^H Mq [G; I]`` is singular: imaginary eigenvalues of its
    Hamiltonian matrix (Mq on (y, u); its (u, u) block must make the value at infinity positive definite)."""
    m = B.shape[1]
    Ch = np.vstack([C, np.zeros((m, C.shape[1]))])
    Dh = np.vstack([D, np.eye(m)])
    Qx, Sx, Rx = Ch.T @ Mq @ Ch, Ch.T @ Mq @ Dh, Dh.T @ Mq @ Dh
    Rx = (Rx + Rx.T) / 2
    Ri = np.linalg.inv(Rx)
    F = A - B @ Ri @ Sx.T
    Hm = np.block([[F, -B @ Ri @ B.T], [-Qx + Sx @ Ri @ Sx.T, -F.T]])
    lam = np.linalg.eigvals(Hm)
    # on the axis: a real part within 1e-8 of the eigenvalue's own size, or within the rounding of the eigenvalue
    # problem (1e3 eps |H|); relative to its own size, a slow mode of a stiff model is not mistaken for a crossing
    floor = 1e3 * np.finfo(float).eps * max(float(np.linalg.norm(Hm, 1)), 1e-300)
    on_axis = np.abs(lam.real) <= 1e-8 * np.abs(lam) + floor
    dist = np.abs(lam.real) / np.maximum(np.abs(lam), floor)
    crossings = np.unique(np.abs(lam.imag[on_axis]))
    return crossings, {"cond_Rx": float(np.linalg.cond(Rx)), "axis_distance": float(np.min(dist)) if dist.size else 1.0}


def _index_sweep(fun, A, B, C, D, w):
    """Infimum of ``fun(G(jω))`` over the grid ``w`` (and ω = ∞, and ω = 0), refined around the lowest points."""
    vals = fun(_frequency_response(A, B, C, D, w))
    best_w, best = float(w[int(np.argmin(vals))]), float(np.min(vals))
    for i in np.argsort(vals)[:3]:
        a, b = w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)]
        if not (0 < a < b):
            continue
        r = scipy.optimize.minimize_scalar(lambda lw: float(fun(_frequency_response(A, B, C, D, np.array([np.exp(lw)])))[0]),
                                           bounds=(np.log(a), np.log(b)), method="bounded", options={"xatol": 1e-6})
        if r.fun < best:
            best, best_w = float(r.fun), float(np.exp(r.x))
    vinf = float(fun(D[None].astype(complex))[0]) if np.all(np.isfinite(D)) else np.inf
    if vinf < best:
        best, best_w = vinf, np.inf
    return best, best_w, vals


def _lti(model: _Model, x, u, p):
    """Linearisation at (x, u): scaled, reduced by the conserved directions, balanced."""
    system = model.system
    A, B, C, D, Hs, M, _ = (np.asarray(v, dtype=float) for v in model.flin(x, u, p))
    n, m = model.nx, model.nu
    A, B, C, D = A.reshape(n, n), B.reshape(n, m), C.reshape(m, n), D.reshape(m, m)
    s = np.array([st.typical for st in system.states])
    W = _conserved(M.reshape(n, -1), s)
    if W.shape[1]:
        Vr = scipy.linalg.null_space(W.T)
    else:
        Vr = np.eye(n)
    As = A * s[None, :] / s[:, None]
    Ar, Br, Cr = Vr.T @ As @ Vr, Vr.T @ (B / s[:, None]), (C * s[None, :]) @ Vr
    leak = float(np.linalg.norm(W.T @ As) / max(np.linalg.norm(As), 1e-300)) if W.shape[1] else 0.0
    if Ar.size:
        _, (sc, perm) = scipy.linalg.matrix_balance(Ar, permute=False, separate=True)
    else:
        sc = np.ones(0)
    Tb = np.diag(sc)
    Ab, Bb, Cb = Ar * sc[None, :] / sc[:, None], Br / sc[:, None], Cr * sc[None, :]
    Pz = Vr.T @ (Hs.reshape(n, n) * np.outer(s, s)) @ Vr
    Pb = Pz * np.outer(sc, sc)
    T = (s[:, None] * Vr) @ Tb
    return Ab, Bb, Cb, D, Pb, T, W.shape[1], {"conserved_leak": leak, "cond_balancing": float(np.max(sc) / np.min(sc))
                                               if sc.size else 1.0}


def _cvxopt_available() -> bool:
    try:
        import control.passivity as cp
    except ImportError:  # pragma: no cover - python-control is a dependency
        return False
    return cp.cvx is not None


def _units_of(system) -> tuple[str, str]:
    ins = {i.unit for i in system.inputs}
    outs = {i.output_unit for i in system.inputs}
    if len(ins) == 1 and len(outs) == 1:
        a, b = ins.pop(), outs.pop()
        return f"{b}/{a}", f"{a}/{b}"
    return "[y]/[u]", "[u]/[y]"


def local_passivity(system, x_eq=None, u_eq=None, *, params=None, x0=None, frequencies: int = 600,
                    cross_check: bool | None = None) -> LocalPassivity:
    """Passivity indices of the linearisation of ``system`` at an equilibrium.

    The linearisation ``δx' = A δx + B δu``, ``δy = C δx + D δu`` is taken at ``(x_eq, u_eq)`` with the
    generated Jacobians, in scaled states ``x / s``; the conserved directions of J (the left null space of
    ``[J - R, G - P]``: Casimirs such as the curling HASEL's top-film length, one per segment) are removed
    first, since they only add zero eigenvalues; the rest is balanced.  Then, with ``G(s)`` its transfer
    matrix:

    * the input-feedforward index ``ν = inf_ω λ_min(He G(jω))`` and the output-feedback index
      ``ρ = inf_ω λ_min(He G(jω)^-1)`` from a log-spaced frequency sweep (refined around its minima, plus
      ω = ∞), each verified by the imaginary-axis eigenvalues of the Hamiltonian matrix of the Popov function
      at the index minus a small margin (an LMI-free KYP test; its conditioning is reported);
    * the storage-function test: whether ``V = ½ δxᵀ ∇²H δx`` satisfies the KYP inequality (exact for a
      port-Hamiltonian linearisation);
    * where cvxopt is installed, python-control's LMI indices (``get_input_ff_index``,
      ``get_output_fb_index``) on the same scaled model, for comparison.

    The verdict is ``pass`` for a stable linearisation with ``ν >= 0`` (to 1e-8 of the gain) or when the
    storage function certifies it, ``fail`` for an unstable one or ``ν < 0``, else ``undecided``.

    Parameters
    ----------
    system : PHSystem
    x_eq : dict, array or EquilibriumResult, optional
        The equilibrium state; checked (an :class:`EquilibriumError` names a state that moves).  Default:
        solved with :func:`phs.equilibrium` under ``u_eq`` from ``x0``.
    u_eq : dict or float, optional
        Constant input at the equilibrium (default zero).
    params : dict, optional
        Parameter overrides.
    x0 : dict, optional
        Starting point of the equilibrium solver (fixes the conserved quantities).
    frequencies : int
        Number of frequencies of the sweep.
    cross_check : bool, optional
        Compare with python-control's LMI: ``None`` when cvxopt is installed, ``True`` requires it.

    Returns
    -------
    LocalPassivity

    Raises
    ------
    EquilibriumError
        When ``x_eq`` is not an equilibrium (or none is found).
    InputDataError
        For unknown state or input names, or ``cross_check=True`` without cvxopt.

    Examples
    --------
    >>> from systems.examples import rlc_circuit
    >>> loc = local_passivity(rlc_circuit(R=10.0), cross_check=False)
    >>> loc.verdict, round(loc.output_index, 6), loc.units                  # rho = R
    ('pass', 10.0, ('A/V', 'V/A'))
    """
    import control

    model = _model(system)
    p = system.param_vector(params)
    x, uv, how = _equilibrium_point(system, model, x_eq, u_eq, p, params, x0)
    x_named = dict(zip(system.state_names, map(float, x)))
    u_named = dict(zip(system.input_names, map(float, uv)))
    unit_nu, unit_rho = _units_of(system)
    if not system.inputs:
        return LocalPassivity(system.name, x_named, u_named, None, np.zeros((len(x), 0)), 0, np.zeros(0), "stable",
                              float("nan"), float("nan"), (unit_nu, unit_rho), "undecided",
                              "the system has no ports: passivity is not defined", {"method": how})
    if cross_check and not _cvxopt_available():
        raise InputDataError("local_passivity: cross_check=True needs cvxopt (pip install cvxopt)")
    A, B, C, D, Pb, T, removed, cond = _lti(model, x, uv, p)
    ss = control.ss(A, B, C, D)
    lam = np.linalg.eigvals(A) if A.size else np.zeros(0)
    lam_scale = float(np.max(np.abs(lam))) if lam.size else 0.0
    alpha = float(np.max(lam.real)) if lam.size else -np.inf
    tol_eig = 1e-11 * max(lam_scale, 1e-300)  # eigenvalue errors of the balanced matrix: ~1e-16 of its norm
    stability = "unstable" if alpha > tol_eig else ("marginal" if alpha >= -tol_eig else "stable")
    nz = np.abs(lam[np.abs(lam) > tol_eig])
    lo_w = max(float(np.min(nz)) / 1e3, 1e-12) if nz.size else 1e-3
    hi_w = float(np.max(nz)) * 1e3 if nz.size else 1e3
    w = np.unique(np.concatenate([np.logspace(np.log10(lo_w), np.log10(hi_w), frequencies),
                                  np.abs(lam.imag[np.abs(lam.imag) > 0])]))
    details: dict = {"method": how, **cond}
    gain = max(float(np.max(np.linalg.norm(_frequency_response(A, B, C, D, w), ord=2, axis=(1, 2)))), 1e-300)

    def rho_of(G):
        return _rho_of(G, 1e-12 * gain)

    nu, w_nu, nu_curve = _index_sweep(_nu_of, A, B, C, D, w)
    rho, w_rho, rho_curve = _index_sweep(rho_of, A, B, C, D, w)
    if stability == "stable" and np.linalg.cond(A) < 1e14:
        G_0 = (C @ np.linalg.solve(-A, B) + D)[None]
        nu, w_nu = (float(_nu_of(G_0)[0]), 0.0) if _nu_of(G_0)[0] < nu else (nu, w_nu)
        rho, w_rho = (float(rho_of(G_0)[0]), 0.0) if rho_of(G_0)[0] < rho else (rho, w_rho)
    details.update({"omega": w, "nu_curve": nu_curve, "rho_curve": rho_curve, "nu_frequency": w_nu,
                    "rho_frequency": w_rho, "gain": gain, "eigenvalue_spread": float(np.max(nz) / np.min(nz)) if nz.size else 1.0})
    m = B.shape[1]
    # LMI-free KYP verification: no imaginary-axis eigenvalue of the Popov Hamiltonian just below the index
    if stability == "stable":
        delta = 1e-6 * gain
        verified = False
        info = {}
        for _ in range(5):
            Mq = np.block([[np.zeros((m, m)), np.eye(m) / 2], [np.eye(m) / 2, -(nu - delta) * np.eye(m)]])
            try:
                cross, info = _hamiltonian_crossings(A, B, C, D, Mq)
            except np.linalg.LinAlgError:
                break
            cross = cross[cross > 0]
            if not cross.size:
                verified = True
                break
            extra = _nu_of(_frequency_response(A, B, C, D, cross))
            if np.min(extra) >= nu:  # crossings the sweep cannot confirm: report, do not loop
                break
            nu, w_nu = float(np.min(extra)), float(cross[int(np.argmin(extra))])
        details["hamiltonian_nu"] = {"verified": verified, "margin": delta, **info}
        if np.isfinite(rho):
            drho = 1e-6 * max(abs(rho), 1 / gain)
            Mq = np.block([[-(rho - drho) * np.eye(m), np.eye(m) / 2], [np.eye(m) / 2, 1e-6 * gain * np.eye(m)]])
            try:
                cross, info = _hamiltonian_crossings(A, B, C, D, Mq)
                details["hamiltonian_rho"] = {"verified": not np.any(cross > 0), "margin": drho, **info}
            except np.linalg.LinAlgError:
                details["hamiltonian_rho"] = {"verified": False}
    # storage function V = 1/2 dx^T Hess(H) dx in the KYP inequality
    K = np.block([[A.T @ Pb + Pb @ A, Pb @ B - C.T], [B.T @ Pb - C, -(D + D.T)]])
    kscale = max(np.linalg.norm(A.T @ Pb + Pb @ A), np.linalg.norm(Pb @ B) + np.linalg.norm(C), np.linalg.norm(D + D.T), 1e-300)
    kyp = float(np.max(np.linalg.eigvalsh((K + K.T) / 2)) / kscale) if K.size else 0.0
    pmin = float(np.min(np.linalg.eigvalsh(Pb)) / max(np.linalg.norm(Pb), 1e-300)) if Pb.size else 0.0
    storage_ok = kyp <= 1e-9 and pmin >= -1e-9
    details["storage_kyp"] = {"max_eigenvalue_relative": kyp, "min_eigenvalue_hessian_relative": pmin, "certifies": storage_ok}
    if cross_check is not False and _cvxopt_available():
        details["lmi"] = _lmi_indices(ss, nu, rho, gain)
    tol_nu = 1e-8 * gain
    element = ""
    if stability == "unstable":
        k = int(np.argmax(lam.real))
        vec = np.abs(T @ np.linalg.eig(A)[1][:, k]) / np.array([st.typical for st in system.states])
        names = [system.state_names[i] for i in np.argsort(-vec)[:3]]
        verdict, element = "fail", "unstable mode in " + ", ".join(names)
        summary = f"the linearisation is unstable (eigenvalue {lam[k]:.4g} 1/s): not passive with a positive storage"
    elif stability == "stable" and nu >= -tol_nu:
        verdict = "pass"
        summary = f"passive: input index ν = {nu:.4g} {unit_nu}, output index ρ = {rho:.4g} {unit_rho}"
    elif nu < -tol_nu:
        verdict = "fail"
        Gw = _frequency_response(A, B, C, D, np.array([w_nu if np.isfinite(w_nu) else 1e300]))[0]
        v = np.linalg.eigh((Gw + Gw.conj().T) / 2)[1][:, 0]
        element = "port " + ", ".join(system.input_names[i] for i in np.argsort(-np.abs(v))[:2] if abs(v[i]) > 0.3)
        summary = (f"not passive: He G(jω) has eigenvalue {nu:.4g} {unit_nu} < 0 at ω = {w_nu:.4g} rad/s "
                   f"(output index ρ = {rho:.4g} {unit_rho})")
    elif storage_ok:
        verdict = "pass"
        summary = f"passive (storage ½ δxᵀ∇²H δx satisfies the KYP inequality); ν = {nu:.4g} {unit_nu}, ρ = {rho:.4g} {unit_rho}"
    else:
        verdict = "undecided"
        summary = (f"eigenvalues on the imaginary axis and the Hessian of H is no KYP storage: ν = {nu:.4g} {unit_nu} "
                   f"away from the poles")
    details["method"] = (f"{how}; linearised with generated Jacobians, {removed} conserved direction(s) removed, scaled and "
                         f"balanced; frequency sweep ({len(w)} points) verified by the Popov Hamiltonian matrix"
                         + ("; python-control LMI (cvxopt) for comparison" if "lmi" in details else ""))
    return LocalPassivity(system.name, x_named, u_named, ss, T, removed, lam, stability, float(nu), float(rho),
                          (unit_nu, unit_rho), verdict, summary, details, element)


def _lmi_indices(ss, nu, rho, gain) -> dict:
    """python-control's LMI passivity indices (cvxopt) on the same scaled model, and whether they agree."""
    import control

    out: dict = {}
    for key, fn in (("input_index", control.get_input_ff_index), ("output_index", control.get_output_fb_index)):
        try:
            out[key] = float(fn(ss))
        except Exception as exc:  # the LMI solver's own failures are part of the comparison
            out[key] = None
            out[f"{key}_error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}"
    try:
        out["ispassive"] = bool(control.ispassive(ss))
    except Exception as exc:
        out["ispassive"] = None
        out["ispassive_error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0][:160] if str(exc) else ''}"
    agree = []
    if out.get("input_index") is not None:
        agree.append(abs(out["input_index"] - nu) <= 1e-4 * gain + 1e-6 * abs(nu))
    if out.get("output_index") is not None and np.isfinite(rho):
        agree.append(abs(out["output_index"] - rho) <= 1e-4 * max(abs(rho), 1 / gain))
    out["agree"] = bool(agree) and all(agree)
    return out


def _equilibrium_point(system, model: _Model, x_eq, u_eq, p, params, x0):
    """(x, u, how) of an equilibrium given as a result, a claimed state (checked) or solved for."""
    from phs.equilibria import EquilibriumResult, equilibrium

    names, inames = system.state_names, system.input_names
    uvec = np.zeros(len(inames))
    if isinstance(u_eq, dict):
        for k, v in u_eq.items():
            if k not in inames:
                raise InputDataError(f"equilibrium input: system {system.name!r} has no input {k!r} "
                                     f"(inputs: {', '.join(inames) or 'none'})")
            uvec[inames.index(k)] = _finite(v, f"equilibrium input {k!r}")
    elif u_eq is not None:
        arr = np.atleast_1d(np.asarray(u_eq, dtype=float))
        if arr.shape != uvec.shape:
            raise InputDataError(f"equilibrium input: expected {len(inames)} value(s), got {arr.size}")
        uvec = arr.astype(float)
    if isinstance(x_eq, EquilibriumResult):
        return np.asarray(x_eq.x, dtype=float), np.asarray(x_eq.u, dtype=float), "equilibrium given as a solver result"
    if x_eq is None:
        eq = equilibrium(system, u=dict(zip(inames, uvec)), x0=x0, params=params)
        return eq.x, uvec, f"equilibrium solved for u = {_fmt_point(dict(zip(inames, uvec))) or 'none'}"
    x = np.array([min(max(0.0, st.range[0]), st.range[1]) for st in system.states])
    if isinstance(x_eq, dict):
        for k, v in x_eq.items():
            if k not in names:
                raise InputDataError(f"equilibrium: system {system.name!r} has no state {k!r} "
                                     f"(states: {', '.join(names)})")
            x[names.index(k)] = _finite(v, f"equilibrium state {k!r}")
        given = x_eq
    else:
        arr = np.asarray(x_eq, dtype=float).reshape(-1)
        if arr.shape != x.shape:
            raise InputDataError(f"equilibrium: expected {len(names)} state values, got {arr.size}")
        x = arr
        given = dict(zip(names, map(float, arr)))
    _check_equilibrium(system, model, x, uvec, p, given)
    return x, uvec, "equilibrium given and checked"


def _finite(v, what) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputDataError(f"{what}: {v!r} is not a number") from None
    if not math.isfinite(f):
        raise InputDataError(f"{what}: {v!r} is not finite")
    return f


def _check_equilibrium(system, model: _Model, x, u, p, given: dict) -> None:
    A, *_, xdot = (np.asarray(v, dtype=float) for v in model.flin(x, u, p))
    n = len(x)
    s = np.array([st.typical for st in system.states])
    ctx = (f"{_fmt_point(given)}: not an equilibrium of {system.name!r} under "
           f"{_fmt_point(dict(zip(system.input_names, u))) or 'zero input'}")
    if system.conditions:
        g = model.conditions(x[None, :], u[None, :], p[None, :])[0]
        bad = [c.label for c, v in zip(system.conditions, g) if not v >= -1e-12]
        if bad:
            raise EquilibriumError(f"equilibrium {ctx}: the state is outside the validity domain ({'; '.join(bad)})")
    xdot = xdot.reshape(-1)
    As = A.reshape(n, n) * s[None, :] / s[:, None]
    r = np.abs(xdot) / s
    rel = r / max(float(np.linalg.norm(As, 2)), 1e-300)
    if not np.all(np.isfinite(xdot)):
        raise EquilibriumError(f"equilibrium {ctx}: the dynamics are not finite there")
    if np.max(rel) > EQUILIBRIUM_TOL:
        i = int(np.argmax(rel))
        st = system.states[i]
        raise EquilibriumError(
            f"equilibrium {ctx}: the rate of {st.name} is {xdot[i]:.4g} ({st.unit})/s (scaled residual {rel[i]:.3g} > "
            f"{EQUILIBRIUM_TOL:g}); give only the inputs to have the equilibrium solved for")


# -- the certificate ------------------------------------------------------------------------------------
def certify(system, *, box: dict | None = None, params: dict | None = None, equilibrium=None, u=None, x0=None,
            trajectory=None, samples: int = 2000, starts: int = 8, seed: int = 0) -> PassivityReport:
    """Certify that ``system`` is passive over a box of states (and parameters), and say where it is not.

    Runs the tests of the module docstring: ``interconnection``, ``dissipation`` (the margin),
    ``feedthrough``, ``storage``, and, when asked, ``trajectory`` and ``local``.

    Parameters
    ----------
    system : PHSystem
    box : dict, optional
        ``{name: (lower, upper)}``: states default to their declared ranges; parameters named here are varied
        over the given bounds (``None``: their declared range), the others stay at their values.
    params : dict, optional
        Parameter overrides by name (e.g. fitted values); they need not satisfy the parameters' declared sign
        (a negative resistance is reported, not refused).
    equilibrium : dict, array, EquilibriumResult or True, optional
        Adds the ``local`` test at this equilibrium: a claimed state (``{name: value}``, checked), a solver
        result, or True to solve for it under ``u`` from ``x0``.
    u : dict or float, optional
        Constant input at the equilibrium (implies ``equilibrium=True`` when that is not given).
    x0 : dict, optional
        Starting point of the equilibrium solver (fixes the conserved quantities, e.g. the curling HASEL's
        ``seg{i}.l_p``).
    trajectory : SimulationResult or dict, optional
        Adds the ``trajectory`` test: a simulation result, or ``{"t": ..., "u": ..., "x0": ...}`` to simulate
        (``u`` may hold a recording's input columns as arrays on ``t``).
    samples : int
        Points of the dense sample of the box.
    starts : int
        Starts of each ``nlpsol`` minimisation (the best half of the sample and random others).
    seed : int
        Seed of the sample and of the random starts.

    Returns
    -------
    PassivityReport

    Raises
    ------
    InputDataError
        For a malformed box (unknown name, lower > upper bound, non-finite bound) or trajectory.
    ParameterError
        For an unknown parameter in ``params``.
    EquilibriumError
        When the equilibrium given is not one, or none is found.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> rep = certify(rc_circuit(), params={"R.R": -1e3}, samples=64, starts=1)   # a negative resistor
    >>> rep.passive, rep["dissipation"].verdict, rep["dissipation"].element
    (False, 'fail', 'R (declared positive but R.R = -1000)')
    >>> certify(rc_circuit(), box={"C.Q": (1e-6, -1e-6)})
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: box 'C.Q': lower bound 1e-06 > upper bound -1e-06
    """
    from phs.checks import check_system

    wall = time.perf_counter()
    for name, v in (("samples", samples), ("starts", starts)):
        if not isinstance(v, int) or isinstance(v, bool) or v < (1 if name == "samples" else 0):
            raise InputDataError(f"certify: {name} must be a {'positive' if name == 'samples' else 'nonnegative'} "
                                 f"integer, got {v!r}")
    b = _resolve_box(system, box, params)
    model = _model(system)
    checks = check_system(system, samples=16, seed=seed)
    violations = _sign_violations(system, b)
    symbolic = _symbolic_dissipation(system, checks, violations)
    local = None
    if equilibrium is not None or u is not None:
        local = local_passivity(system, None if equilibrium is True else equilibrium, u, params=params, x0=x0)
    traj = None
    if trajectory is not None:
        traj = _trajectory(system, trajectory, params)
    V, info = _sample(model, b, samples, seed)
    tests = [_interconnection(system, checks)]
    if len(V) == 0:
        why = "no point of the box satisfies the validity conditions " + "; ".join(info.get("empty", []))
        tests += [PassivityTest(n, "undecided", "sampled", why) for n in ("dissipation", "feedthrough", "storage")]
        margin = float("nan")
    else:
        X, P = b.points(V, model.nx)
        valid = _valid(model, b, X, P)
        V, X, P, valid = V[valid], X[valid], P[valid], valid[valid]
        if len(V) == 0:
            why = "no sampled point is inside the validity domain at these parameter values"
            tests += [PassivityTest(n, "undecided", "sampled", why) for n in ("dissipation", "feedthrough", "storage")]
            margin = float("nan")
        else:
            dtest, ftest, margin = _dissipation(model, b, V, X, P, valid, starts, seed, symbolic, system.param_vector())
            tests += [dtest, ftest, _storage(model, b, V, X, P, valid, starts, seed, checks)]
    if traj is not None:
        tests.append(traj)
    if local is not None:
        tests.append(local.test())
    info = {"samples": samples, "starts": starts, "seed": seed, "seconds": time.perf_counter() - wall,
            "sampling": info.get("groups", [])}
    return PassivityReport(system, tests, margin, b.as_dict(), dict(zip(system.param_names, map(float, b.p))), info)


def _interconnection(system, checks) -> PassivityTest:
    item = checks["J skew-symmetric"]
    nskew = all(sp.simplify(e) == 0 for e in (system.N + system.N.T))
    verdict = "pass" if item.verdict == "pass" and nskew else "fail"
    return PassivityTest("interconnection", verdict, "symbolic",
                         "J(x) + J(x)^T and N + N^T simplify to zero: the interconnection is power-preserving"
                         if verdict == "pass" else f"{item.detail}; N skew: {nskew}")


def _trajectory(system, trajectory, params) -> PassivityTest:
    from codegen.results import SimulationResult

    if isinstance(trajectory, SimulationResult):
        if trajectory.system.model_hash() != system.model_hash():
            raise InputDataError(f"trajectory: the simulation result is of {trajectory.system.name!r}, not {system.name!r}")
        return dissipation_inequality(trajectory)
    if not isinstance(trajectory, dict):
        raise InputDataError("trajectory: give a SimulationResult or a dict with 't' (and 'u', 'x0')")
    unknown = set(trajectory) - {"t", "u", "x0", "rtol"}
    if unknown:
        raise InputDataError(f"trajectory: unknown key(s) {sorted(unknown)}; use 't', 'u', 'x0', 'rtol'")
    if "t" not in trajectory:
        raise InputDataError("trajectory: the dict needs the time grid 't'")
    return dissipation_inequality(system, trajectory["t"], u=trajectory.get("u"), x0=trajectory.get("x0"),
                                  params=params, rtol=trajectory.get("rtol", 1e-8))


# -- output ---------------------------------------------------------------------------------------------
def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, complex):
        return [obj.real, obj.imag]
    return obj


def _fmt_point(point: dict) -> str:
    return ", ".join(f"{k}={v:.6g}" if isinstance(v, (float, int, np.floating)) else f"{k}={v}" for k, v in point.items())


def _figures(report: PassivityReport) -> dict[str, bytes]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = {}
    for t in report.tests:
        if not t.series:
            continue
        fig = Figure(figsize=(9, 3.4), constrained_layout=True)
        FigureCanvasAgg(fig)
        if t.name in ("dissipation", "storage"):
            plot_box(t, fig)
        elif t.name == "trajectory":
            plot_energy(t, fig)
        elif t.name == "local":
            plot_local(t, fig)
        else:
            continue
        fig.suptitle(f"{report.system.name}: {t.name} ({t.verdict})")
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        out[f"{t.name}.png"] = buf.getvalue()
    return out


def plot_box(test: PassivityTest, fig):
    """Plot a box test (``dissipation`` or ``storage``): the sampled values against the most influential
    variable, and sorted, with the optimised points; returns the figure.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from systems.examples import mass_spring_damper
    >>> rep = certify(mass_spring_damper(), samples=32, starts=1)
    >>> len(plot_box(rep["storage"], Figure()).axes)
    2
    """
    key = "lambda" if test.name == "dissipation" else "H"
    vals, V, names = test.series[key], test.series["V"], test.series["names"]
    ok = np.isfinite(vals)
    corr = [abs(np.corrcoef(V[ok, j], vals[ok])[0, 1]) if np.ptp(V[ok, j]) > 0 and np.ptp(vals[ok]) > 0 else 0.0
            for j in range(V.shape[1])]
    j = int(np.argmax(np.nan_to_num(corr)))
    ax1, ax2 = fig.subplots(1, 2)
    neg = ok & (vals < 0) if key == "lambda" else np.zeros_like(ok)
    ax1.scatter(V[ok & ~neg, j], vals[ok & ~neg], s=6, alpha=0.5, label="samples")
    if np.any(neg):
        ax1.scatter(V[neg, j], vals[neg], s=6, color="tab:red", label="negative")
    if key == "lambda":
        wx, wv = test.numbers.get("full_form_point", {}).get(names[j]), test.numbers.get("full_form_min_eigenvalue")
    else:
        wx, wv = test.worst.get(names[j]), test.numbers.get("H_min")
    if wx is not None and wv is not None:
        ax1.plot([wx], [wv], "kx", ms=10, mew=2, label="worst point" if key == "lambda" else "argmin")
    ax1.set_xlabel(names[j])
    ax1.set_ylabel("smallest scaled eigenvalue of D" if key == "lambda" else "H [J]")
    if key == "lambda":
        ax1.axhline(0.0, color="k", lw=0.6)
    ax1.legend(fontsize=7)
    srt = np.sort(vals[ok])
    ax2.plot(np.arange(len(srt)) / max(len(srt) - 1, 1), srt)
    if wv is not None:
        ax2.axhline(wv, color="k", ls=":", lw=0.8, label="optimised minimum")
        ax2.legend(fontsize=7)
    ax2.set_xlabel("fraction of the valid sample")
    ax2.set_ylabel("sorted values")
    return fig


def plot_energy(test: PassivityTest, fig):
    """Plot the energy accounts of a ``trajectory`` test: supplied, stored, dissipated, the split per element
    and the slack of the dissipation inequality; returns the figure.

    Examples
    --------
    >>> import numpy as np
    >>> from matplotlib.figure import Figure
    >>> from systems.examples import rc_circuit
    >>> test = dissipation_inequality(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0})
    >>> len(plot_energy(test, Figure()).axes)
    2
    """
    s = test.series
    t = s["t"]
    ax1, ax2 = fig.subplots(1, 2)
    ax1.plot(t, s["supplied"], label="supplied ∫yᵀu dt")
    ax1.plot(t, s["stored"], label="stored H − H(0)")
    ax1.plot(t, s["dissipated"], label="dissipated")
    ax1.plot(t, s["supplied"] - s["stored"], "k:", label="supplied − stored")
    ax1.set_xlabel("t [s]")
    ax1.set_ylabel("energy [J]")
    ax1.legend(fontsize=7)
    parts = s["parts"]
    if parts:
        order = sorted(parts, key=lambda n: -abs(parts[n][-1]))
        shown = order[:7]
        curves = [parts[n] for n in shown]
        labels = list(shown)
        if len(order) > 7:
            curves.append(np.sum([parts[n] for n in order[7:]], axis=0))
            labels.append(f"{len(order) - 7} others")
        if all(np.all(c >= -1e-12 * max(1.0, float(np.max(np.abs(c))))) for c in curves):
            ax2.stackplot(t, *curves, labels=labels, alpha=0.8)  # the top of the stack is the total
        else:
            for c, lab in zip(curves, labels):
                ax2.plot(t, c, label=lab)
            ax2.axhline(0.0, color="k", lw=0.6)
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("dissipated per element [J]")
    ax2.legend(fontsize=7)
    return fig


def plot_local(test: PassivityTest, fig):
    """Plot a ``local`` test: ``λ_min(He G(jω))`` and ``λ_min(He G(jω)^-1)`` against ω with the indices.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from systems.examples import rlc_circuit
    >>> test = local_passivity(rlc_circuit(), cross_check=False).test()
    >>> len(plot_local(test, Figure()).axes)
    2
    """
    s = test.series
    w = s["omega"]
    ax1, ax2 = fig.subplots(1, 2)
    ax1.semilogx(w, s["nu_curve"])
    ax1.axhline(test.numbers["input_index"], color="k", ls=":", label=f"ν = {test.numbers['input_index']:.4g}")
    ax1.set_xlabel("ω [rad/s]")
    ax1.set_ylabel(f"λ_min He G(jω) [{test.numbers['input_index_unit']}]")
    ax1.legend(fontsize=7)
    rho = np.where(np.isfinite(s["rho_curve"]), s["rho_curve"], np.nan)
    ax2.semilogx(w, rho)
    ax2.axhline(test.numbers["output_index"], color="k", ls=":", label=f"ρ = {test.numbers['output_index']:.4g}")
    ax2.set_xlabel("ω [rad/s]")
    ax2.set_ylabel(f"λ_min He G(jω)⁻¹ [{test.numbers['output_index_unit']}]")
    ax2.legend(fontsize=7)
    return fig


def _html(report: PassivityReport, figs: dict[str, bytes]) -> str:
    esc = html.escape
    rows = []
    for t in report.tests:
        color = {"pass": "#2a7", "fail": "#c33", "undecided": "#c90"}[t.verdict]
        rows.append(f"<tr><td>{esc(t.name)}</td><td style='color:{color};font-weight:bold'>{t.verdict}</td>"
                    f"<td>{esc(t.summary)}</td><td>{esc(t.element)}</td><td>{esc(_fmt_point(t.worst))}</td>"
                    f"<td>{esc(t.method)}</td></tr>")
    imgs = "".join(f"<h2>{esc(n[:-4])}</h2><img alt='{esc(n)}' src='data:image/png;base64,"
                   f"{base64.b64encode(png).decode()}'/>" for n, png in figs.items())
    verdict = "PASSIVE" if report.passive else "NOT CERTIFIED PASSIVE"
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Passivity of {esc(report.system.name)}</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{border:1px solid #ccc;padding:4px;vertical-align:top}"
            "table{border-collapse:collapse}</style></head><body>"
            f"<h1>Passivity of {esc(report.system.name)}: {verdict}</h1>"
            f"<p>model hash {esc(report.system.model_hash())}; margin {report.margin:.4g} (smallest scaled eigenvalue "
            f"of [[R, P], [P^T, S]] over the box)</p>"
            "<table><tr><th>test</th><th>verdict</th><th>numbers</th><th>element</th><th>worst point</th><th>method</th></tr>"
            + "".join(rows) + "</table>" + imgs
            + f"<h2>JSON</h2><pre>{esc(json.dumps(report.to_dict(), indent=1))}</pre></body></html>\n")
