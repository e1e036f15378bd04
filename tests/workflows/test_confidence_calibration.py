"""The diagnosis' confidence is the share of right verdicts measured on the concealed cases.

``bench/calibration_data.jsonl`` holds 80 diagnoses (``bench/calibrate_confidence.py``); the knots in
``phs.workflows.diagnose.ranking.CALIBRATION`` must be what the bench's fit gives on them, and the
calibrated confidence must be reliable on them: in each kind of verdict its mean within 0.05 of the
share right (each level is smoothed by Laplace's rule, which moves a level of ten verdicts by at most
1/12 ≈ 0.04 towards one half), and its Brier score below the raw score's.  The self-test shows the
reliability check failing for the raw score.
"""

from __future__ import annotations

import importlib.util
import json
import os

import numpy as np
import pytest

from phs.workflows.diagnose.ranking import CALIBRATION, calibrated, partial

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")


def _bench():
    spec = importlib.util.spec_from_file_location("calibrate_confidence", os.path.join(ROOT, "bench", "calibrate_confidence.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def rows():
    with open(os.path.join(ROOT, "bench", "calibration_data.jsonl")) as f:
        return [json.loads(ln) for ln in f if ln.strip()]


def _by_kind(rows, kind):
    rk = sorted([r for r in rows if (r["verdict"] == "none") == (kind == "none")], key=lambda r: r["score"])
    return np.array([r["score"] for r in rk]), np.array([1.0 if r["right"] else 0.0 for r in rk])


def _reliable(conf, y, tol=0.05):
    return abs(float(np.mean(conf)) - float(np.mean(y))) <= tol


def test_installed_knots_are_the_fit_of_the_stored_diagnoses(rows):
    bench = _bench()
    for kind in ("effect", "none"):
        s, y = _by_kind(rows, kind)
        assert [tuple(k) for k in bench._knots(s, y)] == [tuple(k) for k in CALIBRATION[kind]]


def test_calibrated_confidence_is_reliable_and_beats_the_raw_score(rows):
    conf_all, raw_all, y_all = [], [], []
    for kind in ("effect", "none"):
        s, y = _by_kind(rows, kind)
        conf = np.array([calibrated(v, kind) for v in s])
        assert _reliable(conf, y), (kind, conf.mean(), y.mean())
        conf_all += list(conf)
        raw_all += list(s)
        y_all += list(y)
    # the Brier score over every verdict (a kind with a handful of verdicts, the four "none"s, is one level
    # of the calibration: its own Brier score against the raw one says nothing)
    conf_all, raw_all, y_all = map(np.asarray, (conf_all, raw_all, y_all))
    assert np.mean((conf_all - y_all) ** 2) < np.mean((raw_all - y_all) ** 2) - 0.02
    # self-test: the raw score of a "none" verdict (0.63 to 1) is far from its share right (2 in 4)
    s, y = _by_kind(rows, "none")
    assert not _reliable(s, y)


def test_calibration_is_monotone_and_bounded():
    grid = np.linspace(0, 1, 101)
    for kind in ("effect", "none"):
        c = np.array([calibrated(v, kind) for v in grid])
        assert np.all(np.diff(c) >= 0) and np.all((c >= 0) & (c < 1))
        # below every calibrated verdict the raw score, never more
        assert np.all(c[grid < CALIBRATION[kind][0][0]] <= grid[grid < CALIBRATION[kind][0][0]])


def test_scaling_partial_verdicts_makes_the_confidence_more_reliable(rows):
    """The share rule (``ranking.partial``) on the stored diagnoses: the calibrated confidence of every
    verdict, scaled where it explains less than half of the mismatch and leaves structure, is closer to
    rightness (Brier score) than unscaled; it scales wrong verdicts more often than right ones (on the stored
    set: the four weak slew-rate limits named ``quadratic_drag`` at a share of 2-3 % and an input saturation
    named ``added_mass``; two input saturations named right at 28 and 36 %; Brier 0.095 -> 0.058)."""
    plain, scaled, hit = [], [], {True: 0, False: 0}
    for r in rows:
        kind = "none" if r["verdict"] == "none" else "effect"
        c = calibrated(r["score"], kind)
        v = partial({"effect": r["verdict"], "confidence": c, "explanation": "", "explained_share": r["explained_share"],
                     "residual_above_noise": r["residual_above_noise"]})
        y = 1.0 if r["right"] else 0.0
        plain.append((c - y) ** 2)
        scaled.append((v["confidence"] - y) ** 2)
        if v["confidence"] < c:
            hit[r["right"]] += 1
    assert np.mean(scaled) < np.mean(plain) - 0.03, (np.mean(scaled), np.mean(plain))
    assert hit[False] >= 2 * hit[True], hit
