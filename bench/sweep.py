"""Benchmark: a 1000-variant design study of the 4-segment curling HASEL, four ways, in one run.

Each variant simulates 10 s under the 2 Hz, 0-5 kV square drive of
``bench/simulate_curling_hasel.py`` (40 edges, output every 1 ms) with
parameters drawn by Latin hypercube (K_b, b, gamma1, K, C1 within +-15 % of
their values, all inside the validity domain), and computes metrics of the tip
displacement: its peak, its final value and its rise time over the first
on-phase (``--energy`` adds the energy supplied by the source).  Timed:

* **threaded map**: :func:`phs.workflows.sweep.sweep` with its default executor
  (CasADi ``map`` over the chained CVODES integrators in 2 threads, chunks,
  metrics, no file);
* **serial loop**: a Python loop over :class:`codegen.Simulator` ``.run`` with
  the same metrics (what a user of the simulator would write);
* **Dask**: the same ``sweep`` on a ``LocalCluster`` of 2 worker processes (one
  thread each); the cluster is started before the clock starts (its start-up
  time is printed separately: a lab cluster is already running);
* **solve_ivp baseline**: a Python loop over ``scipy.integrate.solve_ivp``
  (LSODA) of the lambdified model with its exact Jacobian, restarted at every
  edge like ours, on a subset of the variants, extrapolated to all of them
  (with ``--energy``, the supplied energy integrated as one more state).

Fairness: equal tolerances (``rtol=1e-8``; ``atol`` on the scaled states, so
solve_ivp gets ``atol * s``); every path computes the same metrics from its own
trajectory, ours checking the validity domain at every output point.  With
``--energy`` ours integrate the energy of every resistor as well (quadratures:
the study asks for them when a metric needs energy), the baseline only the
supplied energy.  The baseline's symbolic Jacobian and lambdify time is
excluded; our integrator construction is included (the first chunk builds it).
The metrics of the serial loop and of Dask must equal the map's (same
integrators) to 1e-12 relative; the baseline's must agree to 1e-3 relative
(peak, final, energy) and one grid step (rise time).

Run ``python bench/sweep.py`` (``--quick``: 8 variants of 1 s; the smoke test).
The last line printed is one JSON object with ``ratio_map_vs_serial``,
``ratio_map_vs_solve_ivp``, ``ratio_dask_vs_map`` (throughput ratios) and the
figures behind them.
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import json
import logging
import os
import sys
import time

import numpy as np

TARGET_MAP_VS_SERIAL, TARGET_MAP_VS_SOLVE_IVP = 1.7, 20.0
SAME = 1e-12  # map, serial loop and Dask run the same integrators
BASELINE_AGREEMENT = 1e-3  # relative, peak and energy of solve_ivp at the same tolerances
HERE = os.path.dirname(os.path.abspath(__file__))


def _simulate_bench():
    """The baseline helpers of bench/simulate_curling_hasel.py (lambdified model, first steps to retry)."""
    spec = importlib.util.spec_from_file_location("simulate_curling_hasel", os.path.join(HERE, "simulate_curling_hasel.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _study(n: int, duration: float, with_energy: bool, seed: int = 0):
    from phs.signals import square
    from phs.workflows.sweep import Study, Uniform
    from phs.workflows.sweep.metrics import energy, final, peak, rise_time
    from systems.curling_hasel import curling_hasel

    system = curling_hasel(4)
    nominal = system.param_values()
    dists = {k: Uniform(0.85 * nominal[k], 1.15 * nominal[k]) for k in ("K_b", "b", "gamma1", "K", "C1")}
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0
    drive = square(2500.0, 2.0, offset=2500.0)  # unipolar 0 / 5000 V at 2 Hz
    x0 = {f"seg{i}.l_p": 0.015 for i in range(1, 5)}  # rest with l_p = L_v
    metrics = [peak("tip"), final("tip"), rise_time("tip", start=0.0, end=0.25)] + ([energy()] if with_energy else [])
    return Study(system, t, u={"U": drive}, x0=x0, distributions=dists, samples=n, seed=seed, metrics=metrics), drive



def _serial_loop(study, runs):
    """A Python loop over the project's simulator with the same metrics: (seconds, values (n, k), failures)."""
    from codegen import Simulator
    from phs import PHSError

    sim = Simulator(study.system, **study.options)
    values, failed = [], 0
    wall = time.perf_counter()
    for k in runs:
        try:
            res = sim.run(study.t, u=study.u, x0=study.x0, params=study.values(k))
            values.append([m(res)[0] for m in study.metrics])
        except PHSError:
            failed += 1
            values.append([np.nan] * len(study.metrics))
    return time.perf_counter() - wall, np.array(values), failed


def _baseline(study, drive, runs, sim_bench, with_energy):
    """solve_ivp (LSODA) of the lambdified model (plus the supplied energy as a state), restarted at every edge."""
    import sympy as sp
    from scipy.integrate import solve_ivp

    from codegen import Simulator
    from phs.workflows.sweep.metrics import rise_time_of

    s = study.system
    wall = time.perf_counter()
    f, j, _, _ = sim_bench._baseline_functions(s)
    supplied = s.power_balance["supplied"]
    args = (s.x, s.u, s.p)
    fs = sp.lambdify(args, supplied, cse=True)
    js = sp.lambdify(args, sp.Matrix([supplied]).jacobian(s.x), cse=True)
    tip = sp.lambdify([s.x, s.p], s.measured_expressions[s.measured_names.index("tip")], cse=True)
    setup = time.perf_counter() - wall
    sim = Simulator(s, **study.options)
    x0 = sim.initial_state(study.x0)
    scale = sim.scale
    rtol = sim.rtol
    atol = np.append(sim.atol * scale, 1e-12)  # supplied energy ~1e-3 J
    t = study.t
    edges = [float(t[0]), *[float(b) for b in drive.breakpoints(float(t[0]), float(t[-1]))], float(t[-1])]
    values, retries = [], 0
    nx = len(x0)
    ne = 1 if with_energy else 0
    if not with_energy:
        atol = atol[:nx]
    wall = time.perf_counter()
    for k in runs:
        p = s.param_vector(study.values(k))

        def fun(_t, z, u, p=p):
            xdot = f(z[:nx], u, p).ravel()
            return np.append(xdot, fs(z[:nx], u, p)) if ne else xdot

        def jac(_t, z, u, p=p):
            if not ne:
                return j(z, u, p)
            J = np.zeros((nx + 1, nx + 1))
            J[:nx, :nx] = j(z[:nx], u, p)
            J[nx, :nx] = np.asarray(js(z[:nx], u, p)).ravel()
            return J

        X = np.empty((len(t), nx + ne))
        z = np.append(x0, 0.0) if ne else np.array(x0, dtype=float)
        X[0] = z
        for a, b in itertools.pairwise(edges):
            level = np.array([float(drive(0.5 * (a + b)))])
            tol = 1e-12 * max(1.0, abs(b))
            idx = np.nonzero((t > a + tol) & (t <= b + tol))[0]
            te = t[idx]
            on_grid = len(te) > 0 and abs(te[-1] - b) <= tol
            t_eval = np.append(te[:-1] if on_grid else te, b) - a
            opts = dict(method="LSODA", t_eval=t_eval, jac=jac, rtol=rtol, atol=atol, args=(level,))
            with np.errstate(invalid="ignore"):
                sol = solve_ivp(fun, (0.0, b - a), z, **opts)
                for h0 in sim_bench.FIRST_STEPS:
                    if sol.success:
                        break
                    retries += 1
                    sol = solve_ivp(fun, (0.0, b - a), z, first_step=h0, **opts)
            if not sol.success:
                raise RuntimeError(f"solve_ivp LSODA failed for variant {k} on [{a}, {b}]: {sol.message}")
            X[idx] = sol.y[:, : len(idx)].T
            z = sol.y[:, -1]
        h = np.array([tip(x, p) for x in X[:, :nx]], dtype=float)
        sel = t <= 0.25
        values.append([h.max(), h[-1], rise_time_of(t[sel], h[sel])] + ([X[-1, nx]] if ne else []))
    return time.perf_counter() - wall, np.array(values), setup, retries


def _rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if not ok.any():
        return 0.0
    return float(np.max(np.abs(a[ok] - b[ok]) / np.maximum(np.abs(b[ok]), 1e-300)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="8 variants of 1 s, baseline on 2 (smoke test)")
    ap.add_argument("--variants", type=int, default=None, help="number of variants (default 1000)")
    ap.add_argument("--baseline-runs", type=int, default=None, help="variants integrated by solve_ivp (default 10)")
    ap.add_argument("--threads", type=int, default=2, help="threads of the map / Dask workers (default 2)")
    ap.add_argument("--energy", action="store_true", help="add the supplied-energy metric (energy quadratures)")
    args = ap.parse_args(argv)
    n, duration, n_base = (8, 1.0, 2) if args.quick else (1000, 10.0, 10)
    n = args.variants or n
    n_base = min(args.baseline_runs or n_base, n)
    workers = args.threads

    from phs.workflows.sweep import sweep

    wall = time.perf_counter()
    study, drive = _study(n, duration, args.energy)
    build = time.perf_counter() - wall
    print(f"curling HASEL, 4 segments: {n} variants (Latin hypercube, K_b, b, gamma1, K, C1 within +-15 %), "
          f"{duration:g} s each under the 2 Hz 0-5 kV square drive, output every 1 ms ({len(study.t)} points), "
          f"rtol={study.options['rtol']:g}; metrics: {', '.join(m.name for m in study.metrics)} "
          f"(model built in {build:.1f} s)")

    # 1. threaded map (the default executor)
    res_map = sweep(study, threads=workers, progress=False)
    t_map = res_map.seconds
    map_values = np.column_stack([res_map[m.name] for m in study.metrics])
    print(f"threaded map ({workers} threads): {t_map:.1f} s, {n / t_map:.2f} runs/s, {len(res_map.failed)} failed")

    # 2. Python loop over the project's simulator
    t_serial, serial_values, serial_failed = _serial_loop(study, range(n))
    print(f"serial loop over Simulator.run: {t_serial:.1f} s, {n / t_serial:.2f} runs/s, {serial_failed} failed")

    # 3. Dask LocalCluster, 2 worker processes
    from dask.distributed import Client, LocalCluster

    w0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    client.run(lambda: __import__("codegen.batch"))  # workers import the project (as a running cluster has)
    startup = time.perf_counter() - w0
    try:
        res_dask = sweep(study, scheduler=client, progress=False)
    finally:
        client.close()
        cluster.close()
    t_dask = res_dask.seconds
    dask_values = np.column_stack([res_dask[m.name] for m in study.metrics])
    print(f"Dask LocalCluster ({workers} processes): {t_dask:.1f} s, {n / t_dask:.2f} runs/s "
          f"(cluster start-up {startup:.1f} s, not included)")

    # 4. solve_ivp loop on a subset, extrapolated
    sim_bench = _simulate_bench()
    t_base, base_values, base_setup, retries = _baseline(study, drive, range(n_base), sim_bench, args.energy)
    per_base = t_base / n_base
    print(f"solve_ivp LSODA loop: {t_base:.1f} s for {n_base} variants, {per_base:.2f} s per run, "
          f"{n * per_base:.0f} s extrapolated to {n} (setup {base_setup:.1f} s not included; {retries} retried pieces)")

    per = {"map": t_map / n, "serial": t_serial / n, "dask": t_dask / n, "solve_ivp": per_base}
    ratio_serial = per["serial"] / per["map"]
    ratio_base = per["solve_ivp"] / per["map"]
    ratio_dask = per["map"] / per["dask"]
    same_serial = _rel(serial_values, map_values)
    same_dask = _rel(dask_values, map_values)
    sub = map_values[:n_base]
    cols = [0, 1] + ([3] if args.energy else [])  # peak, final (, energy): relative agreement
    agree_values = max(_rel(base_values[:, c], sub[:, c]) for c in cols)
    agree_rise = float(np.nanmax(np.abs(base_values[:, 2] - sub[:, 2]))) if n_base else 0.0

    print()
    print(f"{'path':<40}{'runs/s':>10}{'s per run':>12}{'s for ' + str(n):>14}{'map speed-up':>14}")
    for label, key in (("threaded map (sweep, default)", "map"), ("serial loop over Simulator.run", "serial"),
                       ("Dask LocalCluster, 2 processes", "dask"), ("solve_ivp LSODA loop (extrapolated)", "solve_ivp")):
        print(f"{label:<40}{1 / per[key]:>10.2f}{per[key]:>12.4f}{per[key] * n:>14.1f}{per[key] / per['map']:>14.2f}")
    print(f"ratios: map vs serial loop {ratio_serial:.2f}x (target >= {TARGET_MAP_VS_SERIAL:g}), map vs solve_ivp "
          f"{ratio_base:.1f}x (target >= {TARGET_MAP_VS_SOLVE_IVP:g}), Dask vs map {ratio_dask:.2f}x")
    print(f"agreement: serial loop vs map {same_serial:.1e}, Dask vs map {same_dask:.1e} (must be <= {SAME:g}); "
          f"solve_ivp vs map: {'peak/final/energy' if args.energy else 'peak/final'} {agree_values:.1e} "
          f"(<= {BASELINE_AGREEMENT:g}), rise time "
          f"{agree_rise * 1e3:.3f} ms (<= one 1 ms grid step)")
    ok = same_serial <= SAME and same_dask <= SAME and agree_values <= BASELINE_AGREEMENT and agree_rise <= 1e-3
    figures = {
        "ratio_map_vs_serial": ratio_serial,
        "ratio_map_vs_solve_ivp": ratio_base,
        "ratio_dask_vs_map": ratio_dask,
        "runs_per_second": {k: 1 / v for k, v in per.items()},
        "seconds": {"map": t_map, "serial": t_serial, "dask": t_dask, "solve_ivp_subset": t_base,
                    "solve_ivp_extrapolated": per_base * n, "dask_cluster_startup": startup,
                    "solve_ivp_setup": base_setup, "model_build": build},
        "variants": n, "solve_ivp_variants": n_base, "duration": duration, "samples_per_run": len(study.t),
        "threads": workers, "failed": {"map": len(res_map.failed), "serial": serial_failed,
                                        "dask": len(res_dask.failed)},
        "agreement": {"serial_vs_map": same_serial, "dask_vs_map": same_dask,
                      "solve_ivp_vs_map_values": agree_values, "solve_ivp_vs_map_rise_time_s": agree_rise},
        "results_agree": bool(ok),
        "targets_met": {"map_vs_serial": ratio_serial >= TARGET_MAP_VS_SERIAL,
                        "map_vs_solve_ivp": ratio_base >= TARGET_MAP_VS_SOLVE_IVP},
        "solve_ivp_retried_pieces": retries,
        "metrics": [m.name for m in study.metrics],
        "energy": bool(args.energy),
        "quick": bool(args.quick),
    }
    print(json.dumps(figures))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
