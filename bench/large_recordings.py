"""Benchmark: long recordings (10⁴ to 10⁶ samples) simulated and identified, growth and peak memory.

The mass-spring-damper (``systems.examples.mass_spring_damper``) sampled at 10 kHz: a smooth multisine force
``F`` (0.7, 1.9 and 5.3 Hz) and its position (simulated from the force as an expression, 1e-3 of noise),
written as a CSV file of ``n`` rows (``t,F,position``), as a data logger hands it over.  For each ``n``, in a
fresh interpreter (its own caches and peak memory):

* **simulate**: what ``phs simulate MODEL --input file.csv`` does: read the inputs from the file
  (:func:`phs.workflows.inputs.read_input_csv`) and simulate on the file's grid (``codegen.Simulator``,
  ``energy=True``, as the command runs);
* **identify**: what ``phs fit`` does: read the recording (:meth:`phs.workflows.recording.Recording.from_csv`)
  and fit ``k.K`` and ``b.b`` from +25 % (:func:`phs.workflows.identify.identify`).

Each child prints its seconds and its peak resident memory above what it held after its imports
(``resource.getrusage``).  The growth exponent is the least-squares slope of log(seconds) against log(n)
(goal: at most 1.1; a quadratic step gives 2).  Baseline, in the same run: the previous path for the
simulation (CasADi's own B-spline interpolant at every size, ``codegen._interpolants.BSPLINE_BANDED_FROM``
set beyond the sizes, and the cell-by-cell CSV reading, ``phs.workflows.inputs._fast_rows`` disabled), up to
``--baseline-max`` samples (its build time grows quadratically: 2.2 s at 10⁵, 11 s at 2·10⁵).

    python bench/large_recordings.py             # 10^4, 3*10^4, 10^5, 3*10^5, 10^6 (a few minutes)
    python bench/large_recordings.py --quick     # 10^4, 3*10^4, 10^5, simulation only (~1 min)

The last line is one JSON object: ``sizes``, ``simulate_seconds`` and ``identify_seconds`` by size,
``identify_iterations``, ``simulate_growth``, ``identify_growth`` (and ``identify_growth_per_iteration``: the
number of iterations depends on the data; ``growth_from_1e5``: the slopes over the sizes from 10⁵ on, where a
run's fixed costs weigh least), ``peak_mb`` by size (the larger of the two children),
``baseline_simulate_seconds`` and ``baseline_growth``, ``fitted`` (k.K and b.b at the largest size),
``identify_1e6_under_30s``, ``growth_goal_met``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

FS = 1e4
FORCE = "sin(2*pi*0.7*t) + 0.5*sin(2*pi*1.9*t + 0.3) + 0.3*sin(2*pi*5.3*t + 1.0)"


def write_recording(n: int, path: str) -> None:
    """The CSV recording of ``n`` samples at 10 kHz: force, and position with 1e-3 of noise."""
    from codegen import simulate
    from systems.examples import mass_spring_damper

    t = np.arange(n) / FS
    F = np.sin(2 * np.pi * 0.7 * t) + 0.5 * np.sin(2 * np.pi * 1.9 * t + 0.3) + 0.3 * np.sin(2 * np.pi * 5.3 * t + 1.0)
    y = np.asarray(simulate(mass_spring_damper(), t, u={"F": FORCE})["position"])
    y = y + 1e-3 * np.random.default_rng(n).standard_normal(n)
    np.savetxt(path, np.column_stack([t, F, y]), delimiter=",", header="t,F,position", comments="", fmt="%.10g")


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def child(task: str, path: str, baseline: bool) -> dict:
    """One measurement in this interpreter: ``task`` ("simulate" or "identify") on the file ``path``."""
    import codegen._interpolants as interpolants
    import phs.workflows.inputs as inputs
    from codegen import Simulator
    from phs.workflows.identify import identify
    from phs.workflows.recording import Recording
    from systems.examples import mass_spring_damper

    if baseline:
        interpolants.BSPLINE_BANDED_FROM = 10**12
        inputs._fast_rows = lambda p: None
    system = mass_spring_damper()
    rss0 = _rss_mb()
    w = time.perf_counter()
    out: dict = {}
    if task == "simulate":
        t, sigs = inputs.read_input_csv(path, system)
        res = Simulator(system).run(t, u=sigs)
        out["final_position"] = float(np.asarray(res["position"])[-1])
    else:
        rec = Recording.from_csv(path)
        fit = identify(system, rec, ["k.K", "b.b"], initial={"k.K": 5.0, "b.b": 0.5})
        out["fitted"] = {k: float(fit.values[k]) for k in ("k.K", "b.b")}
        out["iterations"] = int(fit.iterations)
    out["seconds"] = time.perf_counter() - w
    out["peak_mb"] = _rss_mb() - rss0
    return out


def run_child(task: str, path: str, baseline: bool = False) -> dict:
    cmd = [sys.executable, os.path.abspath(__file__), "--child", task, path] + (["--baseline"] if baseline else [])
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if proc.returncode != 0:
        raise SystemExit(f"{task} on {path} failed: {proc.stderr.strip().splitlines()[-1:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def growth(sizes, seconds) -> float:
    """The least-squares slope of log(seconds) against log(sizes)."""
    return float(np.polyfit(np.log(sizes), np.log(seconds), 1)[0])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10^4 to 10^5 samples, simulation only")
    ap.add_argument("--sizes", help="comma-separated numbers of samples (default: 1e4,3e4,1e5,3e5,1e6)")
    ap.add_argument("--baseline-max", type=float, default=1e5, help="largest size the previous path is timed at")
    ap.add_argument("--child", nargs=2, metavar=("TASK", "FILE"), help=argparse.SUPPRESS)
    ap.add_argument("--baseline", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(*args.child, args.baseline)))
        return
    default = "1e4,3e4,1e5" if args.quick else "1e4,3e4,1e5,3e5,1e6"
    sizes = [int(float(s)) for s in (args.sizes or default).split(",")]
    sim, ide, its, peak, base, fitted = {}, {}, {}, {}, {}, None
    with tempfile.TemporaryDirectory() as d:
        for n in sizes:
            path = os.path.join(d, f"r{n}.csv")
            write_recording(n, path)
            s = run_child("simulate", path)
            sim[n], peak[n] = s["seconds"], s["peak_mb"]
            line = f"n = {n:>8}  simulate {s['seconds']:7.2f} s"
            if not args.quick:
                i = run_child("identify", path)
                ide[n], peak[n], fitted, its[n] = i["seconds"], max(peak[n], i["peak_mb"]), i["fitted"], i["iterations"]
                line += (f"  identify {i['seconds']:7.2f} s in {its[n]} iterations "
                         f"(k.K {fitted['k.K']:.5f}, b.b {fitted['b.b']:.5f})")
            if n <= args.baseline_max:
                b = run_child("simulate", path, baseline=True)
                base[n] = b["seconds"]
                line += f"  previous path: simulate {b['seconds']:7.2f} s"
            print(line + f"  peak {peak[n]:6.0f} MB", flush=True)
    ns = sorted(sim)
    g_sim = growth(ns, [sim[n] for n in ns])
    g_ide = growth(ns, [ide[n] for n in ns]) if ide else None
    g_per = growth(ns, [ide[n] / its[n] for n in ns]) if ide else None
    top = [n for n in ns if n >= 100_000]  # the fixed costs of a run weigh least there
    g_top = {"simulate": round(growth(top, [sim[n] for n in top]), 3)} if len(top) > 1 else {}
    if ide and len(top) > 1:
        g_top["identify"] = round(growth(top, [ide[n] for n in top]), 3)
    g_base = growth(sorted(base), [base[n] for n in sorted(base)]) if len(base) > 1 else None
    print(f"growth exponent: simulate {g_sim:.2f}" + (f", identify {g_ide:.2f}" if g_ide is not None else "")
          + (f", previous path (simulate, up to {max(base)}) {g_base:.2f}" if g_base is not None else "")
          + "  (goal: at most 1.1)")
    if g_top:
        print("growth exponent from 10^5 on: " + ", ".join(f"{k} {v:.2f}" for k, v in g_top.items()))
    big = ide.get(1_000_000)
    if big is not None:
        print(f"identify 10^6 samples: {big:.1f} s (goal: under 30 s)")
    print(json.dumps({
        "sizes": ns, "quick": args.quick,
        "simulate_seconds": {str(n): round(sim[n], 3) for n in ns},
        "identify_seconds": {str(n): round(ide[n], 3) for n in sorted(ide)},
        "identify_iterations": {str(n): its[n] for n in sorted(its)},
        "simulate_growth": round(g_sim, 3), "identify_growth": None if g_ide is None else round(g_ide, 3),
        "identify_growth_per_iteration": None if g_per is None else round(g_per, 3), "growth_from_1e5": g_top,
        "peak_mb": {str(n): round(peak[n], 1) for n in ns},
        "baseline_simulate_seconds": {str(n): round(base[n], 3) for n in sorted(base)},
        "baseline_growth": None if g_base is None else round(g_base, 3),
        "fitted": fitted, "identify_1e6_under_30s": None if big is None else bool(big < 30.0),
        "growth_goal_met": bool(g_sim <= 1.1 and (g_ide is None or g_ide <= 1.1)),
    }))


if __name__ == "__main__":
    main()
