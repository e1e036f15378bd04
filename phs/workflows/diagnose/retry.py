"""Fitting a hypothesis so that it is never lost: the candidate's starts, then the neutral point, then
tighter bounds, then continuation from the neutral point.

Every augmented model contains the nominal one (its new element at zero strength, the candidate's
:attr:`~components.candidates.Augmentation.neutral` point), so a fit that fails or ends worse than that
point has not yet tried hard enough.  :func:`fit_with_retries` runs one fit (any callable
``fit_one(start, bounds)`` that returns a result with a ``cost`` or raises) through a ladder of rungs and
stops at the first rung that gives a usable answer:

1. the candidate's starts (the model as built, then :attr:`~components.candidates.Augmentation.starts`);
2. the neutral point (when every start failed, or the best ended worse than ``reference``: the cost at
   the neutral point with the nominal values);
3. tighter bounds: the new parameters boxed within a decade of their default start (a smaller first step);
4. continuation: the new parameters stepped from the neutral point towards their default start in
   :data:`STAGES`, each stage boxed between the neutral point and its step and started from the previous
   stage's result, the last with the full bounds.

Only when every rung fails is :class:`FitFailed` raised, with every reason.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from phs.errors import PHSError

STAGES = (0.25, 0.5, 0.75, 1.0)
"""Fractions of the way (in log scale for log-scaled parameters) from the neutral point to the default
start at which continuation fits; the last stage (1.0) has the full bounds.  Not chosen on a measurement."""
TIGHT = 10.0
"""Factor (log-scaled parameters) or tenth of the range (linear ones) boxing the new parameters around
their default start in the tighter-bounds retry.  Not chosen on a measurement."""

SAME_COST = 1e-4
"""Relative margin within which a start's cost counts as the neutral point's (integration tolerance):
only a start ending worse than ``reference`` by more calls the neutral rung.
Chosen by the integration tolerance, not on a measurement."""
RECOVERABLE = (PHSError, RuntimeError, ValueError, ArithmeticError, np.linalg.LinAlgError)
"""What a failed fit raises: an integrator failure, non-finite values, a singular system."""


class FitFailed(PHSError):
    """Every rung of :func:`fit_with_retries` failed; ``reasons`` says why, rung by rung."""

    def __init__(self, reasons: list[tuple[str, str]]):
        self.reasons = list(reasons)
        first = reasons[0][1] if reasons else "no attempt"
        super().__init__(f"{first} (and {len(reasons) - 1} retries failed)" if len(reasons) > 1 else first)


FIT_HINT = "at parameter values the fit tried"
"""What a fit's integrator failure adds to its words (:func:`codegen._solver_errors.in_words`)."""


def reason(exc: BaseException) -> str:
    """The first line of an exception's message (its type when it has none), an integrator's failure put in
    words (what happened, at parameter values the fit tried) instead of its C++ source file and return flag.

    Examples
    --------
    >>> raw = '.../cvodes_interface.cpp:403: CVode returned "CV_CONV_FAILURE". Consult CVODES documentation.'
    >>> print(reason(RuntimeError(raw)))  # doctest: +NORMALIZE_WHITESPACE
    the integrator failed: the Newton iterations of its implicit steps failed repeatedly (the dynamics are
    very stiff or not smooth there), at parameter values the fit tried (CV_CONV_FAILURE)
    >>> reason(ValueError())
    'ValueError'
    """
    from codegen._solver_errors import in_words

    msg = in_words(str(exc).strip(), hint=FIT_HINT)
    return msg.splitlines()[0] if msg else type(exc).__name__


def _between(a: float, b: float, f: float, log: bool) -> float:
    if log and a > 0 and b > 0:
        return float(a * (b / a) ** f)
    return float(a + f * (b - a))


def _clip(values: dict, bounds: dict) -> dict:
    out = {}
    for k, v in values.items():
        lo, hi = bounds.get(k, (-math.inf, math.inf))
        out[k] = float(min(max(v, lo), hi))
    return out


def fit_with_retries(fit_one, starts, *, neutral=None, target=None, bounds=None, log_scale=(), reference=None,
                     stages=STAGES) -> tuple[Any, str]:
    """Fit through the ladder of rungs of this module; returns ``(result, recovery)``.

    Parameters
    ----------
    fit_one : callable
        ``fit_one(start, bounds)``: ``start`` a dict of parameter values to start from (``{}``: as
        built), ``bounds`` a dict of ``(lo, hi)`` for the new parameters; returns an object with a
        ``cost`` and ``values`` (dict), or raises.
    starts : sequence of dict
        The candidate's starts, tried first (best cost wins).
    neutral : dict, optional
        The neutral point moved inside ``bounds`` (:meth:`~components.candidates.Augmentation.neutral_start`);
        without it only the starts and the tighter bounds are tried.
    target : dict, optional
        Default starting values of the new parameters (the end of continuation, the centre of the
        tighter bounds).
    bounds : dict
        Full bounds of the new parameters.
    log_scale : sequence of str
        New parameters stepped and boxed in log scale.
    reference : float, optional
        Cost at the neutral point with the nominal values: a best start above it calls the neutral rung.
    stages : sequence of float
        Continuation fractions (:data:`STAGES`).

    Returns
    -------
    (result, str)
        The best result and how it was reached (``""``: from the starts; else which rung rescued it and
        after which failures).

    Raises
    ------
    FitFailed
        Every rung failed.

    Examples
    --------
    A fit that fails from any start above 5 and cannot step by more than a factor 30 (as an integrator
    that diverges on a strong element or a large first step) reaches the optimum 3 only by continuation:

    >>> from types import SimpleNamespace
    >>> def fit_one(start, bounds):
    ...     a = start.get("a", 10.0)
    ...     lo, hi = bounds.get("a", (1e-3, 1e3))
    ...     best = min(max(3.0, lo), hi)
    ...     if a > 5 or max(best / a, a / best) > 30:
    ...         raise RuntimeError("CVODES: CV_TOO_MUCH_WORK")
    ...     return SimpleNamespace(cost=(best - 3.0) ** 2, values={"a": best})
    >>> res, how = fit_with_retries(fit_one, [{}], neutral={"a": 1e-3}, target={"a": 10.0},
    ...                             bounds={"a": (1e-3, 1e3)}, log_scale=["a"])
    >>> res.values["a"], how.split(" after")[0]
    (3.0, 'rescued by continuation from the neutral point')
    """
    bounds = dict(bounds or {})
    log_scale = set(log_scale)
    failures: list[tuple[str, str]] = []

    def attempt(label, start, bnds):
        try:
            res = fit_one(dict(start), dict(bnds))
        except RECOVERABLE as exc:
            failures.append((label, reason(exc)))
            return None
        if not math.isfinite(float(res.cost)):
            failures.append((label, "non-finite cost"))
            return None
        return res

    def told(rung):
        return f"{rung} after: " + "; ".join(f"{lab}: {why}" for lab, why in failures)

    best = None
    for k, st in enumerate(starts):
        res = attempt("the default start" if k == 0 and not st else f"start {k}", st, bounds)
        if res is not None and (best is None or res.cost < best.cost):
            best = res
    worse = best is not None and reference is not None and best.cost > reference * (1 + SAME_COST)
    if best is not None and not worse:
        return best, ""
    if neutral:
        res = attempt("the neutral start", neutral, bounds)
        if res is not None and (best is None or res.cost < best.cost):
            return res, told("rescued by the neutral start") if failures else "improved on by the neutral start"
        if best is not None:
            return best, ""
    elif best is not None:
        return best, ""
    if target:
        tight = {}
        for k, v in target.items():
            lo, hi = bounds.get(k, (-math.inf, math.inf))
            if k in log_scale and v > 0:
                tight[k] = (max(lo, v / TIGHT), min(hi, v * TIGHT))
            else:
                span = (hi - lo) / TIGHT if math.isfinite(hi - lo) else abs(v) or 1.0
                tight[k] = (max(lo, v - span / 2), min(hi, v + span / 2))
        res = attempt("tighter bounds", {}, {**bounds, **tight})
        if res is not None:
            return res, told("rescued by tighter bounds")
    if neutral and target:
        prev, start = None, dict(neutral)
        for f in stages:
            stage_bounds = dict(bounds)
            if f < 1.0:
                for k, n in neutral.items():
                    v = _between(n, target.get(k, n), f, k in log_scale)
                    lo, hi = sorted((n, v))
                    if hi <= lo:
                        hi = lo + 1e-12 * max(abs(lo), 1.0)
                    stage_bounds[k] = (lo, hi)
            res = attempt(f"continuation stage {f:g}", _clip(start, stage_bounds), stage_bounds)
            if res is None:
                break
            prev, start = res, dict(res.values)
        if prev is not None:
            return prev, told("rescued by continuation from the neutral point")
    raise FitFailed(failures)
