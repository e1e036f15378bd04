"""Block-triangular symbolic solution of sparse linear equation systems.

The junction structure of a model gives many small linear equations in port
variables.  Solving them all at once with sympy would blow up; instead the
equations are matched to unknowns (maximum bipartite matching), ordered into
strongly connected blocks (block lower triangular form) and each small block
is solved on its own with the solutions of earlier blocks substituted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, maximum_bipartite_matching


@dataclass
class StructuralProblem(Exception):
    """Raised when the equations are not uniquely solvable; carries the culprits."""

    kind: str  # "overdetermined", "underdetermined", "singular", "nonlinear"
    equations: list[int]
    unknowns: list[sp.Symbol]


def solve_blt(equations: list[sp.Expr], unknowns: list[sp.Symbol]) -> dict[sp.Symbol, sp.Expr]:
    """Solve ``equations == 0`` (linear in ``unknowns``) block by block.

    Returns a mapping unknown -> expression free of unknowns.

    Raises
    ------
    StructuralProblem
        Naming the equations (indices) or unknowns that make the system
        over- or under-determined, or a block singular.

    Examples
    --------
    >>> a, b, k = sp.symbols("a b k")
    >>> sol = solve_blt([a - 2 * b, b - k], [a, b])
    >>> sol[a]
    2*k
    """
    n_eq, n_un = len(equations), len(unknowns)
    index = {u: j for j, u in enumerate(unknowns)}
    uset = set(unknowns)
    rows, cols = [], []
    incid: list[list[int]] = []
    for i, eq in enumerate(equations):
        js = sorted(index[s] for s in eq.free_symbols & uset)
        incid.append(js)
        rows += [i] * len(js)
        cols += js
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_eq, n_un))
    match_col = maximum_bipartite_matching(graph, perm_type="column")  # eq -> unknown
    eq_of = np.full(n_un, -1)
    for i, j in enumerate(match_col):
        if j >= 0:
            eq_of[j] = i
    unmatched_eq = [i for i in range(n_eq) if match_col[i] < 0]
    if unmatched_eq:
        raise StructuralProblem("overdetermined", _alternating(unmatched_eq, incid, match_col, eq_of), [])
    unmatched_un = [unknowns[j] for j in range(n_un) if eq_of[j] < 0]
    if unmatched_un:
        raise StructuralProblem("underdetermined", [], unmatched_un)

    # dependency graph between equations: i -> eq_of[j] for unknowns j in eq i
    r2, c2 = [], []
    for i, js in enumerate(incid):
        for j in js:
            k = eq_of[j]
            if k != i:
                r2.append(i)
                c2.append(k)
    dep = csr_matrix((np.ones(len(r2)), (r2, c2)), shape=(n_eq, n_eq))
    n_comp, labels = connected_components(dep, directed=True, connection="strong")
    blocks: list[list[int]] = [[] for _ in range(n_comp)]
    for i, lab in enumerate(labels):
        blocks[lab].append(i)
    order = _topological(blocks, labels, dep)

    sol: dict[sp.Symbol, sp.Expr] = {}
    for b in order:
        eqs = blocks[b]
        unk = [unknowns[match_col[i]] for i in eqs]
        sub = [equations[i].xreplace(sol) for i in eqs]
        if len(eqs) == 1:
            z = unk[0]
            e = sub[0]
            a = sp.diff(e, z)
            if a.free_symbols & uset:
                raise StructuralProblem("nonlinear", eqs, unk)
            if a == 0:
                raise StructuralProblem("singular", eqs, unk)
            rest = e.xreplace({z: 0})
            sol[z] = _tidy(-rest / a)
        else:
            for z, v in _eliminate(sub, unk, uset, eqs).items():
                sol[z] = v
    return sol


def _eliminate(eqs: list[sp.Expr], unk: list[sp.Symbol], uset: set, labels: list[int]) -> dict:
    """Solve one algebraic loop by sparse symbolic elimination (tearing).

    At each step the pivot is the (equation, unknown) pair with the fewest unknowns in the
    equation, then the unknown occurring in the fewest equations, then the simplest coefficient:
    a chain of resistors collapses to one equation in the loop current instead of a dense
    LU factorisation whose expressions grow combinatorially.
    """
    eqs = list(eqs)
    rest = set(unk)
    order: list[tuple[sp.Symbol, sp.Expr]] = []
    while eqs:
        occ = {z: 0 for z in rest}
        fs = []
        for e in eqs:
            f = e.free_symbols & rest
            fs.append(f)
            for z in f:
                occ[z] += 1
        best = None
        for i, e in enumerate(eqs):
            for z in fs[i]:
                a = sp.diff(e, z)
                if a.free_symbols & uset:
                    raise StructuralProblem("nonlinear", labels, list(unk))
                if a == 0:
                    continue
                score = (len(fs[i]), occ[z], sp.count_ops(a), str(z))
                if best is None or score < best[0]:
                    best = (score, i, z, a)
        if best is None:
            raise StructuralProblem("singular", labels, list(unk))
        _, i, z, a = best
        e = eqs.pop(i)
        val = -e.xreplace({z: 0}) / a
        order.append((z, val))
        rest.discard(z)
        eqs = [ee.xreplace({z: val}) for ee in eqs]
        if any(ee != 0 and not (ee.free_symbols & rest) and not _vanishes(ee) for ee in eqs):
            raise StructuralProblem("singular", labels, list(unk))
        eqs = [ee for ee in eqs if ee.free_symbols & rest]
    if rest:
        raise StructuralProblem("singular", labels, list(rest))
    final: dict[sp.Symbol, sp.Expr] = {}
    for z, v in reversed(order):
        final[z] = v.xreplace(final) if v.free_symbols & final.keys() else v
    return final


def _vanishes(expr: sp.Expr) -> bool:
    """Whether an expression is identically zero, tested at random positive values of its symbols."""
    rng = np.random.default_rng(12345)
    for _ in range(3):
        vals = {s: float(rng.uniform(0.5, 2.0)) for s in expr.free_symbols}
        try:
            v = complex(expr.xreplace(vals).evalf())
        except (TypeError, ValueError):
            return False
        if abs(v) > 1e-9:
            return False
    return True


def _tidy(expr: sp.Expr) -> sp.Expr:
    """Cheap normalisation: combine fractions when the expression is rational."""
    if expr.is_Atom:
        return expr
    try:
        out = sp.cancel(expr)
    except (sp.PolynomialError, TypeError, ValueError):
        return expr
    return out if sp.count_ops(out) <= sp.count_ops(expr) else expr


def _alternating(start: list[int], incid, match_col, eq_of) -> list[int]:
    """Equations reachable from unmatched ones by alternating paths (the over-determined set)."""
    seen = set(start)
    stack = list(start)
    while stack:
        i = stack.pop()
        for j in incid[i]:
            k = eq_of[j]
            if k >= 0 and k not in seen:
                seen.add(k)
                stack.append(k)
    return sorted(seen)


def _topological(blocks, labels, dep) -> list[int]:
    """Order blocks so that each comes after the blocks it depends on."""
    n = len(blocks)
    deps: list[set[int]] = [set() for _ in range(n)]
    dep = dep.tocsr()
    for i in range(dep.shape[0]):
        for k in dep.indices[dep.indptr[i] : dep.indptr[i + 1]]:
            if labels[k] != labels[i]:
                deps[labels[i]].add(labels[k])
    users: list[list[int]] = [[] for _ in range(n)]
    count = [len(d) for d in deps]
    for b, ds in enumerate(deps):
        for d in ds:
            users[d].append(b)
    ready = [b for b in range(n) if count[b] == 0]
    order = []
    while ready:
        b = ready.pop()
        order.append(b)
        for u in users[b]:
            count[u] -= 1
            if count[u] == 0:
                ready.append(u)
    return order
