"""Is the Hamiltonian bounded below?  Decided symbolically where possible, else over the state box.

``H - min H`` is a storage function (the passivity argument) only if H is bounded below. The
decision, in order:

1. **symbolic**: every energy term is provably nonnegative under the symbols' assumptions (sympy's
   ``is_nonnegative``, e.g. ``K (l - L)**2 / 2`` with ``K > 0``), or is a polynomial in one state of
   even degree with a provably positive leading coefficient (``k x**2/2 + k3 x**4/4``).  Then H is
   bounded below everywhere, not only on the declared ranges.
2. **numeric**: H is minimised over the declared state box (a seeded sample of the box's valid
   points, then bounded L-BFGS-B polishes from the best of them).  When the minimum lies on a
   face of the box, H is followed outward along that face's normal to 64 box widths: if it is
   still falling there and its drops do not shrink as the distance doubles, H is **unbounded
   below** beyond the stated box, and the verdict is ``fail`` (the box's minimum is only an
   artefact of where the box was drawn).  If H stops falling, or is undefined outside (the box edge
   is the edge of the model's domain), the minimum on the box stands, and the detail says it was
   found numerically over the stated box only.

Examples
--------
>>> import sympy as sp
>>> from systems.examples import duffing_oscillator, mass_spring_damper
>>> bounded_below(mass_spring_damper()).method
'symbolic'
>>> bounded_below(duffing_oscillator()).verdict
'pass'
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
import sympy as sp

from phs._budget import affordable

#: box widths to which H is followed outward from a minimum on a face of the box
REACH = 64.0


@dataclass(frozen=True)
class Bound:
    """The answer of :func:`bounded_below`: verdict (``pass``/``fail``/``undecided``), method, a
    sentence, the minimum found (None when symbolic) and where."""

    verdict: str
    method: str
    detail: str
    minimum: float | None = None
    point: dict = field(default_factory=dict)


def _parts(expr: sp.Expr, states: list[sp.Symbol]) -> list[sp.Expr]:
    """The expanded sum split into parts that share no state (each part bounded below => the sum is)."""
    terms = sp.Add.make_args(sp.expand(expr))
    sets = [frozenset(t.free_symbols & set(states)) for t in terms]
    groups: list[tuple[set, list]] = []
    for t, syms in zip(terms, sets):
        joined = [g for g in groups if g[0] & syms]
        merged = (set(syms), [t])
        for g in joined:
            merged[0].update(g[0])
            merged[1].extend(g[1])
            groups.remove(g)
        groups.append(merged)
    return [sp.Add(*g[1]) for g in groups]


def _part_bounded(part: sp.Expr, states: list[sp.Symbol]) -> bool:
    if part.is_nonnegative or part.is_number:
        return True
    free = [s for s in states if s in part.free_symbols]
    if len(free) != 1:
        return False
    try:
        poly = sp.Poly(part, free[0])
    except sp.PolynomialError:
        return False
    if any(free[0] in c.free_symbols for c in poly.coeffs()):
        return False
    return poly.degree() % 2 == 0 and poly.degree() > 0 and bool(poly.LC().is_positive)


def _provably_bounded(expr: sp.Expr, states: list[sp.Symbol]) -> bool:
    """True if ``expr`` is provably bounded below: nonnegative as a whole, or a sum of parts in disjoint
    states each nonnegative or an even univariate polynomial with a positive leading coefficient."""
    expr = sp.sympify(expr)
    if expr.is_nonnegative:
        return True
    if not affordable(expr):
        return False  # over the symbolic budget: not expanded, decided over the box instead
    return all(_part_bounded(part, states) for part in _parts(expr, states))


def _evaluator(system):
    """``evaluate(X) -> H`` (NaN where a validity condition fails) and ``valid(X) -> (k, m)`` per condition."""
    fH = system.lambdify(system.H, with_u=False)
    fc = system.lambdify([c.expr for c in system.conditions], with_u=False) if system.conditions else None
    pv = system.param_vector()

    def conditions(X: np.ndarray) -> np.ndarray:
        if fc is None:
            return np.ones((X.shape[0], 0), dtype=bool)
        with np.errstate(all="ignore"):
            c = np.asarray([np.broadcast_to(np.asarray(v, dtype=float), (X.shape[0],)) for v in fc(X.T, (), pv)])
        return (c >= 0).T

    def evaluate(X: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        with np.errstate(all="ignore"):
            h = np.broadcast_to(np.asarray(fH(X.T, (), pv), dtype=float), (X.shape[0],)).copy()
        h[~np.all(conditions(X), axis=1)] = np.nan
        h[~np.isfinite(h)] = np.nan
        return h

    return evaluate, conditions


def _valid_sample(system, conditions, lo, hi, k: int, seed: int) -> np.ndarray:
    """``k`` points of the box, redrawn per group of coupled coordinates until their conditions hold.

    Conditions usually tie a few states together (one segment's angle and length); drawing the
    whole box at once would almost never satisfy all of them in a many-segment model."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(lo, hi, size=(k, len(lo)))
    if not system.conditions:
        return X
    index = {s: i for i, s in enumerate(system.x)}
    deps = [sorted(index[s] for s in c.expr.free_symbols if s in index) for c in system.conditions]
    for _ in range(60):
        ok = conditions(X)
        if ok.all():
            break
        for j, cols in enumerate(deps):
            bad = ~ok[:, j]
            if cols and bad.any():
                X[np.ix_(bad, cols)] = rng.uniform(lo[cols], hi[cols], size=(int(bad.sum()), len(cols)))
    return X


def _minimise(evaluate, X, lo, hi):
    X = np.vstack([X, 0.5 * (lo + hi)])
    h = evaluate(X)
    if not np.any(np.isfinite(h)):
        return None, None
    order = np.argsort(np.where(np.isfinite(h), h, np.inf))[:3]
    best_x, best_h = X[order[0]], float(h[order[0]])

    width = np.where(hi > lo, hi - lo, 1.0)
    penalty = best_h + 1e6 * (abs(best_h) + 1.0)

    def value_and_gradient(z):
        # one batched evaluation: the point and a forward step in each coordinate (inward at an upper bound)
        step = 1e-7 * width * np.where(z + 1e-7 * width > hi, -1.0, 1.0)
        v = evaluate(np.vstack([z, z + np.diag(step)]))
        v = np.where(np.isfinite(v), v, penalty)
        return float(v[0]), (v[1:] - v[0]) / step

    for i in order:
        if not np.isfinite(h[i]):
            continue
        res = scipy.optimize.minimize(value_and_gradient, X[i], method="L-BFGS-B", jac=True, bounds=list(zip(lo, hi)),
                                      options={"maxiter": 200})
        v = evaluate(res.x[None, :])[0]
        if np.isfinite(v) and v < best_h:
            best_x, best_h = res.x, float(v)
    return best_x, best_h


def follow_outward(evaluate, x, h_min, lo, hi) -> tuple[bool, bool, float, np.ndarray]:
    """Follow H outward from ``x``: along the normal of the box faces it lies on, and along each state axis.

    Returns ``(on_face_falling, elsewhere_falling, h_far, x_far)``: a direction "falls without
    bound" when H at its far end is below the box's minimum and its last drops, as the distance
    doubles, are positive and do not shrink (a function that levels off has shrinking drops).
    ``evaluate(X)`` gives H at the rows of X (NaN where the model is not defined).

    Examples
    --------
    >>> import numpy as np
    >>> f = lambda X: -X[:, 0] ** 4
    >>> follow_outward(f, np.array([1.0]), -1.0, np.array([-1.0]), np.array([1.0]))[:2]
    (True, False)
    """
    width = hi - lo
    tol = 1e-6 * width
    normal = np.where(x >= hi - tol, 1.0, 0.0) - np.where(x <= lo + tol, 1.0, 0.0)
    eye = np.eye(len(x))
    directions = ([normal] if np.any(normal) else []) + list(eye) + list(-eye)
    steps = np.array([2.0 ** k for k in range(-4, int(np.log2(REACH)) + 1)])
    worst = (False, False, np.nan, x)
    for k, d in enumerate(directions):
        P = x[None, :] + steps[:, None] * (d * width)[None, :]
        h = evaluate(P)
        if not np.all(np.isfinite(h)):
            continue                     # undefined outside: the box edge is the edge of the model's domain
        drops = -np.diff(h[-5:])
        if h[-1] < h_min and np.all(drops > 0) and drops[-1] >= 0.5 * drops[0]:
            face = bool(np.any(normal)) and k == 0
            if face or not worst[0] and (np.isnan(worst[2]) or h[-1] < worst[2]):
                worst = (face, not face, float(h[-1]), P[-1])
    return worst


def bounded_below(system, samples: int = 200, seed: int = 0) -> Bound:
    """Decide whether ``system.H`` is bounded below (see the module docstring for how).

    Parameters
    ----------
    system : PHSystem
    samples : int
        Points of the state box sampled before the local polishes.
    seed : int
        Seed of the sample.

    Returns
    -------
    Bound

    Examples
    --------
    >>> from phs import PHSystem, StateInfo
    >>> q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    >>> bad = PHSystem("quartic", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")], H=-q**4 + p**2 / 2,
    ...                J=[[0, 1], [-1, 0]], R=[[0, 0], [0, 0]])
    >>> b = bounded_below(bad)
    >>> b.verdict, round(b.minimum, 3)
    ('fail', -1.0)
    """
    states = list(system.x)
    refused = [t.label for t in system.energy_terms if not sp.sympify(t.expr, strict=True).is_nonnegative and not affordable(t.expr)]
    if all(_provably_bounded(t.expr, states) for t in system.energy_terms):
        return Bound("pass", "symbolic", "every energy term is nonnegative or an even polynomial with a positive "
                     "leading coefficient: H is bounded below everywhere")
    lo = np.array([s.range[0] for s in system.states], dtype=float)
    hi = np.array([s.range[1] for s in system.states], dtype=float)
    evaluate, conditions = _evaluator(system)
    X = _valid_sample(system, conditions, lo, hi, samples, seed)
    x, h = _minimise(evaluate, X, lo, hi)
    names = [s.name for s in system.states]
    refusal = f"; symbolic decision refused (energy term {', '.join(map(repr, refused))} over the budget)" if refused else ""
    if x is None:
        return Bound("undecided", f"sampled ({samples} points){refusal}", "H is not finite at any valid point of the state box")
    point = {n: float(v) for n, v in zip(names, x)}
    on_face, beyond, h_far, x_far = follow_outward(evaluate, x, h, lo, hi)
    method = f"numeric ({samples} samples + L-BFGS-B over the state box, followed {REACH:g} box widths outward){refusal}"
    inside = np.all(conditions(X), axis=1)
    undefined = int(np.sum(inside & np.isnan(evaluate(X))))
    far = ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, x_far) if v != point[n])
    if on_face:
        return Bound("fail", method, f"H is unbounded below: its minimum {h:.6g} J over the state box lies on the box's "
                     f"face and H keeps falling outward ({h_far:.6g} J at {far}); the declared ranges do not make it "
                     "a storage function", h, point)
    if beyond:
        return Bound("undecided", method, f"bounded on the stated box only: minimum {h:.6g} J inside it, but H is unbounded "
                     f"below outside it ({h_far:.6g} J at {far}); a storage function only while the state stays in the box",
                     h, point)
    if undefined:
        first = X[inside & np.isnan(evaluate(X))][0]
        return Bound("undecided", method, f"H is not finite at {undefined} of {len(X)} sampled states inside the "
                     "validity domain (first at " + ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, first))
                     + f"): no evidence there; minimum {h:.6g} J over the other points", h, point)
    on_face = bool(np.any((x <= lo + 1e-6 * (hi - lo)) | (x >= hi - 1e-6 * (hi - lo))))
    return Bound("pass", method, f"minimum {h:.6g} J over the state box" + (
        " (on its face; H levels off or is undefined outside)" if on_face else "")
        + "; no direction found in which H falls without bound", h, point)
