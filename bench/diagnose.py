"""Benchmark: one diagnosis of a 20 s, 1 kHz recording with the full candidate library.

The nominal model is the 1-DOF electrostatic actuator (position and current measured); each case's
recording comes from a truth that contains one effect the nominal model lacks, in a functional form
different from the library's candidate (``examples/concealed_effects.py``), with a validation
recording of its own.  For every case the script runs ``phs.diagnose`` with every candidate, times
it, and checks the verdict against the truth.  Target: under 2 minutes per case on a 2-core machine.

    python bench/diagnose.py                       # default cases, 20 s recordings
    python bench/diagnose.py --effects all         # every effect of the generator (long)
    python bench/diagnose.py --quick               # 4 s recordings, two cases (smoke test)

The last line printed is one JSON object: ``seconds_per_case`` (mean), ``max_seconds``,
``verdict_correct`` (share of cases whose verdict names the truth's effect), ``cases`` (per case:
seconds, verdict, expected, fit before/after on validation).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from examples.concealed_effects import EFFECTS, NOMINAL_FREE, generate  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

DEFAULT = ["charge_retention", "cubic_stiffness", "coulomb_friction", "time_delay", "none"]


def run_case(effect: str, seconds: float, jobs: int | None) -> dict:
    train, _ = generate(effect, seconds=seconds, seed=1)
    val, _ = generate(effect, seconds=seconds, seed=2, validation=True)
    t0 = time.perf_counter()
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=jobs)
    sec = time.perf_counter() - t0
    return {
        "seconds": round(sec, 2), "verdict": d.effect, "effects": d.verdict["effects"], "expected": effect,
        "correct": d.effect == effect, "confidence": d.verdict["confidence"],
        "validation_fit_before": {k: round(v, 2) for k, v in d.nominal.validation_fit_percent.items()},
        "validation_fit_after": {k: round(v, 2) for k, v in d.final.validation_fit_percent.items()},
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="recording length [s] (default 20)")
    ap.add_argument("--effects", default=",".join(DEFAULT), help="comma-separated effects, or 'all'")
    ap.add_argument("--jobs", type=int, default=None, help="processes (default: CPUs, at most 4)")
    ap.add_argument("--quick", action="store_true", help="4 s recordings, two cases")
    args = ap.parse_args(argv)
    effects = EFFECTS if args.effects == "all" else [e.strip() for e in args.effects.split(",")]
    seconds = args.seconds
    if args.quick:
        effects, seconds = ["charge_retention", "none"], 4.0
    cases = {}
    for e in effects:
        r = run_case(e, seconds, args.jobs)
        cases[e] = r
        print(f"{e:<20} {r['seconds']:7.1f} s  verdict {r['verdict']:<20} {'ok' if r['correct'] else 'WRONG'}  "
              f"validation fit {r['validation_fit_before']} -> {r['validation_fit_after']}", flush=True)
    secs = [c["seconds"] for c in cases.values()]
    out = {"seconds_per_case": round(sum(secs) / len(secs), 2), "max_seconds": max(secs),
           "verdict_correct": sum(c["correct"] for c in cases.values()) / len(cases), "recording_seconds": seconds,
           "target_seconds": 120, "cases": cases}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
