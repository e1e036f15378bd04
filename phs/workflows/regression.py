"""Linear-in-parameters regression of a measured signal on powers of another signal and its derivatives.

The black-box force model of the catheter-bender paper ("Force analysis and modelling of soft
actuators for catheter robots", eqs. 3-10): ``F = X Phi`` with regressors ``X`` made of
powers of the volume ``x`` and its time derivatives, ``Phi >= 0`` by non-negative least
squares (eq. 6), the contribution of each term by dropping it (eq. 10), and the number of
terms chosen by an exhaustive search over subsets of each size with the constant always in,
stopping when one more term lowers the best RMSE by less than a threshold (1 % in the paper).

Terms are strings read by one regular expression (never evaluated): ``"1"`` (the constant),
``"x"``, ``"x**3"``, ``"x'"``, ``"x''**2"`` (a signal name, ``'`` per time derivative, an
integer power).  Derivatives are taken numerically (second-order central differences on the
recording's time grid) unless the data hold a column of that name (``"x'"``).

Choices where the paper is ambiguous (see ``docs/systems/catheter_bender.md``): eq. 4 prints
``[x'**3 x'**2 x' x**3 x**2 x x**3 x**2 x 1]`` with the dots lost; the regressors are read as
``[x''**3 x''**2 x'' x'**3 x'**2 x' x**3 x**2 x 1]`` (:data:`BENDER_TERMS`, nine terms and the
constant, as the text says); eq. 8 prints ``RMSE = (sum F~**2)**0.5`` without the mean; the
RMSE here is ``sqrt(mean(F~**2))`` (the selection is the same: N is fixed).
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import nnls

from phs.errors import InputDataError

BENDER_TERMS = ("x''**3", "x''**2", "x''", "x'**3", "x'**2", "x'", "x**3", "x**2", "x", "1")
"""The regressors of eq. 4 of the catheter paper, with the derivative marks restored."""

_TERM = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_.]*)(?P<primes>'*)(?:\*\*(?P<power>[1-9]))?$")


@dataclass(frozen=True)
class Regression:
    """Result of :func:`regress`: the kept terms, their coefficients and the selection's trace.

    Attributes
    ----------
    terms : tuple of str
        Kept terms (the selected model; all terms when no selection was made).
    coefficients : numpy array
        Their coefficients, in the units of the target per unit of the term.
    rmse : float
        RMSE of the kept model, in the target's unit.
    steps : list of dict
        One entry per number of non-constant terms k: ``{"k", "terms", "rmse", "decrease"}`` with the
        best subset of that size, its RMSE and the relative decrease from k - 1 (the selection).
    dropped : dict of str -> float
        For each term of the full model, the RMSE increase when it alone is dropped (eq. 10 at
        the final time, as an RMSE).
    full : dict of str -> float
        Coefficients of the full model.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 201)
    >>> r = regress({"t": t, "x": t, "F": 2 * t**2 + 0.5}, ["x**2", "x", "1"], target="F")
    >>> r.terms, np.round(r.coefficients, 6).tolist()
    (('x**2', '1'), [2.0, 0.5])
    """

    terms: tuple
    coefficients: np.ndarray
    rmse: float
    steps: list = field(default_factory=list)
    dropped: dict = field(default_factory=dict)
    full: dict = field(default_factory=dict)

    def predict(self, data) -> np.ndarray:
        """The model's prediction on ``data`` (same forms as for :func:`regress`).

        Examples
        --------
        >>> t = np.linspace(0.0, 1.0, 11)
        >>> r = regress({"t": t, "x": t, "F": 3 * t}, ["x", "1"], target="F", select=False)
        >>> round(float(r.predict({"t": t, "x": 2 * t})[-1]), 6)
        6.0
        """
        X = _matrix(_columns(data), self.terms)
        return X @ self.coefficients


def _columns(data) -> dict:
    if hasattr(data, "signals") and hasattr(data, "t"):  # a phs.workflows.recording.Recording
        cols = {k: np.asarray(v, dtype=float) for k, v in data.signals.items()}
        cols["t"] = np.asarray(data.t, dtype=float)
        return cols
    if isinstance(data, dict):
        if "t" not in data:
            raise InputDataError("regress: the data need a time column 't'")
        return {k: np.asarray(v, dtype=float) for k, v in data.items()}
    raise InputDataError(f"regress: data must be a Recording or a dict of arrays, not {type(data).__name__}")


def _parse(term: str) -> tuple[str, int, int]:
    m = _TERM.match(term.replace(" ", ""))
    if not m:
        raise InputDataError(f"regress: cannot read term {term!r}; write a signal name, ' per derivative and "
                             f"an integer power, e.g. \"x''**2\", or \"1\"")
    return m["name"], len(m["primes"]), int(m["power"] or 1)


def _signal(cols: dict, name: str, order: int) -> np.ndarray:
    key = name + "'" * order
    if key in cols:
        return cols[key]
    if name not in cols:
        raise InputDataError(f"regress: no signal {name!r} in the data (have {sorted(cols)})")
    v, t = cols[name], cols["t"]
    for _ in range(order):
        v = np.gradient(v, t, edge_order=2)
    return v


def _matrix(cols: dict, terms) -> np.ndarray:
    n = len(cols["t"])
    out = []
    for term in terms:
        if term.strip() == "1":
            out.append(np.ones(n))
            continue
        name, order, power = _parse(term)
        out.append(_signal(cols, name, order) ** power)
    return np.column_stack(out) if out else np.empty((n, 0))


def _solve(X: np.ndarray, y: np.ndarray, nonnegative: bool) -> tuple[np.ndarray, float]:
    """Least squares (non-negative if asked) on columns scaled to unit norm; returns (coefficients, RMSE)."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    c = nnls(Xs, y, maxiter=50 * X.shape[1] + 100)[0] if nonnegative else np.linalg.lstsq(Xs, y, rcond=None)[0]
    c = c / scale
    return c, float(np.sqrt(np.mean((y - X @ c) ** 2)))


def regress(data, terms=BENDER_TERMS, *, target: str = "F", nonnegative: bool = True, select: bool = True,
            max_terms: int = 6, threshold: float = 0.01) -> Regression:
    """Fit ``target = sum_i c_i term_i`` (eqs. 3-6), rank the terms (eq. 10) and select a reduced model.

    Parameters
    ----------
    data : Recording or dict of arrays
        Time ``t`` and the signals the terms and the target name.
    terms : sequence of str
        Regressors (see the module docstring); ``"1"`` is the constant, kept in every model.
    target : str
        Name of the fitted signal (the measured force).
    nonnegative : bool
        Non-negative least squares (eq. 6); ordinary least squares otherwise.
    select : bool
        Search subsets of 1..``max_terms`` non-constant terms exhaustively and keep the smallest
        size after which one more term lowers the best RMSE by less than ``threshold``.
    max_terms : int
        Largest subset size searched (6 in the paper).
    threshold : float
        Relative RMSE decrease that justifies one more term (0.01 in the paper).

    Returns
    -------
    Regression

    Raises
    ------
    InputDataError
        For unreadable terms, missing signals or non-finite data.

    Examples
    --------
    >>> t = np.linspace(0.0, 10.0, 1001)
    >>> x = 5 + 3 * np.sin(t)
    >>> r = regress({"t": t, "x": x, "F": 0.003 * x**2 + 0.01}, ["x'**2", "x**3", "x**2", "x", "1"])
    >>> r.terms, [round(s["rmse"], 9) for s in r.steps][:2]
    (('x**2', '1'), [0.0, 0.0])
    """
    cols = _columns(data)
    terms = tuple(terms)
    if target not in cols:
        raise InputDataError(f"regress: no target signal {target!r} in the data (have {sorted(cols)})")
    X, y = _matrix(cols, terms), cols[target]
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
        raise InputDataError("regress: the regressors or the target contain non-finite values")
    full, rmse_full = _solve(X, y, nonnegative)
    dropped = {}
    for i, term in enumerate(terms):
        keep = [j for j in range(len(terms)) if j != i]
        dropped[term] = _solve(X[:, keep], y, nonnegative)[1] - rmse_full
    if not select:
        return Regression(terms, full, rmse_full, [], dropped, dict(zip(terms, full.tolist(), strict=True)))
    const = [i for i, term in enumerate(terms) if term.strip() == "1"]
    others = [i for i in range(len(terms)) if i not in const]
    steps, prev = [], None
    floor = 1e-12 * float(np.sqrt(np.mean(y**2)))  # RMSE at rounding level: nothing left to explain
    for k in range(1, min(max_terms, len(others)) + 1):
        best = None
        for subset in itertools.combinations(others, k):
            idx = list(subset) + const
            c, e = _solve(X[:, idx], y, nonnegative)
            if best is None or e < best[1]:
                best = (idx, e, c)
        decrease = math.nan if prev is None else (prev[1] - best[1]) / prev[1] if prev[1] > floor else 0.0
        steps.append({"k": k, "terms": tuple(terms[i] for i in best[0]), "rmse": best[1], "decrease": decrease,
                      "coefficients": best[2]})
        prev = best
    chosen = steps[-1]
    for a, b in itertools.pairwise(steps):
        if not b["decrease"] >= threshold:
            chosen = a
            break
    return Regression(chosen["terms"], chosen["coefficients"], chosen["rmse"], steps, dropped,
                      dict(zip(terms, full.tolist(), strict=True)))


__all__ = ["regress", "Regression", "BENDER_TERMS"]
