"""Benchmark: build cost of the planar Cosserat rod (assembly and code generation) as n grows.

    python bench/rod_assembly.py                     # n = 25, 50, 100
    python bench/rod_assembly.py --full              # n = 25, 50, 100, 200
    python bench/rod_assembly.py --quick             # n = 6, 12 (smoke test)
    python bench/rod_assembly.py --against ../old    # also time another checkout, same n, same run

The model is the one of the cost table in ``docs/systems/rod.md``: ``CosseratRod("rod", n, gravity=True,
tau=0.01, c_v=0.1)`` (stiffness-proportional Kelvin-Voigt damping, viscous drag, weight; ``6 n`` states)
assembled alone by ``phs.interconnect`` and translated by ``codegen.generate``.  Each n is built in a fresh
interpreter, so no sympy cache or generated function carries over from one size to the next.

* **assembly**: ``interconnect`` (the rod's piece, the junction solve, the structure matrices, the
  dissipation forms and the construction checks of ``PHSystem``);
* **codegen**: ``generate`` (model hash, translation to CasADi, the ten functions).

Both are reported as wall seconds and CPU seconds of the process (``time.process_time``); on a shared
machine the CPU seconds are the steadier figure and the growth exponents (least-squares slope of
log(seconds) against log(n)) are fitted to them.  The baseline is the smallest n of the same run: each
size is also given as the ratio of its total to the smallest size's total, next to the ratio of the
sizes (what linear growth would give).  With ``--against DIR`` the same sizes are built from the
checkout in ``DIR`` as well (an older commit, for instance), in the same run, and the ratio
``theirs / ours`` is printed for each size.

Targets: n = 100 assembled and generated in under 30 s, growth no faster than about n^1.2.
The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
TARGET_SECONDS_100 = 30.0
TARGET_GROWTH = 1.2


def _child(n: int, root: str) -> None:
    """Build the rod of n elements from the checkout in ``root``; print one JSON line of timings."""
    sys.path.insert(0, os.path.abspath(root))
    from codegen import generate
    from components import CosseratRod
    from phs import interconnect

    w0, c0 = time.perf_counter(), time.process_time()
    system = interconnect("rod", [CosseratRod("rod", n, gravity=True, tau=0.01, c_v=0.1)])
    w1, c1 = time.perf_counter(), time.process_time()
    generate(system)
    w2, c2 = time.perf_counter(), time.process_time()
    print(json.dumps({"n": n, "states": len(system.states), "assembly_wall": w1 - w0, "assembly_cpu": c1 - c0,
                      "codegen_wall": w2 - w1, "codegen_cpu": c2 - c1}))


def _measure(n: int, root: str) -> dict:
    proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", str(n), "--root", root],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"building n={n} from {root} failed:\n{proc.stderr[-2000:]}")
    row = json.loads(proc.stdout.strip().splitlines()[-1])
    return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in row.items()}


def _slope(ns, values) -> float:
    return round(float(np.polyfit(np.log(ns), np.log(values), 1)[0]), 3)


def _series(ns, root: str, label: str) -> dict:
    rows = {}
    for n in ns:
        r = rows[n] = _measure(n, root)
        r["total_wall"] = round(r["assembly_wall"] + r["codegen_wall"], 3)
        r["total_cpu"] = round(r["assembly_cpu"] + r["codegen_cpu"], 3)
        base = rows[ns[0]]
        print(f"{label} n={n:<4} ({r['states']:4d} states)  assembly {r['assembly_wall']:7.2f} s wall "
              f"{r['assembly_cpu']:7.2f} s cpu   codegen {r['codegen_wall']:6.2f} s wall {r['codegen_cpu']:6.2f} s cpu   "
              f"total/total(n={ns[0]}) {r['total_cpu'] / base['total_cpu']:5.2f} cpu (n ratio {n / ns[0]:g})",
              flush=True)
    fit = {f"{part}_exponent": _slope(ns, [rows[n][f"{part}_cpu"] for n in ns]) for part in ("assembly", "codegen", "total")}
    fit["total_exponent_wall"] = _slope(ns, [rows[n]["total_wall"] for n in ns])
    print(f"{label} growth (cpu seconds): assembly n^{fit['assembly_exponent']}, codegen n^{fit['codegen_exponent']}, "
          f"total n^{fit['total_exponent']} (wall: n^{fit['total_exponent_wall']})", flush=True)
    return {"rows": {str(n): rows[n] for n in ns}, **fit}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="n = 6, 12")
    ap.add_argument("--full", action="store_true", help="also n = 200")
    ap.add_argument("--against", metavar="DIR", help="also build from the checkout in DIR (the baseline code)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--root", default=ROOT, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        _child(args.child, args.root)
        return {}
    ns = [6, 12] if args.quick else [25, 50, 100] + ([200] if args.full else [])
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = None
    print(f"load average at start: {load} on {os.cpu_count()} cores", flush=True)
    ours = _series(ns, ROOT, "ours")
    out = {"quick": args.quick, "n": ns, "load_average_start": load, "ours": ours}
    if args.against:
        theirs = _series(ns, args.against, "baseline")
        out["baseline"] = theirs
        out["ratio_baseline_over_ours_cpu"] = {
            str(n): round(theirs["rows"][str(n)]["total_cpu"] / ours["rows"][str(n)]["total_cpu"], 2) for n in ns}
        out["ratio_baseline_over_ours_wall"] = {
            str(n): round(theirs["rows"][str(n)]["total_wall"] / ours["rows"][str(n)]["total_wall"], 2) for n in ns}
        print("baseline / ours (total, cpu): " + ", ".join(f"n={n} {r}" for n, r in out["ratio_baseline_over_ours_cpu"].items()))
    if 100 in ns:
        r100 = ours["rows"]["100"]
        out["targets_met"] = {"n100_under_30s_wall": r100["total_wall"] < TARGET_SECONDS_100,
                              "n100_under_30s_cpu": r100["total_cpu"] < TARGET_SECONDS_100,
                              "growth_at_most_1.2": ours["total_exponent"] <= TARGET_GROWTH}
        print(f"targets: n=100 in {r100['total_wall']:.1f} s wall / {r100['total_cpu']:.1f} s cpu (< {TARGET_SECONDS_100:g} s), "
              f"growth n^{ours['total_exponent']} (<= {TARGET_GROWTH})")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
