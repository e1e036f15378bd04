"""The confidence's calibration: fitting it on stored diagnoses, and measuring it on cases it was not fitted on.

A stored diagnosis is one row of ``bench/calibration_data.jsonl`` (``bench/calibrate_confidence.py``): the
concealed case it ran on (``effect``, ``size``, ``seed``), its verdict, whether the verdict was ``right``,
its raw ``score`` and what :func:`~phs.workflows.diagnose.ranking.partial` reads (``explained_share``,
``residual_above_noise``).  :func:`fit_calibration` fits the share of right verdicts as a non-decreasing step
function of the raw score (:func:`fit_knots`), one per kind of verdict (:func:`kind_of`).

Scored on the diagnoses it was fitted on, a calibration looks better than it is.  :func:`cross_validate`
scores it on cases it was not fitted on: the stored diagnoses are split into groups (by default one per
concealed effect, so that a fold never shares an effect with the diagnoses its calibration was fitted on),
each group's confidences come from a calibration fitted on the other groups (:func:`held_out_confidences`),
and the Brier score (:func:`brier`) and the reliability (:func:`reliability`) of those held-out confidences
are compared with the in-sample ones.  :func:`held_out_knots` fits what the held-out confidences were worth
(the share right of the verdicts a calibration fitted without their effect gave each confidence): the
diagnosis reports its confidence through it (``ranking.HELD_OUT_CALIBRATION``).

The stored diagnoses of noise seed :data:`HELD_OUT_SEED` are held out (:func:`is_held_out`): no constant of
the diagnosis is justified by them, so that they can check a threshold chosen on the others.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from phs.errors import InputDataError, ParameterError

MIN_BLOCK = 10
"""Fewest verdicts behind one level of a calibration (:func:`fit_knots`).  A level of ten verdicts smoothed
by Laplace's rule moves at most 1/12 ≈ 0.04 towards one half; fewer would let one verdict move a level by
0.1.  Not chosen on a measurement.  Held out (grouped by concealed effect) the calibration's Brier score is
0.057, 0.056, 0.056 and 0.056 with blocks of 5, 10, 20 and 40 verdicts, the reported confidence's (through
:func:`held_out_knots`) 0.056 at each: no block size pays (on the collection before the last, 0.124 to
0.110 and 0.108 to 0.112)."""
HELD_OUT_SEED = 4
"""Noise seed of the stored diagnoses that are held out (:func:`is_held_out`): every concealed effect at
every strength with this seed.  They are never cited to justify a constant of the diagnosis
(``tests/workflows/test_diagnosis_constants.py`` checks the constants' docstrings for their names,
:func:`case_name`); a threshold chosen on the other stored diagnoses is checked on them."""
KINDS = ("effect", "none")
"""The kinds of verdict a calibration has one step function for (:func:`kind_of`)."""
_GROUPINGS = ("effect", "seed", "size")


def kind_of(verdict: str) -> str:
    """The kind of calibration a verdict is read through: ``"none"`` for ``none``, ``"effect"`` for anything else.

    Examples
    --------
    >>> kind_of("none"), kind_of("cubic_stiffness"), kind_of("discovered")
    ('none', 'effect', 'effect')
    """
    return "none" if verdict == "none" else "effect"


def case_name(row: dict) -> str:
    """The name a stored diagnosis is cited by: ``effect@size/seedN``.

    Examples
    --------
    >>> case_name({"effect": "time_delay", "size": 0.6, "seed": 4})
    'time_delay@0.6/seed4'
    """
    return f"{row['effect']}@{float(row['size']):g}/seed{int(row['seed'])}"


def is_held_out(row: dict) -> bool:
    """Whether a stored diagnosis belongs to the held-out cases (noise seed :data:`HELD_OUT_SEED`).

    Examples
    --------
    >>> is_held_out({"effect": "offset", "size": 1.0, "seed": 4}), is_held_out({"effect": "offset", "size": 1.0, "seed": 3})
    (True, False)
    """
    return int(row["seed"]) == HELD_OUT_SEED


def load_rows(path) -> list[dict]:
    """The stored diagnoses of a JSON-lines file (one object per line; blank lines skipped).

    Raises
    ------
    InputDataError
        A line that is not a JSON object, or lacks one of ``effect``, ``size``, ``seed``, ``verdict``, ``right``,
        ``score`` (the message names the file and line).

    Examples
    --------
    >>> import os, tempfile
    >>> p = os.path.join(tempfile.mkdtemp(), "d.jsonl")
    >>> _ = open(p, "w").write('{"effect": "offset", "size": 1, "seed": 3, "verdict": "offset", "right": true, "score": 0.7}\\n')
    >>> [case_name(r) for r in load_rows(p)]
    ['offset@1/seed3']
    """
    need = ("effect", "size", "seed", "verdict", "right", "score")
    rows = []
    with open(path, encoding="utf-8") as f:
        for k, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError as e:
                raise InputDataError(f"{path}, line {k}: not JSON ({e.msg})") from None
            missing = [n for n in need if not isinstance(row, dict) or n not in row]
            if missing:
                raise InputDataError(f"{path}, line {k}: a stored diagnosis needs {', '.join(missing)}")
            rows.append(row)
    return rows


def fit_knots(scores: Sequence[float], right: Sequence[float], min_block: int = MIN_BLOCK) -> list[tuple[float, float]]:
    """Non-decreasing share of right verdicts against raw scores: consecutive blocks of at least ``min_block``
    verdicts (in order of score; the last block absorbs the remainder), pooled where a block's share falls
    below the one before (adjacent violators), each pooled level then smoothed by Laplace's rule
    ``(right + 1) / (n + 2)`` (a handful of verdicts never gives 0 or 1); one knot ``(score, level)`` at the
    start of each level.  :func:`level` reads them.

    Examples
    --------
    >>> fit_knots([0.1, 0.2, 0.3, 0.4], [0, 1, 1, 1], min_block=2)   # blocks 1/2 and 2/2: (1+1)/4, (2+1)/4
    [(0.1, 0.5), (0.3, 0.75)]
    >>> fit_knots([0.1, 0.2, 0.3, 0.4], [1, 1, 0, 0], min_block=2)   # pooled: (2+1)/(4+2)
    [(0.1, 0.5)]
    """
    from scipy.optimize import isotonic_regression

    order = np.argsort(np.asarray(scores, dtype=float), kind="stable")
    s = np.asarray(scores, dtype=float)[order]
    y = np.asarray(right, dtype=float)[order]
    n = len(s)
    if n == 0:
        return []
    edges = list(range(0, n, min_block))
    if len(edges) > 1 and n - edges[-1] < min_block:
        edges.pop()  # the last block absorbs the remainder
    edges.append(n)
    sizes = np.diff(edges)
    shares = np.array([y[a:b].mean() for a, b in zip(edges[:-1], edges[1:], strict=True)])
    levels = isotonic_regression(shares, weights=sizes, increasing=True).x
    starts = [k for k in range(len(levels)) if k == 0 or levels[k] != levels[k - 1]] + [len(levels)]
    smoothed = []
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        lo, hi = edges[a], edges[b]
        smoothed.append(((y[lo:hi].sum() + 1) / (hi - lo + 2), hi - lo))
    vals = isotonic_regression([v for v, _ in smoothed], weights=[m for _, m in smoothed], increasing=True).x
    return [(round(float(s[edges[a]]), 3), round(float(v), 3)) for k, (a, v) in enumerate(zip(starts[:-1], vals, strict=True))
            if k == 0 or v != vals[k - 1]]


def level(knots: Sequence[tuple[float, float]], score: float) -> float:
    """The calibrated value of ``score``: each knot ``(x, p)`` starts a level ``p`` that holds up to the next
    knot; below the first knot the score itself if lower than the first level (no evidence for more); without
    knots the score itself.

    Examples
    --------
    >>> k = [(0.4, 0.75), (0.6, 0.9)]
    >>> level(k, 0.3), level(k, 0.5), level(k, 0.6), level(k, 0.99), level([], 0.42)
    (0.3, 0.75, 0.9, 0.9, 0.42)
    """
    if not knots:
        return float(score)
    xs, ps = zip(*knots, strict=True)
    if score < xs[0]:
        return float(min(score, ps[0]))
    return float(ps[int(np.searchsorted(xs, score, side="right")) - 1])


def reported(knots: Sequence[tuple[float, float]], held_out: Sequence[tuple[float, float]], score: float) -> float:
    """The confidence a diagnosis reports for a raw ``score``: its calibrated :func:`level` (``knots``) read through
    what that level was worth held out (``held_out``, :func:`held_out_knots`).  Below the first knot the raw score
    stands (at most the first level): the held-out knots read calibrated levels only.

    Examples
    --------
    >>> reported([(0.4, 0.75), (0.6, 0.9)], [(0.7, 0.85)], 0.65), reported([(0.4, 0.75)], [(0.7, 0.85)], 0.3)
    (0.85, 0.3)
    """
    if not knots or score < knots[0][0]:
        return level(knots, score)
    return level(held_out, level(knots, score))


def brier(confidence: Iterable[float], right: Iterable[float]) -> float:
    """Brier score: the mean squared difference between confidence and rightness (1 right, 0 wrong); lower
    is better, 0.25 for a constant one half.

    Examples
    --------
    >>> brier([0.9, 0.5, 0.2], [1, 1, 0])   # (0.01 + 0.25 + 0.04) / 3
    0.1
    """
    c = np.asarray(list(confidence), dtype=float)
    y = np.asarray(list(right), dtype=float)
    return round(float(np.mean((c - y) ** 2)), 12) if len(c) else math.nan


def reliability(confidence: Iterable[float], right: Iterable[float], bins: int = 10) -> float:
    """How far a confidence is from the share of right verdicts it is given to (the expected calibration
    error): the confidences are put in ``bins`` bins of equal width on [0, 1] (1 in the last), and each
    verdict counts the difference between its bin's mean confidence and its bin's share right; 0 is perfectly
    reliable, lower is better.

    Examples
    --------
    >>> reliability([0.9, 0.9, 0.2, 0.2], [1, 0, 0, 0])   # bin 0.9: |0.9 - 0.5|, bin 0.2: |0.2 - 0|
    0.3
    """
    c = np.asarray(list(confidence), dtype=float)
    y = np.asarray(list(right), dtype=float)
    if not len(c):
        return math.nan
    idx = np.minimum((c * bins).astype(int), bins - 1)
    total = sum(abs(c[idx == b].mean() - y[idx == b].mean()) * np.count_nonzero(idx == b) for b in np.unique(idx))
    return round(float(total / len(c)), 12)


def fit_calibration(rows: Sequence[dict]) -> dict:
    """The calibration of ``rows`` (stored diagnoses): :func:`fit_knots` of rightness on the raw score, per
    kind of verdict that occurs in them.

    Examples
    --------
    >>> rows = [{"verdict": "offset", "score": s, "right": r} for s, r in [(0.5, 0), (0.6, 1), (0.7, 1), (0.9, 1)]]
    >>> fit_calibration(rows)   # one block of four: (3 + 1) / (4 + 2)
    {'effect': [(0.5, 0.667)]}
    """
    out = {}
    for kind in KINDS:
        rk = [r for r in rows if kind_of(r["verdict"]) == kind]
        if rk:
            out[kind] = fit_knots([float(r["score"]) for r in rk], [1.0 if r["right"] else 0.0 for r in rk])
    return out


def _grouping(by) -> Callable[[dict], object]:
    if callable(by):
        return by
    if by not in _GROUPINGS:
        raise ParameterError(f"cross-validation by {by!r}: group the stored diagnoses by one of {', '.join(_GROUPINGS)} "
                             "or pass a function of a row")
    return lambda r: r[by]


def held_out_confidences(rows: Sequence[dict], by="effect", recalibrate: bool = False) -> np.ndarray:
    """Each stored diagnosis' confidence from a calibration fitted on the other groups only (``by``: ``"effect"``,
    ``"seed"``, ``"size"`` or a function of a row giving its group).  With ``recalibrate``, the calibration
    is followed, as the diagnosis reports it, by the :func:`held_out_knots` fitted on the other groups too
    (a cross-validation inside each fitting set): the confidence the diagnosis would report for a case of a
    group it never saw.

    Raises
    ------
    ParameterError
        ``by`` is not a known grouping, or the rows form fewer than two groups.

    Examples
    --------
    >>> rows = [{"effect": e, "verdict": e, "score": s, "right": r}
    ...         for e, s, r in [("a", 0.5, 1), ("a", 0.9, 1), ("b", 0.6, 0), ("b", 0.8, 1)]]
    >>> held_out_confidences(rows).tolist()   # a's from b's one level (1+1)/(2+2), b's from a's (2+1)/(2+2)
    [0.5, 0.5, 0.75, 0.75]
    """
    group = _grouping(by)
    keys = [group(r) for r in rows]
    groups = list(dict.fromkeys(keys))
    if len(groups) < 2:
        raise ParameterError(f"cross-validation by {by!r}: the stored diagnoses form {len(groups)} group, at least 2 are needed")
    out = np.empty(len(rows))
    for g in groups:
        fitting = [r for r, k in zip(rows, keys, strict=True) if k != g]
        cal = fit_calibration(fitting)
        recal = held_out_knots(fitting, by=by) if recalibrate else {}
        for i, (r, k) in enumerate(zip(rows, keys, strict=True)):
            if k == g:
                kind = kind_of(r["verdict"])
                out[i] = reported(cal.get(kind, ()), recal.get(kind, ()), float(r["score"]))
    return out


def held_out_knots(rows: Sequence[dict], by="effect") -> dict:
    """What a confidence was worth on cases its calibration was not fitted on: per kind of verdict,
    :func:`fit_knots` of rightness on the :func:`held_out_confidences` (``by``).  Read through :func:`level`
    after the calibration, a confidence becomes the share right of the held-out verdicts given that
    confidence.  With fewer than two groups (nothing to hold out) it is empty: the calibration stands.

    Examples
    --------
    >>> rows = [{"effect": e, "verdict": e, "score": s, "right": r}
    ...         for e, s, r in [("a", 0.5, 1), ("a", 0.9, 1), ("b", 0.6, 0), ("b", 0.8, 1)]]
    >>> held_out_knots(rows)   # held out, the four confidences hold one level: (3 + 1) / (4 + 2)
    {'effect': [(0.5, 0.667)]}
    """
    keys = {_grouping(by)(r) for r in rows}
    if len(keys) < 2:
        return {}
    c = held_out_confidences(rows, by=by)
    out = {}
    for kind in KINDS:
        m = [i for i, r in enumerate(rows) if kind_of(r["verdict"]) == kind]
        if m:
            out[kind] = fit_knots(c[m], [1.0 if rows[i]["right"] else 0.0 for i in m])
    return out


@dataclass(frozen=True)
class CrossValidation:
    """Figures of :func:`cross_validate`: Brier scores (:func:`brier`) and reliabilities (:func:`reliability`) over
    ``n`` stored diagnoses, of the raw score, of the calibration fitted on all of them (``in_sample_*``), of the
    same calibration fitted without each group (``held_out_*``), and of the confidence the diagnosis reports
    (calibration then held-out knots, both fitted without each group: ``reported_*``).
    """

    by: str
    groups: int
    n: int
    raw_brier: float
    in_sample_brier: float
    held_out_brier: float
    reported_brier: float
    in_sample_reliability: float
    held_out_reliability: float
    reported_reliability: float

    def to_dict(self) -> dict:
        """The figures as a dict, rounded to 4 digits.

        Examples
        --------
        >>> rows = [{"effect": e, "verdict": e, "score": s, "right": r}
        ...         for e, s, r in [("a", 0.5, 1), ("a", 0.9, 1), ("b", 0.6, 0), ("b", 0.8, 1)]]
        >>> cross_validate(rows).to_dict()["held_out_brier"]   # (0.25 + 0.25 + 0.5625 + 0.0625) / 4
        0.2812
        """
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


def cross_validate(rows: Sequence[dict], by="effect", adjust: Callable[[dict, float], float] | None = None) -> CrossValidation:
    """The calibration scored in sample and on held-out groups of ``rows`` (stored diagnoses; ``by`` as in
    :func:`held_out_confidences`).  ``adjust(row, confidence)`` is applied to every confidence before it is
    scored (e.g. :func:`~phs.workflows.diagnose.ranking.partial`'s scaling); the raw score is scored as it is.

    Examples
    --------
    >>> rows = [{"effect": e, "verdict": e, "score": s, "right": r}
    ...         for e, s, r in [("a", 0.5, 1), ("a", 0.9, 1), ("b", 0.6, 0), ("b", 0.8, 1)]]
    >>> cv = cross_validate(rows)
    >>> cv.groups, round(cv.in_sample_brier, 4), cv.held_out_brier   # in sample every verdict at (3+1)/(4+2)
    (2, 0.1944, 0.28125)
    """
    name = by if isinstance(by, str) else getattr(by, "__name__", "groups")
    group = _grouping(by)
    y = np.array([1.0 if r["right"] else 0.0 for r in rows])
    cal = fit_calibration(rows)
    inside = np.array([level(cal.get(kind_of(r["verdict"]), ()), float(r["score"])) for r in rows])
    held = held_out_confidences(rows, by=by)
    rep = held_out_confidences(rows, by=by, recalibrate=True)
    if adjust is not None:
        inside, held, rep = (np.array([adjust(r, c) for r, c in zip(rows, v, strict=True)]) for v in (inside, held, rep))
    raw = [float(r["score"]) for r in rows]
    return CrossValidation(by=name, groups=len({group(r) for r in rows}), n=len(rows), raw_brier=brier(raw, y),
                           in_sample_brier=brier(inside, y), held_out_brier=brier(held, y), reported_brier=brier(rep, y),
                           in_sample_reliability=reliability(inside, y), held_out_reliability=reliability(held, y),
                           reported_reliability=reliability(rep, y))
