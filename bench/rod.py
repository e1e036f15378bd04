"""Benchmark: the planar Cosserat rod (``components.CosseratRod``) against pyelastica at equal tip accuracy, on the
undamped cantilever under a step tip load of ``bench/rod_cantilever.py`` (1.5 periods of the first mode).

    python bench/rod.py                       # targets 2 % and 1 % of the tip deflection (about 4 min)
    python bench/rod.py --full                # also 0.5 % (pyelastica up to n = 800: about 10 min more)
    python bench/rod.py --quick --no-elastica # smoke test: ours only, small n
    python bench/rod.py --fresh-reference     # recompute pyelastica's reference instead of reading tests/data

Accuracy of a run: the largest distance of its tip from the reference trajectory of the same code over the run,
in units of the largest tip deflection (0.59 L).  References: ours, the Richardson extrapolation (order 2) of
n = 20 and 40 at rtol 1e-9; pyelastica, that (order 1) of n = 160 and 320 at ``frac = 0.45`` of its stability
bound (read from ``tests/data/rod_cantilever_pyelastica.npz``, written by ``bench/rod_cantilever.py`` with the
same code; the two references differ by 0.12 %).

Sweeps.  Ours: n in 8..24 and rtol in 1e-3..1e-6 (CVODES, ``compile=True``, no energy quadratures); the C
compilation (once per n, cached on disk) is reported with the build, not in the run time.  pyelastica:
n in 160..400 (``--full``: to 800) at ``frac = 0.9`` of the PositionVerlet stability bound (its time error is
negligible: halving the step changes the tip by 3e-6 of the deflection; the bound itself cannot be exceeded) —
the cheapest run is at the largest stable step.  For each target the cheapest run of each code that reaches it
is timed again (median of 3) and the ratio pyelastica/ours of those run times is printed, with the ratio that
also counts our build (assembly, code generation, C compilation) against pyelastica's set-up.  pyelastica's numba
compilation (about 100 s with a cold cache, 5 s warm) is done before and not counted.

The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import rod_cantilever as rc  # noqa: E402

from codegen import generate, simulator  # noqa: E402


def _ours_sweep(ns, rtols, reference, compile_: bool) -> list[dict]:
    rows = []
    for n in ns:
        t0 = time.perf_counter()
        system = rc.ours_system(n, "tip")
        t1 = time.perf_counter()
        generate(system)
        t2 = time.perf_counter()
        build = {"assembly_seconds": t1 - t0, "codegen_seconds": t2 - t1}
        for k, rtol in enumerate(rtols):
            sim = simulator(system, rtol=rtol, energy=False, compile=compile_)
            first, _ = rc.ours_run(sim, n, "tip")  # builds the integrator (and compiles to C once per n)
            if k == 0:
                build["first_run_seconds"] = first
            seconds, tip = rc.ours_run(sim, n, "tip")
            rows.append({"n": n, "rtol": rtol, "seconds": seconds, "error": rc.deviation(tip, reference),
                         "sim": sim, **build})
            print(f"ours n={n:<3} rtol={rtol:.0e}  run {seconds:6.3f} s  error {rows[-1]['error']:.2e}"
                  f"  (assembly {build['assembly_seconds']:.2f} s, codegen {build['codegen_seconds']:.2f} s, "
                  f"first run {build['first_run_seconds']:.2f} s)", flush=True)
    return rows


def _elastica_sweep(ns, frac, reference, smallest_target) -> list[dict]:
    rows = []
    for n in ns:
        t0 = time.perf_counter()
        seconds, tip = rc.elastica(n, "tip", frac)
        setup = time.perf_counter() - t0 - seconds
        rows.append({"n": n, "frac": frac, "steps": rc.N_OUT * rc.elastica_steps(n, frac), "seconds": seconds,
                     "setup_seconds": setup, "error": rc.deviation(tip, reference)})
        print(f"pyelastica n={n:<4} frac={frac}  {rows[-1]['steps']} steps  run {seconds:7.2f} s  "
              f"error {rows[-1]['error']:.2e}", flush=True)
        if rows[-1]["error"] < smallest_target:
            break
    return rows


def _cheapest(rows, target):
    ok = [r for r in rows if r["error"] <= target]
    return min(ok, key=lambda r: r["seconds"]) if ok else None


def _retime(fn, first: float) -> float:
    """Median of the sweep's time and two more runs (one more when a run takes over 30 s)."""
    times = [first] + [fn() for _ in range(1 if first > 30 else 2)]
    return statistics.median(times)


def _plain(row):
    return None if row is None else {k: (float(f"{v:.4g}") if isinstance(v, float) else v) for k, v in row.items() if k != "sim"}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="ours at small n only, loose targets (smoke test)")
    ap.add_argument("--full", action="store_true", help="also the 0.5 %% target (pyelastica up to n = 800)")
    ap.add_argument("--no-elastica", action="store_true", help="skip pyelastica")
    ap.add_argument("--fresh-reference", action="store_true", help="recompute pyelastica's reference")
    args = ap.parse_args(argv)
    if args.quick:
        targets, ns, rtols, ref_ns, compile_ = [0.05, 0.02], [4, 6, 8], [1e-4, 1e-6], (8, 16), False
    else:
        targets, ns, rtols, ref_ns, compile_ = [0.02, 0.01] + ([0.005] if args.full else []), \
            [8, 10, 12, 14, 16, 20, 24], [1e-3, 1e-4, 1e-5, 1e-6], (20, 40), True
    print(f"cantilever: omega_1 {rc.OMEGA1:.4f} rad/s, T = {rc.T_END:.4f} s, F_y = {rc.FY:.4g} N; "
          f"targets {targets} of the tip deflection", flush=True)
    t0 = time.perf_counter()
    coarse, fine = (rc.ours(n, "tip", rtol=1e-9) for n in ref_ns)
    ours_ref = rc.richardson(coarse, fine, 2)
    print(f"ours reference: n = {ref_ns} extrapolated ({time.perf_counter() - t0:.1f} s); "
          f"n = {ref_ns[1]} is {rc.deviation(fine, ours_ref):.2e} from it", flush=True)
    ours_rows = _ours_sweep(ns, rtols, ours_ref, compile_)
    out = {"quick": args.quick, "targets": targets, "T": rc.T_END,
           "ours": [_plain(r) for r in ours_rows], "pyelastica": None, "equal_accuracy": {}}
    order = np.log2(ours_rows[0]["error"] / ours_rows[-1]["error"]) / np.log2(ns[-1] / ns[0])
    out["ours_order"] = round(float(order), 2)
    ea = None
    if not args.no_elastica:
        try:
            import elastica as ea
        except ImportError:
            print("pyelastica not importable: comparison not run")
    if ea is not None:
        s0 = time.perf_counter()
        rc.elastica(4, "tip")  # numba compilation (cached on disk), not timed below
        out["pyelastica_warmup_seconds"] = round(time.perf_counter() - s0, 2)
        if args.fresh_reference or not os.path.exists(rc.REFERENCE):
            el_ref = rc.richardson(rc.elastica(160, "tip")[1], rc.elastica(320, "tip")[1], 1)
        else:
            with np.load(rc.REFERENCE) as f:
                if not np.allclose(f["params"], [rc.L, rc.RADIUS, rc.RHO, rc.E, rc.G, rc.ALPHA_C, rc.FY, rc.GRAVITY,
                                                 rc.T_END], rtol=1e-12):
                    raise SystemExit(f"{rc.REFERENCE} is of another cantilever: rerun bench/rod_cantilever.py")
                el_ref = f["tip_reference"]
        out["reference_difference"] = rc.deviation(ours_ref, el_ref)
        print(f"pyelastica reference: n = 160, 320 extrapolated; ours and pyelastica's references differ by "
              f"{out['reference_difference']:.2e}", flush=True)
        el_ns = [160, 200, 250, 320, 400] + ([500, 640, 800] if args.full else [])
        el_rows = _elastica_sweep(el_ns, 0.9, el_ref, min(targets))
        out["pyelastica"] = [_plain(r) for r in el_rows]
    for target in targets:
        mine = _cheapest(ours_rows, target)
        entry = {"ours": None, "pyelastica": None, "ratio": None, "ratio_with_build": None}
        if mine is not None:
            mine["median_seconds"] = _retime(lambda m=mine: rc.ours_run(m["sim"], m["n"], "tip")[0], mine["seconds"])
            entry["ours"] = _plain(mine)
        if ea is not None:
            theirs = _cheapest(el_rows, target)
            if theirs is not None:
                theirs["median_seconds"] = _retime(lambda r=theirs: rc.elastica(r["n"], "tip", r["frac"])[0],
                                                   theirs["seconds"])
                entry["pyelastica"] = _plain(theirs)
            if mine is not None and theirs is not None:
                entry["ratio"] = round(theirs["median_seconds"] / mine["median_seconds"], 2)
                build = mine["assembly_seconds"] + mine["codegen_seconds"] + mine["first_run_seconds"]
                entry["ratio_with_build"] = round((theirs["median_seconds"] + theirs["setup_seconds"])
                                                  / (mine["median_seconds"] + build), 2)
        out["equal_accuracy"][str(target)] = entry
        describe = [f"{who} " + ("not reached" if entry[who] is None else
                                 f"n={entry[who]['n']} {entry[who]['median_seconds']:.3f} s (error {entry[who]['error']:.2e})")
                    for who in ("ours", "pyelastica") if who == "ours" or ea is not None]
        print(f"target {target:.1%}: " + ", ".join(describe)
              + (f"; ratio pyelastica/ours {entry['ratio']} (with our build {entry['ratio_with_build']})"
                 if entry["ratio"] else ""), flush=True)
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
