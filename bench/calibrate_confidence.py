"""Calibration of the diagnosis' confidence: how often a verdict of a given raw score is right.

Runs ``phs.diagnose`` on the concealed cases of ``examples/concealed_effects.py`` at several effect
strengths (``size``: the effect's tuned strength times 0.35, 0.6, 1) and noise seeds, 3 s recordings,
and records for each the verdict, whether it names the truth (``none`` for the control), the share of
the mismatch it explains and whether its residual stays above the noise (``explained_share``,
``residual_above_noise``: what :func:`phs.workflows.diagnose.ranking.partial` reads), and the raw
score the confidence is built from (``Diagnosis.verdict["score"]``: ``0.5 + 0.5 (g1 - g2) / g1``
for an effect, ``1 - g / (2 MIN_VALIDATION_GAIN)`` for ``none``, before the calibration, the failure
factor and the cap).  Then it fits the share of right verdicts as a non-decreasing function of the raw
score (blocks of at least ten verdicts, pooled adjacent violators, each level Laplace-smoothed) and
prints the reliability table and the knots that ``phs.workflows.diagnose.ranking.CALIBRATION`` holds.

    python bench/calibrate_confidence.py --out cal-0.jsonl --shard 0/2 &   # one process per core
    python bench/calibrate_confidence.py --out cal-1.jsonl --shard 1/2
    python bench/calibrate_confidence.py --fit cal-0.jsonl cal-1.jsonl     # table and knots

A shard skips the cases its file already holds (a stopped run resumes).

The last line printed by ``--fit`` is one JSON object: ``cases``, ``right``, ``brier_raw`` (mean squared
difference between raw score and rightness, lower is better), ``brier_now`` (the same for the confidence
the installed :data:`~phs.workflows.diagnose.ranking.CALIBRATION` gives), and ``knots`` per kind of
verdict (``effect``, ``none``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

SIZES = (0.35, 0.6, 1.0)
SEEDS = (3, 4)


def cases():
    from examples.concealed_effects import EFFECTS

    return [(e, s, seed) for e in EFFECTS for s in (SIZES if e != "none" else (1.0,)) for seed in SEEDS]


def run(shard: int, n_shards: int, out: str, seconds: float) -> None:
    from examples.concealed_effects import NOMINAL_FREE, generate
    from phs.io import write_atomic
    from phs.workflows.diagnose import diagnose
    from systems.electrostatic_actuator import electrostatic_actuator

    done = set()
    lines = []
    if os.path.exists(out):
        with open(out) as f:
            lines = [ln for ln in f.read().splitlines() if ln.strip()]
        done = {(d["effect"], d["size"], d["seed"]) for d in map(json.loads, lines)}
    for k, (effect, size, seed) in enumerate(cases()):
        if k % n_shards != shard or (effect, size, seed) in done:
            continue
        train, _ = generate(effect, seconds=seconds, seed=seed, size=size)
        val, _ = generate(effect, seconds=seconds, seed=seed + 100, validation=True, size=size)
        t0 = time.perf_counter()
        d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=1)
        row = {"effect": effect, "size": size, "seed": seed, "verdict": d.effect, "right": d.effect == effect,
               "score": d.verdict["score"], "confidence": d.verdict["confidence"], "failed": len(d.verdict["failed"]),
               "explained_share": round(float(d.verdict.get("explained_share", 0.0)), 4),
               "residual_above_noise": bool(d.verdict.get("residual_above_noise", False)),
               "seconds": round(time.perf_counter() - t0, 1)}
        print(json.dumps(row), flush=True)
        lines.append(json.dumps(row))
        write_atomic(out, "\n".join(lines) + "\n")


MIN_BLOCK = 10
"""Fewest verdicts behind one level of the calibration."""


def _knots(s, y):
    """Non-decreasing share of right verdicts ``y`` against scores ``s`` (sorted): consecutive blocks of at
    least :data:`MIN_BLOCK` verdicts, pooled where a block's share falls below the one before (adjacent
    violators), each pooled level then smoothed by Laplace's rule ``(right + 1) / (n + 2)`` (a handful of
    verdicts never gives 0 or 1); one knot at the start of each level."""
    from scipy.optimize import isotonic_regression

    n = len(s)
    edges = list(range(0, n, MIN_BLOCK))
    if len(edges) > 1 and n - edges[-1] < MIN_BLOCK:
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


def fit(paths) -> dict:
    from phs.workflows.diagnose.ranking import calibrated

    rows = []
    for p in paths:
        with open(p) as f:
            rows += [json.loads(ln) for ln in f if ln.strip()]
    out = {"cases": len(rows), "right": sum(r["right"] for r in rows), "knots": {}}
    print(f"{len(rows)} verdicts, {out['right']} right")
    print("| verdict | raw score | verdicts | right | share right | calibrated confidence (mean) |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    sq_raw, sq_cal = [], []
    for kind in ("effect", "none"):
        rk = sorted([r for r in rows if (r["verdict"] == "none") == (kind == "none")], key=lambda r: r["score"])
        if not rk:
            continue
        s = np.array([r["score"] for r in rk])
        y = np.array([1.0 if r["right"] else 0.0 for r in rk])
        c = np.array([calibrated(v, kind) for v in s])
        out["knots"][kind] = _knots(s, y)
        for a, b in zip([0.0, 0.55, 0.65, 0.8, 0.9], [0.55, 0.65, 0.8, 0.9, 1.0001], strict=True):
            m = (s >= a) & (s < b)
            if m.any():
                print(f"| {kind} | {a:.2f}–{min(b, 1.0):.2f} | {int(m.sum())} | {int(y[m].sum())} | "
                      f"{y[m].mean():.2f} | {c[m].mean():.2f} |")
        sq_raw += list((s - y) ** 2)
        sq_cal += list((np.array([calibrated(v, kind) for v in s]) - y) ** 2)
    out["brier_raw"] = round(float(np.mean(sq_raw)), 4)
    out["brier_now"] = round(float(np.mean(sq_cal)), 4)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="calibration.jsonl", help="JSON-lines file the runs append to")
    ap.add_argument("--shard", default="0/1", help="i/n: run every n-th case starting at i")
    ap.add_argument("--seconds", type=float, default=3.0, help="recording length [s]")
    ap.add_argument("--fit", nargs="+", help="fit the calibration on these JSON-lines files")
    args = ap.parse_args(argv)
    if args.fit:
        print(json.dumps(fit(args.fit)))
        return
    i, n = (int(v) for v in args.shard.split("/"))
    run(i, n, args.out, args.seconds)


if __name__ == "__main__":
    main()
