"""Benchmark: the 4-segment curling HASEL under a 2 Hz, 0-5 kV square drive.

Times ``codegen.simulator`` (CasADi + CVODES, scaled states, restarts at the
square-wave edges) against what a user would otherwise write in the same run:
the same sympy model (``system.dynamics`` and its exact Jacobian) lambdified
with ``cse=True`` into ``scipy.integrate.solve_ivp`` with ``method="BDF"`` and
with ``method="LSODA"``.  Then times model assembly + code generation for
growing segment counts.

Fairness
--------
* Same tolerances: our ``atol`` is on the scaled states ``x / s``
  (``s = StateInfo.typical``), so solve_ivp gets the array ``atol * s``.
  The default is ``rtol=1e-9``, ``atol=rtol/100``: at the simulator's default
  ``rtol=1e-8`` ours agrees with both scipy solutions to 7.5e-6, but scipy's
  BDF and LSODA final states differ from each other by 1.3e-5 (> 1e-5).
* The baseline is integrated piecewise between the square-wave edges (a
  restart at each edge, with the input held at that piece's level), as a
  careful user would do and as our simulator does; like ours, each piece
  is integrated in time from its start (the model is autonomous between
  edges), without which scipy's BDF fails at rtol=1e-8 (its minimum step
  is ten float spacings of t, too coarse for the 0.4 us electrical
  transient at a rising edge late in the run).
* Both sides write the output every 1 ms (``t_eval`` for solve_ivp).
* The baseline's symbolic Jacobian and lambdify time is reported separately,
  not in the ratios.  Our first run (which builds the CVODES integrator) is
  reported separately; the ratios use the median of repeated runs of both
  sides (the baseline caches nothing, so its first run counts among them),
  and the ratios against our first run are printed too.
* Like for like, our timed runs skip the energy quadratures (``energy=False``),
  which the baseline does not compute; a run with them is reported too.  Ours
  still checks the validity domain at every output.

Run ``python bench/simulate_curling_hasel.py`` (``--quick`` for a short smoke
run).  The last line printed is one JSON object with the figures; the exit
status is non-zero when the final states of the three integrators disagree by
more than 1e-5 relative to the state scales.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

AGREEMENT = 1e-5  # max |x_a - x_b| / s between the final states
TARGET_BDF, TARGET_LSODA = 30.0, 8.0
TARGET_CODEGEN_32, TARGET_GROWTH = 20.0, 2.2  # seconds for 32 segments; log-log slope ("about quadratic")
SLOW_BASELINE = 120.0  # seconds: above this, one baseline run only
FIRST_STEPS = (1e-6, 1e-9, 1e-12)  # seconds: solve_ivp's first steps to try when its own choice fails


# -- helpers ---------------------------------------------------------------------------------------
def _peak_rss_mb() -> float:
    """Peak resident memory of this process in MB (VmHWM; ru_maxrss would include the parent's at fork)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


def _codegen_child(n: int) -> None:
    """Assemble and generate ``n`` segments in this (fresh) interpreter; print one JSON line."""
    from codegen import generate
    from systems.curling_hasel import curling_hasel

    t0 = time.perf_counter()
    system = curling_hasel(n)
    t1 = time.perf_counter()
    generate(system)
    t2 = time.perf_counter()
    print(json.dumps({"n": n, "assembly": t1 - t0, "generate": t2 - t1, "states": len(system.states),
                      "peak_rss_mb": _peak_rss_mb()}))


def _codegen_times(segments: list[int]) -> dict[int, dict]:
    """Assembly + code generation per segment count, each in a fresh interpreter (no warm sympy caches)."""
    out = {}
    for n in segments:
        proc = subprocess.run([sys.executable, __file__, "--codegen-child", str(n)], capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"code generation for {n} segments failed:\n{proc.stderr[-2000:]}")
        out[n] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


def _growth_exponent(ns, secs) -> float:
    """Slope of log(seconds) against log(n_segments) (least squares)."""
    if len(ns) < 2:
        return float("nan")
    return float(np.polyfit(np.log(ns), np.log(secs), 1)[0])


# -- our simulator ---------------------------------------------------------------------------------
def _time_ours(system, t, drive, x0, rtol, atol, runs, compile=False, energy=False):
    """First-run seconds (incl. integrator construction), [repeat seconds], final state, x0, scale.

    ``energy=False`` skips the energy quadratures, which the baseline does not compute either
    (like for like); the table also reports a run with them.
    """
    from codegen import Simulator

    t0 = time.perf_counter()
    sim = Simulator(system, rtol=rtol, atol=atol, compile=compile, energy=energy)
    res = sim.run(t, u=drive, x0=x0)
    first = time.perf_counter() - t0
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        res = sim.run(t, u=drive, x0=x0)
        times.append(time.perf_counter() - t0)
    return first, times, res.x[-1].copy(), sim.initial_state(x0), sim.scale


# -- baseline: lambdify + solve_ivp ------------------------------------------------------------------
def _baseline_functions(system):
    """Lambdified (cse=True) right-hand side and exact Jacobian; (f, jac, symbolic seconds, lambdify seconds)."""
    import sympy as sp

    t0 = time.perf_counter()
    rhs = system.dynamics
    jac = rhs.jacobian(system.x)
    t1 = time.perf_counter()
    args = (system.x, system.u, system.p)
    f = sp.lambdify(args, rhs, cse=True)
    j = sp.lambdify(args, jac, cse=True)
    t2 = time.perf_counter()
    return f, j, t1 - t0, t2 - t1


def _baseline_run(method, f, j, p, t, drive, x0, rtol, atol_vec):
    """solve_ivp restarted at every edge of the drive, output on ``t``; returns (states (nt, nx), retries).

    A piece on which solve_ivp gives up is retried with the first steps ``FIRST_STEPS`` in turn (the
    retries are timed too): at a rising edge the electrode charge ``Q2`` starts near zero with a fast
    transient and its absolute tolerance ``atol * 2e-6`` C is tiny, so scipy's BDF can shrink its
    step below the spacing of floats at the start of a piece ("Required step size is less than
    spacing between numbers").
    """
    from scipy.integrate import solve_ivp

    def fun(_t, x, u):
        return f(x, u, p).ravel()

    def jac(_t, x, u):
        return j(x, u, p)

    t_start, t_end = float(t[0]), float(t[-1])
    edges = [t_start, *[float(b) for b in drive.breakpoints(t_start, t_end)], t_end]
    X = np.empty((len(t), len(x0)))
    X[0] = x0
    x = np.asarray(x0, dtype=float)
    retries = 0
    for a, b in itertools.pairwise(edges):
        level = np.array([float(drive(0.5 * (a + b)))])  # the drive is constant between edges
        tol = 1e-12 * max(1.0, abs(b))
        idx = np.nonzero((t > a + tol) & (t <= b + tol))[0]
        te = t[idx]
        on_grid = len(te) > 0 and abs(te[-1] - b) <= tol
        t_eval = np.append(te[:-1] if on_grid else te, b) - a  # end exactly on the edge (the restart point)
        # time from the piece's start (the model is autonomous between edges): near t = 30 s the spacing
        # of floats (~4e-15 s) would otherwise bound the sub-microsecond steps of the electrical transient
        opts = dict(method=method, t_eval=t_eval, jac=jac, rtol=rtol, atol=atol_vec, args=(level,))
        with np.errstate(invalid="ignore"):
            sol = solve_ivp(fun, (0.0, b - a), x, **opts)
            for h0 in FIRST_STEPS:
                if sol.success:
                    break
                retries += 1
                sol = solve_ivp(fun, (0.0, b - a), x, first_step=h0, **opts)
        if not sol.success:
            raise RuntimeError(f"solve_ivp {method} failed on [{a}, {b}] (also with first_step in {FIRST_STEPS}): "
                               f"{sol.message}")
        X[idx] = sol.y[:, : len(idx)].T
        x = sol.y[:, -1]
    return X, retries


def _time_baseline(method, f, j, p, t, drive, x0, rtol, atol_vec, runs):
    """([seconds per run], final state, pieces retried per run)."""
    times, X, retries = [], None, 0
    for k in range(runs):
        t0 = time.perf_counter()
        X, retries = _baseline_run(method, f, j, p, t, drive, x0, rtol, atol_vec)
        times.append(time.perf_counter() - t0)
        if k == 0 and times[0] > SLOW_BASELINE:
            break
    return times, X[-1].copy(), retries


# -- main ------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 s of simulation, 2 runs, 4 and 8 segments")
    ap.add_argument("--rtol", type=float, default=1e-9, help="relative tolerance (default 1e-9, see the docstring)")
    ap.add_argument("--atol", type=float, default=None, help="absolute tolerance on the scaled states (rtol/100)")
    ap.add_argument("--compile", action="store_true", help="also time our simulator with compile=True")
    ap.add_argument("--codegen-child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.codegen_child is not None:
        _codegen_child(args.codegen_child)
        return 0

    from phs.signals import square
    from systems.curling_hasel import curling_hasel

    duration, runs, segments = (3.0, 2, [4, 8]) if args.quick else (30.0, 5, [4, 8, 16, 32])
    rtol = args.rtol
    atol = args.atol if args.atol is not None else rtol / 100
    n_seg = 4
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0  # every 1 ms, exact multiples of 1e-3
    drive = square(2500.0, 2.0, offset=2500.0)  # unipolar 0 / 5000 V at 2 Hz
    levels = sorted({float(drive(x)) for x in (0.1, 0.3, 0.6, 0.8)})
    if levels != [0.0, 5000.0]:
        raise RuntimeError(f"drive levels {levels}, expected 0 and 5000 V")
    x0 = {f"seg{i}.l_p": 0.015 for i in range(1, n_seg + 1)}  # rest with l_p = L_v

    print(f"curling HASEL, {n_seg} segments: {duration:g} s under a 2 Hz 0-5 kV square drive, output every 1 ms "
          f"({len(t)} points), rtol={rtol:g}, atol={atol:g} on x/s (solve_ivp: atol*s)")
    system = curling_hasel(n_seg)
    p = system.param_vector()

    first, ours, x_ours, x0_vec, scale = _time_ours(system, t, drive, x0, rtol, atol, runs)
    e_first, e_times, *_ = _time_ours(system, t, drive, x0, rtol, atol, max(1, runs // 2), energy=True)
    compiled = None
    if args.compile:  # in an empty cache directory, so that the first run includes the C compilation
        old = os.environ.get("PHS_CACHE_DIR")
        with tempfile.TemporaryDirectory() as tmp:
            os.environ["PHS_CACHE_DIR"] = tmp
            try:
                c_first, c_times, x_comp, *_ = _time_ours(system, t, drive, x0, rtol, atol, runs, compile=True)
            finally:
                if old is None:
                    os.environ.pop("PHS_CACHE_DIR", None)
                else:
                    os.environ["PHS_CACHE_DIR"] = old
        compiled = (c_first, c_times, x_comp)

    f, j, sym_s, lamb_s = _baseline_functions(system)
    atol_vec = atol * scale
    bdf, x_bdf, retry_bdf = _time_baseline("BDF", f, j, p, t, drive, x0_vec, rtol, atol_vec, runs)
    lsoda, x_lsoda, retry_lsoda = _time_baseline("LSODA", f, j, p, t, drive, x0_vec, rtol, atol_vec, runs)

    med = statistics.median
    m_ours, m_bdf, m_lsoda = med(ours), med(bdf), med(lsoda)
    finals = {"ours": x_ours, "BDF": x_bdf, "LSODA": x_lsoda}
    if compiled:
        finals["ours (compiled)"] = compiled[2]
    names = list(finals)
    diffs = {f"{a} vs {b}": float(np.max(np.abs(finals[a] - finals[b]) / scale))
             for i, a in enumerate(names) for b in names[i + 1:]}
    worst = max(diffs.values())

    print()
    print(f"{'integrator':<34}{'first run [s]':>14}{'median [s]':>12}{'runs':>6}{'/ ours':>9}")
    print(f"{'ours (CasADi + CVODES)':<34}{first:>14.3f}{m_ours:>12.3f}{len(ours):>6}{1.0:>9.1f}")
    me = med(e_times)
    print(f"{'ours, with energy quadratures':<34}{e_first:>14.3f}{me:>12.3f}{len(e_times):>6}{me / m_ours:>9.2f}")
    if compiled:
        mc = med(compiled[1])
        print(f"{'ours, compile=True':<34}{compiled[0]:>14.3f}{mc:>12.3f}{len(compiled[1]):>6}{mc / m_ours:>9.2f}")
    for label, ts, m in (("solve_ivp BDF + exact Jacobian", bdf, m_bdf), ("solve_ivp LSODA + exact Jacobian", lsoda,
                                                                          m_lsoda)):
        extra = "   (one run only: a run took > 120 s)" if len(ts) < runs else ""
        print(f"{label:<34}{ts[0]:>14.3f}{m:>12.3f}{len(ts):>6}{m / m_ours:>9.1f}{extra}")
    print(f"ratios (median / median of ours): BDF {m_bdf / m_ours:.1f}x, LSODA {m_lsoda / m_ours:.1f}x; "
          f"against our first run: BDF {m_bdf / first:.1f}x, LSODA {m_lsoda / first:.1f}x")
    if compiled:
        print(f"with compile=True: BDF {m_bdf / mc:.1f}x, LSODA {m_lsoda / mc:.1f}x (first run, incl. gcc: "
              f"BDF {m_bdf / compiled[0]:.1f}x, LSODA {m_lsoda / compiled[0]:.1f}x)")
    n_pieces = len(drive.breakpoints(float(t[0]), float(t[-1]))) + 1
    print(f"solve_ivp restarted at every edge ({n_pieces} pieces); retries with first_step in {FIRST_STEPS} "
          f"after solve_ivp gave up on a piece: BDF {retry_bdf}, LSODA {retry_lsoda} per run")
    print(f"baseline setup (not timed above): dynamics + Jacobian in sympy {sym_s:.2f} s, lambdify(cse=True) "
          f"{lamb_s:.2f} s")
    print("final states, max |difference| / s: " + ", ".join(f"{k} {v:.2e}" for k, v in diffs.items())
          + f" ({'ok' if worst <= AGREEMENT else 'FAIL'}: <= {AGREEMENT:g})")
    print(f"targets: >= {TARGET_BDF:g}x BDF: {'met' if m_bdf / m_ours >= TARGET_BDF else 'NOT met'}; "
          f">= {TARGET_LSODA:g}x LSODA: {'met' if m_lsoda / m_ours >= TARGET_LSODA else 'NOT met'}")

    cg = _codegen_times(segments)
    print()
    print(f"{'segments':>8}{'states':>8}{'assembly [s]':>14}{'generate [s]':>14}{'total [s]':>11}{'peak RSS [MB]':>15}")
    for n, r in cg.items():
        total = r["assembly"] + r["generate"]
        print(f"{n:>8}{r['states']:>8}{r['assembly']:>14.2f}{r['generate']:>14.2f}{total:>11.2f}{r['peak_rss_mb']:>15.0f}")
    ns = list(cg)
    totals = [cg[n]["assembly"] + cg[n]["generate"] for n in ns]
    slope = _growth_exponent(ns, totals)
    local = (math.log(totals[-1] / totals[-2]) / math.log(ns[-1] / ns[-2])) if len(ns) > 1 else float("nan")
    print(f"growth: seconds ~ n^{slope:.2f} (least squares), n^{local:.2f} from {ns[-2]} to {ns[-1]} segments; "
          f"target <= n^{TARGET_GROWTH:g}" + (f", 32 segments <= {TARGET_CODEGEN_32:g} s" if 32 in cg else ""))
    print(f"peak RSS of this process: {_peak_rss_mb():.0f} MB")

    figures = {
        "ratio_vs_bdf": m_bdf / m_ours,
        "ratio_vs_lsoda": m_lsoda / m_ours,
        "ratio_vs_bdf_first_run": m_bdf / first,
        "ratio_vs_lsoda_first_run": m_lsoda / first,
        "codegen_seconds": {str(n): cg[n]["assembly"] + cg[n]["generate"] for n in ns},
        "assembly_seconds": {str(n): cg[n]["assembly"] for n in ns},
        "generate_seconds": {str(n): cg[n]["generate"] for n in ns},
        "codegen_growth_exponent": slope,
        "seconds_ours": m_ours,
        "seconds_ours_first_run": first,
        "seconds_bdf": m_bdf,
        "seconds_lsoda": m_lsoda,
        "runs": {"ours": len(ours), "bdf": len(bdf), "lsoda": len(lsoda)},
        "baseline_pieces": n_pieces,
        "baseline_retried_pieces": {"bdf": retry_bdf, "lsoda": retry_lsoda},
        "baseline_symbolic_seconds": sym_s,
        "baseline_lambdify_seconds": lamb_s,
        "final_state_rel_diff": worst,
        "final_states_agree": worst <= AGREEMENT,
        "duration": duration,
        "rtol": rtol,
        "atol": atol,
        "quick": bool(args.quick),
        "seconds_ours_with_energy": me,
        "peak_rss_mb": _peak_rss_mb(),
        "targets_met": {
            "ratio_vs_bdf": m_bdf / m_ours >= TARGET_BDF,
            "ratio_vs_lsoda": m_lsoda / m_ours >= TARGET_LSODA,
            "codegen_growth": slope <= TARGET_GROWTH,
            **({"codegen_32_seconds": totals[ns.index(32)] <= TARGET_CODEGEN_32} if 32 in cg else {}),
        },
    }
    if compiled:
        figures["seconds_ours_compiled"] = mc
        figures["seconds_ours_compiled_first_run"] = compiled[0]
        figures["ratio_vs_bdf_compiled"] = m_bdf / mc
        figures["ratio_vs_lsoda_compiled"] = m_lsoda / mc
    print(json.dumps(figures))
    return 0 if worst <= AGREEMENT else 1


if __name__ == "__main__":
    sys.exit(main())
