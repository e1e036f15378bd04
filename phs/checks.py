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

from phs._budget import MAX_TERMS, affordable, expanded_terms, is_zero, mp_values, scaled_block
from phs._results import ResultMixin, draw_verdicts, finish, panels, require_pandas
from phs._sparse import nonzero_entries
from phs.errors import UnitError
from phs.storage_bound import bounded_below
from phs.structure_units import structure_unit_problems
from phs.units import DIMENSIONLESS, JOULE, dimension, format_dim, parse_unit


@dataclass(frozen=True)
class CheckItem:
    """One check: its verdict (``pass``, ``fail``, ``undecided``), method and numbers."""

    name: str
    verdict: str
    method: str
    detail: str
    worst: dict = field(default_factory=dict)


@dataclass(frozen=True, repr=False)
class CheckReport(ResultMixin):
    """Readable report of :meth:`PHSystem.check`; ``ok`` is False if any check failed.

    ``bool(report)`` is ``report.ok`` (an undecided check does not make it False); ``report["units"]`` is
    one :class:`CheckItem`; ``str(report)`` is the full text, ``repr`` one line; :meth:`plot` draws one
    coloured row per check and :meth:`to_pandas` gives one row per check.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> rep = rc_circuit().check()
    >>> bool(rep), rep  # doctest: +ELLIPSIS
    (True, CheckReport('rc', ok: ... pass))
    """

    system: str
    items: tuple[CheckItem, ...]

    @property
    def ok(self) -> bool:
        return all(i.verdict != "fail" for i in self.items)

    def __bool__(self) -> bool:
        return self.ok

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

    def _headline(self) -> str:
        counts = {v: sum(i.verdict == v for i in self.items) for v in ("pass", "fail", "undecided")}
        return (f"{self.system!r}, {'ok' if self.ok else 'FAILED'}: "
                + ", ".join(f"{n} {v}" for v, n in counts.items() if n))

    def _table(self) -> tuple[list, list]:
        return ["check", "verdict", "method", "detail"], [(i.name, i.verdict, i.method, i.detail) for i in self.items]

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """One row per check (verdict, method, detail), indexed by the check's name.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> rc_circuit().check().to_pandas().loc["units", "verdict"]  # doctest: +SKIP
        'pass'
        """
        pd = require_pandas("CheckReport.to_pandas()")
        header, rows = self._table()
        return pd.DataFrame({c: [r[k] for r in rows] for k, c in enumerate(header[1:], start=1)},
                            index=pd.Index([r[0] for r in rows], name="check"))

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """One coloured row per check: green pass, red fail, amber undecided, with its detail.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes, optional
            Draw into this axes.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> fig = rc_circuit().check().plot()
        >>> fig.axes[0].texts[0].get_text()[:22]
        'J skew-symmetric: pass'
        """
        fig, grid = panels(ax, 1, figsize=(9, 0.4 * len(self.items) + 0.9), what="CheckReport.plot")
        draw_verdicts(grid[0, 0], [(i.name, i.verdict, i.detail) for i in self.items],
                      title=f"structural checks of {self.system}: {'all passed' if self.ok else 'FAILED'}")
        return finish(fig, path)


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
    fc = system.lambdify([c.expr for c in system.conditions]) if system.conditions else None
    worst, nonfinite, outside = None, [], 0
    pnames = [s.name for s in system.states]
    for x, p in _points(system, k, seed, with_params):
        point = dict(zip(pnames, x))
        if with_params:
            point.update(dict(zip(system.param_names, p)))
        if fc is not None:
            with np.errstate(all="ignore"):
                c = np.asarray(fc(x, zero_u, p), dtype=float)
            if not np.all(c >= 0):
                outside += 1  # outside the validity domain: the model says nothing there
                continue
        with np.errstate(all="ignore"):
            vals = np.asarray(f(x, zero_u, p), dtype=float).reshape(-1)
        scaled = set()
        if not np.all(np.isfinite(vals)):
            # inf - inf in floating point: evaluate again with mpmath, and scale each block by its largest entry
            mp = mp_values(exprs, system.x + system.u + system.p, [*x, *zero_u, *p])
            undefined = [k for k, v in enumerate(mp) if not v == v or abs(v) == float("inf")]
            if undefined:
                i, j = entries[undefined[0]]
                nonfinite.append({"entry": _entry_name(system, i, j), "point": point})
                continue
            vals = np.array(vals)
            for nb in range(len(blocks)):
                ks = [k for k, w in enumerate(where) if w[0] == nb]
                if not np.all(np.isfinite(vals[ks])):
                    vals[ks] = scaled_block([mp[k] for k in ks])[0]
                    scaled.add(nb)
        mats = [np.zeros((len(b), len(b))) for b in blocks]
        for (nb, a, c), v in zip(where, vals):
            mats[nb][a, c] = mats[nb][c, a] = v
        for nb, (b, Mb) in enumerate(zip(blocks, mats)):
            ev = np.linalg.eigvalsh(Mb)
            scale = float(np.max(np.abs(ev))) if len(ev) else 1.0
            if worst is None or ev[0] / max(scale, 1e-300) < worst["min_eig"] / max(worst["scale"], 1e-300):
                worst = {"min_eig": float(ev[0]), "scale": scale, "point": point,
                         "block": [_zname(system, i) for i in b], "mpmath": nb in scaled,
                         "entry": _negative_entry(system, b, Mb)}
    if worst is None and (nonfinite or outside):
        worst = {"min_eig": float("nan"), "scale": 1.0, "point": nonfinite[0]["point"] if nonfinite else {},
                 "block": [], "mpmath": False, "entry": ""}
    if worst is not None:
        worst.update(nonfinite=nonfinite, outside=outside)
    return worst


def _entry_name(system, i: int, j: int) -> str:
    """``R[i,j]`` (or P, S) of the dissipation matrix, with the resistive elements acting on it."""
    n = len(system.states)
    name = "R" if i < n and j < n else "S" if i >= n and j >= n else "P"
    a, b = (i if i < n else i - n), (j if j < n else j - n)
    if name == "P" and i >= n:
        a, b = j, i - n
    labels = [lab for lab, ent in system.dissipators if (min(i, j), max(i, j)) in ent]
    return f"{name}[{a},{b}]" + (f" ({', '.join(map(repr, labels))})" if labels else "")


def _negative_entry(system, b, Mb) -> str:
    """The most negative diagonal entry of a block, named (the usual culprit of a negative eigenvalue)."""
    d = np.diag(Mb)
    if not len(d) or d.min() >= 0:
        return ""
    a = int(np.argmin(d))
    return _entry_name(system, b[a], b[a])


def _zname(system, i: int) -> str:
    n = len(system.states)
    return system.states[i].name if i < n else system.inputs[i - n].name


def _symbolic_psd(Mb: sp.Matrix) -> bool | None:
    """True if every principal minor is provably >= 0 under the symbols' assumptions (None: undecided)."""
    return _symbolic_psd_why(Mb)[0]


def _symbolic_psd_why(Mb: sp.Matrix) -> tuple[bool | None, str]:
    """:func:`_symbolic_psd` and, when undecided, why: too large, or a minor over the symbolic budget."""
    k = Mb.rows
    if k > 5:
        return None, f"block of {k} too large for principal minors"
    if not affordable(Mb):
        return None, "an entry is over the symbolic budget"
    for r in range(1, k + 1):
        for idx in itertools.combinations(range(k), r):
            minor = Mb.extract(list(idx), list(idx)).det(method="berkowitz")
            if minor.free_symbols:
                if expanded_terms(minor) > 2 * MAX_TERMS:
                    return None, f"a {r}x{r} principal minor is over the symbolic budget ({MAX_TERMS} terms)"
                minor = sp.factor(sp.expand(minor))
            nn = minor.is_nonnegative
            if nn is None:
                nn = sp.expand(minor).is_nonnegative
            if nn is not True:
                return (None, "a principal minor is not provably nonnegative") if nn is None else (False, "")
    return True, ""


def _differs(system, a, b, what: str, sampled: dict, k: int = 8) -> bool:
    """Whether ``a != b`` identically: symbolic within the budget, else at ``k`` sampled points (noted in ``sampled``)."""
    z = is_zero(a - b)
    if z is not None:
        return not z
    args = system.x + system.u + system.p
    pts = system.sample_box(k, seed=0)
    zero_u, pv = [0.0] * len(system.u), list(system.param_vector())
    defined = 0
    for x in pts:
        va, vb = mp_values([a, b], args, [*x, *zero_u, *pv])
        if not (va == va and vb == vb):
            continue  # undefined here: no evidence either way
        defined += 1
        if abs(va - vb) > 1e-9 * max(abs(va), abs(vb), 1e-300):
            return True
    note = (f"equal at {defined} of {k} sampled points" if defined else f"undefined at all {k} sampled points: not decided")
    if not defined or what not in sampled:  # an undecided entry outweighs a decided one
        sampled[what] = f"{what} over the symbolic budget ({MAX_TERMS} terms): {note}"
    return False


def structure_problems(system, problems: list[str]) -> dict[str, str]:
    """Add to ``problems`` what makes ``system`` no port-Hamiltonian system (used by its constructor).

    J and N skew, [[R, P], [P^T, S]] symmetric: decided symbolically within the budget of
    :mod:`phs._budget`, else at sampled points; then the dissipation matrix at 8 sampled points of the
    declared ranges (mpmath where floats overflow): a negative eigenvalue is a problem, and so is an
    entry undefined at every sampled point inside the validity domain.  Returns ``{check: note}`` for
    the checks decided by sampling.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> problems = []
    >>> structure_problems(rc_circuit(), problems), problems
    ({}, [])
    """
    sampled: dict[str, str] = {}

    def pairs(M):
        return sorted({(min(i, j), max(i, j)) for (i, j) in M.todok() if i != j})

    names = system.state_names + system.input_names
    J, D, N = system.J, system.dissipation_matrix, system.N
    for i, j in pairs(J):
        if _differs(system, J[i, j], -J[j, i], "J skew-symmetric", sampled):
            total = J[i, j] + J[j, i]
            shown = sp.simplify(total) if affordable(total) else "not zero at a sampled point"
            problems.append(f"J is not skew-symmetric: J[{i},{j}] + J[{j},{i}] = {shown} ({names[i]}, {names[j]})")
    for i in range(len(system.states)):
        if J[i, i] != 0 and _differs(system, J[i, i], sp.Integer(0), "J skew-symmetric", sampled):
            problems.append(f"J is not skew-symmetric: J[{i},{i}] = {J[i, i]} ({names[i]})")
    for i, j in pairs(D):
        if _differs(system, D[i, j], D[j, i], "R symmetric", sampled):
            problems.append(f"R (with P, S) is not symmetric at entry ({i},{j}) ({names[i]}, {names[j]})")
    for i, j in pairs(N):
        if _differs(system, N[i, j], -N[j, i], "J skew-symmetric", sampled):
            problems.append(f"N is not skew-symmetric at entry ({i},{j})")
    if problems:
        return sampled
    worst = _psd_samples(system, k=8, seed=0)
    if worst is None:
        return sampled
    if worst["min_eig"] < -1e-9 * max(1.0, worst["scale"]):
        culprit = f": {worst['entry']} is negative there" if worst["entry"] else ""
        how = " (evaluated with mpmath: it overflows in floating point)" if worst["mpmath"] else ""
        problems.append(
            f"R is not positive semidefinite: eigenvalue {worst['min_eig']:.3g} of [[R, P], [P^T, S]] in the block of "
            + ", ".join(worst["block"]) + system._psd_culprits(worst["block"]) + culprit + how + " at "
            + ", ".join(f"{k}={v:.4g}" for k, v in worst["point"].items()))
    elif worst["nonfinite"] and worst["min_eig"] != worst["min_eig"]:
        first = worst["nonfinite"][0]
        problems.append(f"dissipation entry {first['entry']} is not finite at any of the 8 sampled points inside the "
                        "validity domain (first at " + ", ".join(f"{k}={v:.4g}" for k, v in first["point"].items())
                        + "): nothing shows it is positive semidefinite")
    return sampled


def check_system(system, samples: int = 200, seed: int = 0) -> CheckReport:
    """Run every structural check on ``system``; see :meth:`PHSystem.check`."""
    items: list[CheckItem] = []
    sampled = dict(getattr(system, "_sampled_structure", {}))
    for name, what in (("J skew-symmetric", "J + J^T simplifies to zero"),
                       ("R symmetric", "[[R, P], [P^T, S]] equals its transpose")):
        if name in sampled:
            verdict = "undecided" if sampled[name].endswith("not decided") else "pass"
            items.append(CheckItem(name, verdict, "sampled (over the symbolic budget)", sampled[name]))
        else:
            items.append(CheckItem(name, "pass", "symbolic", what))

    D = system.dissipation_matrix
    blocks = _blocks(D)
    undecided, failed, why = [], [], []
    for b in blocks:
        verdict, reason = _symbolic_psd_why(D.extract(b, b))
        if verdict is None:
            undecided.append(b)
            if "budget" in reason:
                why.append(f"block {', '.join(_zname(system, i) for i in b)}: {reason}")
        elif verdict is False:
            failed.append(b)
    if not undecided and not failed:
        items.append(CheckItem("R positive semidefinite", "pass", "symbolic",
                               f"all principal minors of {len(blocks)} block(s) are nonnegative for positive parameters"))
    else:
        items.append(_sampled_psd_item(system, samples, seed, undecided + failed, why))

    # H bounded below: symbolic where possible, else minimised over the state box and followed outward
    bound = bounded_below(system, samples=samples, seed=seed)
    items.append(CheckItem("H bounded below", bound.verdict, bound.method, bound.detail, bound.point))

    # units: the energy terms, then every entry of the structure, the ports and the measured outputs
    try:
        problems = unit_problems(system)
        structural, skipped = structure_unit_problems(system)
        problems += structural
    except UnitError as exc:
        problems, skipped = [str(exc)], 0
    note = f" ({skipped} entries resting on constants without a declared unit skipped)" if skipped else ""
    items.append(CheckItem("units", "fail" if problems else "pass", "dimensional analysis",
                           "; ".join(problems) if problems else "every energy term is in joules; J, R, G, P, S, N, "
                           f"the ports and the measured outputs agree with the states' and ports' units{note}"))

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


def _sampled_psd_item(system, samples: int, seed: int, blocks, why: list[str]) -> CheckItem:
    """The PSD check decided by sampling: a negative eigenvalue fails, a non-finite sample is no pass."""
    worst = _psd_samples(system, k=samples, seed=seed, with_params=True, blocks=blocks)
    method = f"sampled ({samples} points)" + (f"; symbolic decision refused: {'; '.join(why)}" if why else "")
    name = "R positive semidefinite"
    if worst is None or (worst["min_eig"] != worst["min_eig"] and not worst["nonfinite"]):
        return CheckItem(name, "undecided", method, "no sample point inside the validity domain")
    point = {k: float(v) for k, v in worst["point"].items()}
    if worst["min_eig"] < -1e-9 * max(worst["scale"], 1e-300):
        culprit = f": {worst['entry']} is negative there" if worst["entry"] else ""
        how = " (overflows in floating point: evaluated with mpmath, block scaled by its largest entry)" \
            if worst["mpmath"] else ""
        return CheckItem(name, "fail", method, f"smallest eigenvalue {worst['min_eig']:.4g} (block "
                         f"{', '.join(worst['block'])}){culprit}{how}", point)
    if worst["nonfinite"]:
        first = worst["nonfinite"][0]
        at = ", ".join(f"{k}={v:.4g}" for k, v in first["point"].items())
        return CheckItem(name, "undecided", method, f"{first['entry']} is not finite (even with mpmath) at "
                         f"{len(worst['nonfinite'])} of {samples} sampled points, first at {at}: no evidence there",
                         {k: float(v) for k, v in first["point"].items()})
    return CheckItem(name, "pass", method, f"smallest eigenvalue {worst['min_eig']:.4g} (block "
                     f"{', '.join(worst['block'])})", point)


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
