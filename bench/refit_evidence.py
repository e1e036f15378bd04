"""Benchmark: which screened hypotheses a refit to convergence ever changes into an accepted one.

A diagnosis screens every hypothesis by a loose joint fit and refits the most promising to convergence
(``phs.workflows.diagnose.screening``): the best one always, the others only when their screening ΔBIC
is at most ``REFIT_EVIDENCE``.  This script diagnoses the electrostatic actuator's concealed effects
(``examples/concealed_effects.py``) with the rule switched off (every one of the ``refit_top`` best is
refitted, the baseline), and reports for every refit its screening and refit gain and ΔBIC, and how
many refits the rule would have skipped that ended accepted (the rule is safe when none did).

    python bench/refit_evidence.py                         # every effect, 3 s, strengths 1 and 0.35 (~8 min)
    python bench/refit_evidence.py --seconds 20 --effects none,charge_retention --sizes 1

The last line printed is one JSON object: ``refits``, ``skipped_by_rule`` (refits the rule skips),
``skipped_but_accepted`` (must be 0), ``refit_seconds_skipped_share`` (share of the refits' time
the rule saves) and ``cases`` (per case: the refits).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from examples.concealed_effects import EFFECTS, NOMINAL_FREE, generate  # noqa: E402
from phs.workflows.diagnose import diagnose, screening  # noqa: E402
from phs.workflows.diagnose.ranking import _accepted, _delta_bic, _gain  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402


def run_case(effect: str, seconds: float, size: float, jobs: int | None) -> dict:
    log: dict = {}
    run_all = screening._run_all

    def logged(nominal, augs, data, n_jobs, progress, label, joint=True, ordered=False):
        out = run_all(nominal, augs, data, n_jobs, progress, label, joint, ordered)
        if label == "round 1 screening":
            for h in out:
                log.setdefault(h.label, {})["screening"] = (_gain(nominal, h), _delta_bic(nominal, h))
        elif label == "round 1 joint refit":
            for h in out:
                log.setdefault(h.label, {})["refit"] = (_gain(nominal, h), _delta_bic(nominal, h), _accepted(nominal, h), h.seconds)
        return out

    train, _ = generate(effect, seconds=seconds, seed=1, size=size)
    val, _ = generate(effect, seconds=seconds, seed=2, validation=True, size=size)
    screening._run_all, kept = logged, screening.REFIT_EVIDENCE
    screening.REFIT_EVIDENCE = math.inf  # the baseline: every one of the best three refitted
    try:
        d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=jobs)
    finally:
        screening._run_all, screening.REFIT_EVIDENCE = run_all, kept
    refits = []
    for label, v in log.items():
        if "refit" in v and "screening" in v:
            (gs, bs), (gr, br, acc, sec) = v["screening"], v["refit"]
            refits.append({"hypothesis": label, "screening_gain": round(gs, 5), "screening_delta_bic": round(bs, 1),
                           "refit_gain": round(gr, 5), "refit_delta_bic": round(br, 1), "accepted": bool(acc),
                           "seconds": round(sec, 2)})
    best = max(refits, key=lambda r: r["screening_gain"]) if refits else None
    for r in refits:  # the rule refits the best screened one always, the others only with evidence
        r["skipped_by_rule"] = r is not best and not (r["screening_delta_bic"] <= kept and r["screening_gain"] > 0)
    return {"effect": effect, "size": size, "verdict": d.verdict["effects"], "refits": refits}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="recording length [s] (default 3)")
    ap.add_argument("--effects", default=",".join(EFFECTS), help="comma-separated effects (default: all)")
    ap.add_argument("--sizes", default="1,0.35", help="comma-separated effect strengths (default 1,0.35)")
    ap.add_argument("--jobs", type=int, default=None, help="processes (default: CPUs, at most 4)")
    a = ap.parse_args(argv)
    cases = []
    for effect in a.effects.split(","):
        for size in (float(s) for s in a.sizes.split(",")):
            c = run_case(effect, a.seconds, size, a.jobs)
            cases.append(c)
            for r in c["refits"]:
                print(f"{effect:>18} x{size:<5g} {r['hypothesis']:<24} screening {100 * r['screening_gain']:+7.2f} % "
                      f"ΔBIC {r['screening_delta_bic']:+9.1f} -> refit {100 * r['refit_gain']:+7.2f} % ΔBIC {r['refit_delta_bic']:+9.1f}"
                      f"{'  accepted' if r['accepted'] else ''}{'  (skipped by the rule)' if r['skipped_by_rule'] else ''}",
                      flush=True)
    refits = [r for c in cases for r in c["refits"]]
    skipped = [r for r in refits if r["skipped_by_rule"]]
    total = sum(r["seconds"] for r in refits) or 1.0
    out = {"refits": len(refits), "skipped_by_rule": len(skipped),
           "skipped_but_accepted": sum(1 for r in skipped if r["accepted"]),
           "refit_seconds_skipped_share": round(sum(r["seconds"] for r in skipped) / total, 3), "cases": cases}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
