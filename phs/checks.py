"""Structural checks of a PHSystem: skew J, PSD dissipation, H bounded below, units.

Each property is decided symbolically where sympy can (J + J^T simplifies to
zero; every principal minor of a dissipation block is a sum of products of
positive parameters) and otherwise sampled over the declared ranges of
states and parameters, with the worst point reported.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from phs._sparse import nonzero_entries
from phs.errors import UnitError
from phs.storage_bound import bounded_below
from phs.units import DIMENSIONLESS, JOULE, dimension, format_dim, parse_unit


@dataclass(frozen=True)
class CheckItem:
    """One check: its verdict (``pass``, ``fail``, ``undecided``), method and numbers."""

    name: str
    verdict: str
    method: str
    detail: str
    worst: dict = field(default_factory=dict)


@dataclass(frozen=True)
class CheckReport:
    """Readable report of :meth:`PHSystem.check`; ``ok`` is False if any check failed."""

    system: str
    items: tuple[CheckItem, ...]

    @property
    def ok(self) -> bool:
        return all(i.verdict != "fail" for i in self.items)

    def __getitem__(self, name: str) -> CheckItem:
        for i in self.items:
            if i.name == name:
                return i
        raise KeyError(name)

    def to_dict(self) -> dict:
        return {
            "system": self.system,
            "ok": self.ok,
            "checks": [
                {"name": i.name, "verdict": i.verdict, "method": i.method, "detail": i.detail, "worst": i.worst}
                for i in self.items
            ],
        }

    def __str__(self) -> str:
        lines = [f"Structural checks of {self.system!r}: {'all passed' if self.ok else 'FAILED'}"]
        for i in self.items:
            lines.append(f"  [{i.verdict:^9}] {i.name} ({i.method}): {i.detail}")
        return "\n".join(lines)

    _repr_pretty_ = lambda self, p, cycle: p.text(str(self))  # noqa: E731


def _blocks(M: sp.Matrix) -> list[list[int]]:
    """Index groups of the connected components of the nonzero pattern of a symmetric matrix."""
    n = M.rows
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    entries = nonzero_entries(M)
    for i, j, _ in entries:
        if j > i:
            parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in sorted({i for i, _, _ in entries}):
        groups.setdefault(find(i), []).append(i)
    return list(groups.values())


def _points(system, k: int, seed: int, with_params: bool):
    pts = system.sample_box(k, seed=seed, params=with_params)
    nx = len(system.states)
    pv = system.param_vector()
    # first point: parameter values themselves, states at mid-range
    for row in pts:
        x = row[:nx]
        p = row[nx:] if with_params else pv
        yield x, p


def _psd_samples(system, k: int = 8, seed: int = 0, with_params: bool = False, blocks=None):
    """Smallest eigenvalue of the dissipation matrix over sampled points (None if no block)."""
    D = system.dissipation_matrix
    blocks = blocks if blocks is not None else _blocks(D)
    if not blocks:
        return None
    # the upper triangle of each block, row by row (the blocks are components: no entry leaves its block)
    row_entries: dict[int, list[tuple[int, sp.Expr]]] = {}
    for i, j, v in nonzero_entries(D):
        if j >= i:
            row_entries.setdefault(i, []).append((j, v))
    members = [set(b) for b in blocks]
    entries, exprs, where = [], [], []  # (i, j), D[i, j], (block, row in block, column in block)
    for nb, b in enumerate(blocks):
        pos = {i: a for a, i in enumerate(b)}
        for i in b:
            for j, v in row_entries.get(i, ()):
                if j in members[nb]:
                    entries.append((i, j))
                    exprs.append(v)
                    where.append((nb, pos[i], pos[j]))
    zero_u = [0.0] * len(system.inputs)
    f = system._lambdify(exprs, True, plain_names=True)
    worst = None
    for x, p in _points(system, k, seed, with_params):
        with np.errstate(all="ignore"):
            vals = np.asarray(f(x, zero_u, p), dtype=float).reshape(-1)
        if not np.all(np.isfinite(vals)):
            continue
        mats = [np.zeros((len(b), len(b))) for b in blocks]
        for (nb, a, c), v in zip(where, vals):
            mats[nb][a, c] = mats[nb][c, a] = v
        for b, Mb in zip(blocks, mats):
            ev = np.linalg.eigvalsh(Mb)
            scale = float(np.max(np.abs(ev))) if len(ev) else 1.0
            if worst is None or ev[0] / max(scale, 1e-300) < worst["min_eig"] / max(worst["scale"], 1e-300):
                pnames = [s.name for s in system.states]
                point = dict(zip(pnames, x))
                if with_params:
                    point.update(dict(zip(system.param_names, p)))
                worst = {"min_eig": float(ev[0]), "scale": scale, "point": point, "block": [_zname(system, i) for i in b]}
    return worst


def _zname(system, i: int) -> str:
    n = len(system.states)
    return system.states[i].name if i < n else system.inputs[i - n].name


def _symbolic_psd(Mb: sp.Matrix) -> bool | None:
    """True if every principal minor is provably >= 0 under the symbols' assumptions."""
    k = Mb.rows
    if k > 5:
        return None
    for r in range(1, k + 1):
        for idx in itertools.combinations(range(k), r):
            minor = Mb.extract(list(idx), list(idx)).det(method="berkowitz")
            minor = sp.factor(sp.expand(minor)) if minor.free_symbols else minor
            nn = minor.is_nonnegative
            if nn is None:
                nn = sp.expand(minor).is_nonnegative
            if nn is not True:
                return None if nn is None else False
    return True


def check_system(system, samples: int = 200, seed: int = 0) -> CheckReport:
    """Run every structural check on ``system``; see :meth:`PHSystem.check`."""
    items: list[CheckItem] = []
    items.append(CheckItem("J skew-symmetric", "pass", "symbolic", "J + J^T simplifies to zero"))
    items.append(CheckItem("R symmetric", "pass", "symbolic", "[[R, P], [P^T, S]] equals its transpose"))

    D = system.dissipation_matrix
    blocks = _blocks(D)
    undecided = []
    failed = []
    for b in blocks:
        verdict = _symbolic_psd(D.extract(b, b))
        if verdict is None:
            undecided.append(b)
        elif verdict is False:
            failed.append(b)
    if not undecided and not failed:
        items.append(CheckItem("R positive semidefinite", "pass", "symbolic",
                               f"all principal minors of {len(blocks)} block(s) are nonnegative for positive parameters"))
    else:
        worst = _psd_samples(system, k=samples, seed=seed, with_params=True, blocks=undecided + failed)
        if worst is None:
            items.append(CheckItem("R positive semidefinite", "undecided", "sampled", "no sample point inside the domain"))
        else:
            bad = worst["min_eig"] < -1e-9 * max(worst["scale"], 1e-300)
            items.append(CheckItem(
                "R positive semidefinite", "fail" if bad else "pass", f"sampled ({samples} points)",
                f"smallest eigenvalue {worst['min_eig']:.4g} (block {', '.join(worst['block'])})",
                {k: float(v) for k, v in worst["point"].items()},
            ))

    # H bounded below: symbolic where possible, else minimised over the state box and followed outward
    bound = bounded_below(system, samples=samples, seed=seed)
    items.append(CheckItem("H bounded below", bound.verdict, bound.method, bound.detail, bound.point))

    # units
    try:
        problems = unit_problems(system)
    except UnitError as exc:
        problems = [str(exc)]
    items.append(CheckItem("units", "fail" if problems else "pass", "dimensional analysis",
                           "; ".join(problems) if problems else "every energy term is in joules"))

    # validity domain coverage
    if system.conditions:
        zero_u, pv = [0.0] * len(system.inputs), system.param_vector()
        fc = system.lambdify([c.expr for c in system.conditions])
        inside = 0
        total = 0
        for x, _ in _points(system, samples, seed, False):
            with np.errstate(all="ignore"):
                v = np.asarray(fc(x, zero_u, pv), dtype=float)
            total += 1
            inside += bool(np.all(v >= 0))
        items.append(CheckItem("validity domain", "pass", f"sampled ({samples} points)",
                               f"{inside}/{total} sampled states satisfy all {len(system.conditions)} conditions"))
    return CheckReport(system.name, tuple(items))


def unit_problems(system) -> list[str]:
    """Energy terms whose dimension is not energy, each named with its component."""
    units = {s.symbol: parse_unit(s.unit, f"state {s.name!r}") for s in system.states}
    units.update({q.symbol: parse_unit(q.unit, f"parameter {q.name!r}") for q in system.params})
    units.update({u.symbol: parse_unit(u.unit, f"input {u.name!r}") for u in system.inputs})
    out = []
    for t in system.energy_terms:
        try:
            d = dimension(t.expr, units)
        except UnitError as exc:
            out.append(f"energy term of {t.label!r}: {exc}")
            continue
        if d != JOULE and not (d == DIMENSIONLESS and t.expr == 0):
            out.append(f"energy term of {t.label!r} is in {format_dim(d)}, not joules")
    return out
