"""Which directions of the fitted parameters the data determine: the numerical rank of the Jacobian,
the covariance on its identifiable part, and the parameter combinations (products of powers) that are
and are not identified.

The analysis works in relative coordinates: column ``k`` of the Jacobian is the derivative of the
weighted residual with respect to ``log |p_k|`` (estimated initial states and window states keep the
fit's scaled coordinates), so the decision does not depend on the parameters' units.  A combination
``p_1^a_1 p_2^a_2 ...`` is identified when its exponent vector ``a`` (the direction
``sum a_k log p_k``) is orthogonal to every unidentifiable direction; it is not identified when ``a``
lies along one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from phs.errors import UnitError
from phs.units import format_dim, parse_unit

# relative singular-value threshold, in units of the sensitivities' integration tolerance ``rtol``.
# CVODES keeps the local error of the states and their forward sensitivities below ``rtol`` (relative);
# over a recording the global error of a sensitivity column grows to 10-100 ``rtol`` of its size.  By
# Weyl's inequality a Jacobian with an exact null direction, computed with a relative error ``e``,
# has a smallest singular value of at most ``e`` times the largest; singular values below
# ``_RANK_RTOL_FACTOR * rtol`` times the largest are therefore indistinguishable from zero (``1e-5`` at
# the default ``rtol = 1e-8``).  ``max(m, n) eps sigma_max`` (rounding only) would be far too small
# for sensitivities that carry integration error.  A direction just above the threshold has a
# variance 1e10 times that of the best determined one: treating it as unidentified loses nothing.
_RANK_RTOL_FACTOR = 1e3
_RANK_FLOOR = 1e-12  # below rounding of the SVD itself (for very tight rtol)
# a parameter takes part in an unidentifiable direction when its component in the unit null vectors
# exceeds this (the null vectors themselves are known only to about the rank tolerance / the gap)
_MEMBER = 1e-3


def rank_tolerance(rtol: float) -> float:
    """Relative singular-value threshold below which a direction counts as unidentifiable.

    Examples
    --------
    >>> rank_tolerance(1e-8)
    1e-05
    """
    return max(_RANK_RTOL_FACTOR * float(rtol), _RANK_FLOOR)


@dataclass(frozen=True)
class Combination:
    """A product of powers of fitted parameters, ``prod p_k ** exponents[k]``.

    ``value`` is its fitted value (NaN when a parameter is not positive), ``interval`` its 95 %
    interval (``(0, inf)`` when it is not identified), ``unit`` its SI unit.
    """

    exponents: dict
    value: float
    interval: tuple
    unit: str = ""
    group: tuple = ()  # the parameters not identifiable separately that this combination belongs to

    @property
    def name(self) -> str:
        """``"R.R·C.C"``, ``"R.R/C.C"``, ``"K^2·m^(1/2)"``: positive powers first, negative after ``/``."""
        def power(k, e):
            a = abs(e)
            if a == 1:
                return k
            return f"{k}^{a}" if isinstance(a, int) or (isinstance(a, Fraction) and a.denominator == 1) else f"{k}^({a})"
        num = [power(k, e) for k, e in self.exponents.items() if e > 0]
        den = [power(k, e) for k, e in self.exponents.items() if e < 0]
        text = "·".join(num) if num else "1"
        if den:
            text += "/" + (den[0] if len(den) == 1 else "(" + "·".join(den) + ")")
        return text

    def to_dict(self) -> dict:
        return {"name": self.name, "exponents": {k: _plain(e) for k, e in self.exponents.items()},
                "value": self.value, "interval": list(self.interval), "unit": self.unit, "group": list(self.group)}

    def text(self) -> str:
        """``"R.R·C.C = 1.0000e-03 s [9.9900e-04, 1.0010e-03]"``: enough digits to tell the bounds apart."""
        lo, hi = self.interval
        d = 4
        if math.isfinite(self.value) and math.isfinite(hi) and hi > lo and self.value != 0:
            d = min(max(4, int(math.ceil(-math.log10((hi - lo) / abs(self.value)))) + 2), 12)
        return f"{self.name} = {self.value:.{d}g}{' ' + self.unit if self.unit else ''} [{lo:.{d}g}, {hi:.{d}g}]"


def _plain(e):
    """An exponent for JSON: an int, else a float."""
    return int(e) if e == int(e) else float(e)


def analyse(J: np.ndarray, D: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Truncated SVD of the Jacobian ``J`` in relative coordinates ``J * D`` (``D``: column scale).

    Returns ``(Hp, P, rank)``: the rank-truncated inverse of ``JᵀJ`` back in fit coordinates
    (``D Vr Sr⁻² Vrᵀ D``), the projector on the unidentifiable directions in relative coordinates,
    and the numerical rank (singular values above ``tol`` times the largest).

    Examples
    --------
    >>> J = np.array([[1.0, 1.0], [2.0, 2.0], [0.5, 0.5]])  # both columns alike: one free direction
    >>> Hp, P, rank = analyse(J, np.ones(2), 1e-5)
    >>> rank, np.round(P, 3).tolist()
    (1, [[0.5, -0.5], [-0.5, 0.5]])
    """
    Jr = J * D
    n = Jr.shape[1]
    if Jr.size == 0 or not np.all(np.isfinite(Jr)):
        return np.full((n, n), np.nan), np.zeros((n, n)), 0
    # the thin SVD when there are at least as many rows as columns (U of a long Jacobian is never built)
    _, s, Vt = np.linalg.svd(Jr, full_matrices=Jr.shape[0] < n)
    s = np.concatenate([s, np.zeros(n - len(s))])
    keep = s > tol * s[0] if s[0] > 0 else np.zeros(n, dtype=bool)
    Vr, Vn = Vt[keep].T, Vt[~keep].T
    Hp = (Vr / s[keep] ** 2) @ Vr.T
    return D[:, None] * Hp * D[None, :], Vn @ Vn.T, int(keep.sum())


def undetermined_beyond(R: np.ndarray, new: list[int], tol: float) -> np.ndarray:
    """Whether each column ``new[k]`` of a Jacobian is undetermined *beyond* the other columns: after the
    other columns' span (their numerical rank, singular values above ``tol`` times the largest of the
    whole Jacobian) is projected out, the ``new`` columns leave a direction with a singular value below
    that threshold, and the column has a component along it.

    ``R`` is the triangular factor of the Jacobian in relative coordinates (``J D = Q R``: the same
    geometry of the columns, ``n × n`` whatever the number of samples).  A direction that the other
    columns already leave undetermined among themselves does not count: the question is whether the
    data tell the ``new`` parameters apart from any re-adjustment of the others.

    Examples
    --------
    >>> J = np.array([[1.0, 1.0, 0.0], [2.0, 2.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]])
    >>> R = np.linalg.qr(J, mode="r")
    >>> undetermined_beyond(R, [1], 1e-5).tolist()     # column 1 repeats column 0
    [True]
    >>> undetermined_beyond(R, [2], 1e-5).tolist()     # columns 0 and 1 leave a direction free among themselves
    [False]
    """
    R = np.asarray(R, dtype=float)
    n = R.shape[1]
    new = [int(i) for i in new]
    if not new:
        return np.zeros(0, dtype=bool)
    if R.size == 0 or not np.all(np.isfinite(R)):
        return np.ones(len(new), dtype=bool)
    s_all = np.linalg.svd(R, compute_uv=False)
    top = float(s_all[0]) if s_all.size else 0.0
    if top <= 0.0:
        return np.ones(len(new), dtype=bool)
    base = [i for i in range(n) if i not in new]
    A = R[:, new]
    if base:
        U, sb, _ = np.linalg.svd(R[:, base], full_matrices=False)
        Ub = U[:, sb > tol * top]
        A = A - Ub @ (Ub.T @ A)
    _, s, Vt = np.linalg.svd(A, full_matrices=True)
    s = np.concatenate([s, np.zeros(len(new) - len(s))])
    Vn = Vt[s <= tol * top]
    return np.sum(Vn**2, axis=0) > _MEMBER**2


def unidentified(P: np.ndarray, n_par: int) -> np.ndarray:
    """Whether each of the first ``n_par`` coordinates has a component along an unidentifiable
    direction (``P``: the projector on those directions).

    Examples
    --------
    >>> unidentified(np.array([[0.5, -0.5, 0.0], [-0.5, 0.5, 0.0], [0.0, 0.0, 0.0]]), 3).tolist()
    [True, True, False]
    """
    return np.diag(P)[:n_par] > _MEMBER**2


def _groups(P: np.ndarray, n_par: int) -> list[list[int]]:
    """Parameters (indices below ``n_par``) linked through the unidentifiable projector ``P``."""
    members = [int(i) for i in np.nonzero(unidentified(P, n_par))[0]]
    groups, seen = [], set()
    for i in members:
        if i in seen:
            continue
        stack, group = [i], []
        while stack:
            a = stack.pop()
            if a in seen:
                continue
            seen.add(a)
            group.append(a)
            stack += [b for b in members if b not in seen and abs(P[a, b]) > _MEMBER**2]
        groups.append(sorted(group))
    return groups


def _exponent_rows(B: np.ndarray) -> list[np.ndarray]:
    """A readable basis of the row space of ``B``: reduced row echelon form, each row scaled so its
    smallest nonzero entry is +-1 and its first is positive, rounded to small fractions where close."""
    A = np.array(B, dtype=float)
    rows, r = [], 0
    for c in range(A.shape[1]):
        if r >= A.shape[0]:
            break
        p = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[p, c]) < 1e-8:
            continue
        A[[r, p]] = A[[p, r]]
        A[r] /= A[r, c]
        for i in range(A.shape[0]):
            if i != r:
                A[i] -= A[i, c] * A[r]
        r += 1
    for row in A[:r]:
        row = np.where(np.abs(row) < 1e-6 * np.max(np.abs(row)), 0.0, row)
        row = row / np.min(np.abs(row[row != 0]))
        row = row * np.sign(row[row != 0][0])
        fr = [Fraction(float(x)).limit_denominator(12) for x in row]
        close = all(abs(float(f) - x) < 1e-3 * max(1.0, abs(x)) for f, x in zip(fr, row, strict=True))
        rows.append(np.array([int(f) if f.denominator == 1 else f for f in fr] if close
                             else [round(float(x), 4) for x in row], dtype=object))
    return rows


def _unit(exponents: dict, units: dict) -> str:
    """SI unit of a product of powers of parameters with ``units`` (``""`` when dimensionless or unknown)."""
    if not all(isinstance(e, (int, Fraction)) for e in exponents.values()):
        return ""
    try:
        dims = [(parse_unit(units.get(k, "1")), Fraction(e)) for k, e in exponents.items()]
    except UnitError:
        return ""
    total = tuple(sum((d[i] * e for d, e in dims), Fraction(0)) for i in range(7))
    text = format_dim(total)
    return "" if text == "1" else text


def combinations(P, cov_rel, free, values, units) -> tuple[list, list]:
    """The identified and the unidentified combinations of each group of linked parameters.

    ``P``: projector on the unidentifiable directions (relative coordinates); ``cov_rel``: covariance
    of ``log |p|`` on the identifiable part.  Returns ``(identifiable, unidentifiable)``, lists of
    :class:`Combination`.

    Examples
    --------
    >>> P = np.array([[0.5, -0.5], [-0.5, 0.5]])  # log R - log C is free
    >>> ident, free = combinations(P, np.diag([1e-6, 1e-6]), ["R", "C"], {"R": 1e3, "C": 1e-6}, {"R": "Ohm", "C": "F"})
    >>> ident[0].name, round(ident[0].value, 6), ident[0].unit, free[0].name
    ('R·C', 0.001, 's', 'R/C')
    """
    ident, unident = [], []
    for g in _groups(P, len(free)):
        w, V = np.linalg.eigh(P[np.ix_(g, g)])
        for vecs, out in ((V[:, w < _MEMBER**2], ident), (V[:, w >= _MEMBER**2], unident)):
            if vecs.shape[1] == 0:
                continue
            for row in _exponent_rows(vecs.T):
                exps = {free[i]: e for i, e in zip(g, row, strict=True) if e != 0}
                a = np.array([float(e) for e in row])
                pv = np.array([values[free[i]] for i in g], dtype=float)
                # in logs: a product of large exponents of small values neither overflows nor underflows to a warning
                log_value = float(a @ np.log(pv)) if np.all(pv > 0) else float("nan")
                value = float(np.exp(log_value)) if -745.0 < log_value < 709.0 else float("nan")
                if out is ident and math.isfinite(value):
                    se = float(np.sqrt(max(a @ cov_rel[np.ix_(g, g)] @ a, 0.0)))
                    spread = float(np.exp(min(1.96 * se, 700.0)))
                    interval = (value / spread, value * spread)
                else:
                    interval = (0.0, float("inf")) if math.isfinite(value) else (float("nan"), float("nan"))
                out.append(Combination(exps, value, interval, _unit(exps, units), tuple(free[i] for i in g)))
    return ident, unident
