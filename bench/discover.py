"""Benchmark: discovery of physics outside the library, and what it costs.

Cases:

* ``novel``: each truth of ``examples/concealed_novel.py`` (fringe-field capacitance, heating leakage,
  one-sided spring, softening stiffness, drive gain falling with stroke) on a 20 s, 1 kHz recording with
  its own validation recording;
  ``phs.diagnose`` with the whole library and ``discover=None``.  Reported per case: the verdict, the
  validation-fit gain of the final model as a share of the truth's own gain (``recovered``), the
  explained share, the discovered terms with their nature and state, the passivity checks, the time of the
  whole diagnosis and of the discovery step (target: discovery adds at most 60 s).
  With ``--alone``: the discovery step alone on the nominal fit (no library), as in the first table of
  ``docs/workflows/discover.md`` (``--seconds 3``).
* ``outside``: each truth of ``examples/concealed_outside.py`` (a second mechanical mode from a flexible
  appendage, a suspension stiffness drifting as it warms, a current limit of the drive, a light appendage tuned
  near the resonance whose two modes beat, on the ``ringing`` program), simulated from
  hand-written equations with scipy rather than by the framework; 20 s recordings, run and reported as the
  novel cases (``recovered``, verdict, terms).
* ``library``: in-library cases of ``examples/concealed_effects.py`` with ``discover=None``: the verdict
  must still name the truth (``--library all`` for every one).
* ``silverbox``: the Silverbox recording (``../shared/data``, skipped when absent) with ``cubic_stiffness``
  removed from the library: discovery should find a hardening conservative term on the position.

    python bench/discover.py                 # novel and outside cases at 20 s, 3 library cases, Silverbox
    python bench/discover.py --quick         # 3 s recordings, two novel cases and one outside case (smoke test)
    python bench/discover.py --library all   # every in-library case too (long)
    python bench/discover.py --only silverbox --data ../shared/data
    python bench/discover.py --only novel --alone --seconds 3   # discovery alone, every novel case
    python bench/discover.py --only novel --cases heating_resistance   # one case
    python bench/discover.py --only outside --seconds 20                # the outside cases

The last line printed is one JSON object: ``novel`` (per case), ``recovered_min_conservative``,
``recovered_min`` (every novel case), ``outside`` (per case, as ``novel``), ``recovered_min_outside``,
``discovery_seconds_max`` (every novel and outside case), ``library`` (per case: verdict, expected, correct), ``silverbox``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402

from examples import concealed_novel, concealed_outside  # noqa: E402
from examples.concealed_novel import NOVEL, truth_gain  # noqa: E402
from examples.concealed_outside import OUTSIDE  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

FREE = ["k", "b", "eps"]
LIBRARY_CASES = ["cubic_stiffness", "leakage", "offset"]
FAMILIES = {"novel": concealed_novel, "outside": concealed_outside}
"""The modules of the two kinds of cases outside the library (each with ``generate`` and ``NATURE``)."""
DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data")


def _family(effect: str):
    return FAMILIES["outside" if effect in OUTSIDE else "novel"]


def novel_case(effect: str, seconds: float, jobs) -> dict:
    """The whole diagnosis (library, then discovery where it runs) of a novel or outside case."""
    fam = _family(effect)
    train, _ = fam.generate(effect, seconds=seconds, seed=1)
    val, vinfo = fam.generate(effect, seconds=seconds, seed=2, validation=True)
    t0 = time.perf_counter()
    d = diagnose(electrostatic_actuator(), train, validation=val, free=FREE, n_jobs=jobs)
    sec = time.perf_counter() - t0
    truth = truth_gain(d.nominal.validation_rss, val, vinfo["clean"])
    out = {"effect": effect, "nature": fam.NATURE[effect][0], "state": fam.NATURE[effect][1], "seconds": sec, "verdict": d.effect,
           "effects": d.verdict["effects"], "explained_share": d.verdict["explained_share"],
           "truth_gain": truth, "recovered": (d.nominal.validation_rss - d.final.validation_rss) / truth if truth > 0 else None,
           "library_recovered": {h.augmentation.effect: (d.nominal.validation_rss - h.validation_rss) / truth for h in d.accepted},
           "passive": d.structure_checks()["ok"], "discovery_seconds": d.discovery.seconds if d.discovery else 0.0,
           "validation_fit": {"nominal": d.nominal.validation_fit_percent, "final": d.final.validation_fit_percent}}
    if d.discovery is not None and d.discovery.found:
        out["terms"] = [{k: x[k] for k in ("term", "state", "nature", "coefficient")} for x in d.discovery.described]
        out["description"] = d.discovery.text
    return out


def alone_case(effect: str, seconds: float, jobs) -> dict:
    """The discovery step alone on the nominal fit of a novel or outside case (no library effect first)."""
    from phs.workflows.diagnose import noise_level
    from phs.workflows.diagnose.discover import discover
    from phs.workflows.diagnose.hypotheses import Data
    from phs.workflows.diagnose.nominal import fit_nominal

    fam = _family(effect)
    train, _ = fam.generate(effect, seconds=seconds, seed=1)
    val, vinfo = fam.generate(effect, seconds=seconds, seed=2, validation=True)
    t0 = time.perf_counter()
    data = Data(train, val, np.ones(len(val), bool), None, ["position", "current"], FREE, {}, [], None)
    nominal, data = fit_nominal(electrostatic_actuator(), data)
    noise = {ch: noise_level(data.recording[ch]) for ch in data.outputs}
    d = discover(nominal, nominal, data, noise, n_jobs=jobs or 1)
    truth = truth_gain(nominal.validation_rss, val, vinfo["clean"])
    out = {"effect": effect, "nature": fam.NATURE[effect][0], "state": fam.NATURE[effect][1], "seconds": time.perf_counter() - t0,
           "verdict": "discovered" if d.found else "none", "effects": [], "explained_share": d.share,
           "truth_gain": truth, "recovered": (nominal.validation_rss - d.scored.validation_rss) / truth if d.found and truth > 0 else 0.0,
           "passive": bool(d.scored.system.check().ok) if d.found else True, "discovery_seconds": d.seconds,
           "validation_fit": {"nominal": nominal.validation_fit_percent,
                              "final": d.scored.validation_fit_percent if d.found else nominal.validation_fit_percent}}
    if d.found:
        out["terms"] = [{k: x[k] for k in ("term", "state", "nature", "coefficient")} for x in d.described]
        out["description"] = d.text
    return out


def library_case(effect: str, seconds: float, jobs) -> dict:
    from examples.concealed_effects import NOMINAL_FREE
    from examples.concealed_effects import generate as generate_library

    train, _ = generate_library(effect, seconds=seconds, seed=1)
    val, _ = generate_library(effect, seconds=seconds, seed=2, validation=True)
    t0 = time.perf_counter()
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=jobs)
    return {"effect": effect, "verdict": d.effect, "correct": d.effect == effect, "effects": d.verdict["effects"],
            "discovery_ran": d.discovery is not None, "seconds": time.perf_counter() - t0}


def silverbox(jobs, data_dir=DATA) -> dict | None:
    from components.candidates import LIBRARY
    from phs.workflows.identify.starts import second_order_start
    from phs.workflows.recording import Recording
    from systems.examples import mass_spring_damper

    path = os.path.join(data_dir, "silverbox", "SNLS80mV.csv")
    if not os.path.isfile(path):
        return None
    raw = np.genfromtxt(path, delimiter=",", skip_header=1)
    fs = 1e7 / 2**14
    v1, v2 = raw[:, 0] - raw[:, 0].mean(), raw[:, 1] - raw[:, 1].mean()
    n, start = 600, 40000 - 600
    rec = Recording.from_arrays(np.arange(n) / fs, {"F": v1[start:start + n] * 1e5, "position": v2[start:start + n]})
    st = second_order_start(rec["position"], rec["F"], fs)
    model = mass_spring_damper(m=st["m"], k=st["k"], b=st["b"])
    t0 = time.perf_counter()
    d = diagnose(model, rec, free=["m.m", "k.K", "b.b"], outputs=["position"], n_jobs=jobs,
                 candidates=[c for c in LIBRARY if c.effect != "cubic_stiffness"])
    out = {"seconds": time.perf_counter() - t0, "verdict": d.effect, "effects": d.verdict["effects"],
           "explained_share": d.verdict["explained_share"], "passive": d.structure_checks()["ok"],
           "validation_fit": {"nominal": d.nominal.validation_fit_percent, "final": d.final.validation_fit_percent}}
    if d.discovery is not None and d.discovery.found:
        out["terms"] = [{k: x[k] for k in ("term", "state", "nature", "coefficient")} for x in d.discovery.described]
    return out


def _line(r: dict) -> str:
    rec = "—" if r["recovered"] is None else f"{r['recovered']:.2f}"
    return (f"{r['effect']:<22} {r['seconds']:6.1f} s (discovery {r['discovery_seconds']:5.1f} s)  verdict {r['verdict']:<18} "
            f"recovered {rec}  explained {r['explained_share']:.2f}  passive {r['passive']}  "
            f"terms {[t['term'] for t in r.get('terms', [])]}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 s recordings, two novel cases and one outside case, no library cases")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--library", default=",".join(LIBRARY_CASES), help="in-library cases ('all', or none with '')")
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--data", default=DATA, help="directory of the real recordings (default ../shared/data)")
    ap.add_argument("--cases", default="", help="comma-separated novel or outside cases (default: every one of the parts run)")
    ap.add_argument("--alone", action="store_true", help="novel and outside cases: the discovery step alone on the nominal fit")
    ap.add_argument("--only", default="", help="comma-separated parts to run: novel, outside, library, silverbox (default all)")
    args = ap.parse_args(argv)
    seconds = 3.0 if args.quick else args.seconds
    parts = set(args.only.split(",")) if args.only else {"novel", "outside", "library", "silverbox"}
    unknown = sorted(parts - {"novel", "outside", "library", "silverbox"})
    if unknown:
        ap.error(f"unknown part(s) {unknown}; known: novel, outside, library, silverbox")
    chosen = {"novel": ["engaging_spring", "softening_stiffness"] if args.quick else list(NOVEL),
              "outside": ["second_mode"] if args.quick else list(OUTSIDE)}
    if args.cases:
        unknown = [c for c in args.cases.split(",") if c not in NOVEL and c not in OUTSIDE]
        if unknown:
            ap.error(f"unknown case(s) {unknown}; known: {', '.join(NOVEL + OUTSIDE)}")
        chosen = {fam: [c for c in args.cases.split(",") if c in (NOVEL if fam == "novel" else OUTSIDE)] for fam in chosen}
    results = {"novel": [], "outside": []}
    for fam in ("novel", "outside"):
        for e in chosen[fam] if fam in parts else []:
            r = (alone_case if args.alone else novel_case)(e, seconds, args.jobs)
            results[fam].append(r)
            print(_line(r), flush=True)
    library = []
    if not args.quick and args.library and "library" in parts:
        from examples.concealed_effects import EFFECTS

        names = [e for e in EFFECTS if e != "none"] if args.library == "all" else args.library.split(",")
        for e in names:
            r = library_case(e, seconds, args.jobs)
            library.append(r)
            print(f"library {e:<20} verdict {r['verdict']:<20} {'ok' if r['correct'] else 'WRONG'}  discovery ran: {r['discovery_ran']}",
                  flush=True)
    sb = None if args.quick or "silverbox" not in parts else silverbox(args.jobs, args.data)
    if sb is not None:
        print(f"silverbox without cubic_stiffness: verdict {sb['verdict']}, terms {sb.get('terms')}", flush=True)
    novel, outside = results["novel"], results["outside"]
    cons = [r["recovered"] for r in novel if r["nature"] == "conservative" and r["recovered"] is not None]
    every = [r["recovered"] for r in novel if r["recovered"] is not None]
    out_rec = [r["recovered"] for r in outside if r["recovered"] is not None]
    print(json.dumps({"novel": novel, "recovered_min_conservative": min(cons) if cons else None,
                      "recovered_min": min(every) if every else None, "outside": outside,
                      "recovered_min_outside": min(out_rec) if out_rec else None,
                      "discovery_seconds_max": max([r["discovery_seconds"] for r in novel + outside], default=None),
                      "library": library, "silverbox": sb},
                     default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
