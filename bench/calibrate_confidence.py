"""Calibration of the diagnosis' confidence: how often a verdict of a given raw score is right.

Runs ``phs.diagnose`` on the concealed cases of ``examples/concealed_effects.py`` at several effect
strengths (``size``: the effect's tuned strength times 0.35, 0.6, 1) and noise seeds, 3 s recordings,
and records for each the verdict, whether it names the truth (``none`` for the control), the share of
the mismatch it explains and whether its residual stays above the noise (``explained_share``,
``residual_above_noise``: what :func:`phs.workflows.diagnose.ranking.partial` reads), and the raw
score the confidence is built from (``Diagnosis.verdict["score"]``: ``0.5 + 0.5 (g1 - g2) / g1``
for an effect, ``1 - g / (2 MIN_VALIDATION_GAIN)`` for ``none``, before the calibration, the failure
factor and the cap).  Then it fits the share of right verdicts as a non-decreasing function of the raw
score (blocks of at least ten verdicts, pooled adjacent violators, each level Laplace-smoothed:
:func:`phs.workflows.diagnose.calibration.fit_knots`) and prints the reliability table and the knots that
``phs.workflows.diagnose.ranking.CALIBRATION`` holds, then the calibration cross-validated
(:func:`phs.workflows.diagnose.calibration.cross_validate`, grouped by concealed effect, by strength and by
seed: the Brier score and the reliability in sample, held out, and of the confidence the diagnosis reports).

    python bench/calibrate_confidence.py --out cal-0.jsonl --shard 0/2 &   # one process per core
    python bench/calibrate_confidence.py --out cal-1.jsonl --shard 1/2
    python bench/calibrate_confidence.py --fit cal-0.jsonl cal-1.jsonl     # table and knots

A shard skips the cases its file already holds (a stopped run resumes).

The last line printed by ``--fit`` is one JSON object: ``cases``, ``right``, ``brier_raw`` (mean squared
difference between raw score and rightness, lower is better), ``brier_now`` (the same for the confidence
the installed calibration gives: :func:`~phs.workflows.diagnose.ranking.calibrated`), ``knots`` per kind of
verdict (``effect``, ``none``), ``held_out_knots`` (what ``ranking.HELD_OUT_CALIBRATION`` holds) and
``cross_validation`` (per grouping, the figures of ``CrossValidation``).
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


def _knots(s, y):
    """Knots of rightness ``y`` against scores ``s``: :func:`phs.workflows.diagnose.calibration.fit_knots`."""
    from phs.workflows.diagnose.calibration import fit_knots

    return fit_knots(s, y)


def fit(paths) -> dict:
    from phs.workflows.diagnose.calibration import cross_validate, held_out_knots, load_rows
    from phs.workflows.diagnose.ranking import calibrated

    rows = [r for p in paths for r in load_rows(p)]
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
    out["held_out_knots"] = held_out_knots(rows)
    out["cross_validation"] = {}
    print("\n| grouped by | groups | Brier: raw | in sample | held out | reported | reliability: in sample | held out | reported |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for by in ("effect", "size", "seed"):
        cv = cross_validate(rows, by=by)
        out["cross_validation"][by] = cv.to_dict()
        print(f"| {by} | {cv.groups} | {cv.raw_brier:.3f} | {cv.in_sample_brier:.3f} | {cv.held_out_brier:.3f} | "
              f"{cv.reported_brier:.3f} | {cv.in_sample_reliability:.3f} | {cv.held_out_reliability:.3f} | "
              f"{cv.reported_reliability:.3f} |")
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
