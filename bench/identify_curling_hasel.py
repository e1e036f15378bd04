"""Benchmark: grey-box identification of the 4-segment curling HASEL on synthetic data.

Synthetic recovery: 10 s at 1 kHz of ``systems.curling_hasel.curling_hasel(4)`` started at
``x0 = {f"seg{i}.l_p": 0.015}`` and driven by ``phs.signals.staircase(-1000.0, every=2.0, n_steps=5)``
sampled on the 1 ms grid; the sampled array is the input of the truth simulation and of both fits
(linearly interpolated between samples on both sides).  Measured: ``tip`` and ``current`` with seeded
Gaussian noise of 1 % of each signal's range.  Six free parameters ``K_b, b, gamma1, gamma2, C1, R2``
start +30 %, -30 %, +30 %, ... away from the truth.

Timed in the same run:

* **ours**: ``phs.workflows.identify.identify(system, rec, free, x0=X0, initial=perturbed)`` with its
  defaults (output error, CVODES forward sensitivities through CasADi, trust-region reflective; the
  dynamics and their derivatives compiled to C when a C compiler is available, as identify does by
  default for a fit of this size).
* **baseline**, what a user would otherwise write: ``system.dynamics``, its state Jacobian and the
  measured outputs (``system.measured_expressions``) lambdified with ``cse=True``;
  ``scipy.integrate.solve_ivp(method="LSODA", t_eval=t, rtol=1e-8, atol=1e-10 * s, jac=...)`` with the
  input ``np.interp(t, t_data, U)``; ``scipy.optimize.least_squares(method="trf", jac="2-point")``.

Fairness
--------
* Same coordinates: both fit ``p / p_start`` for ``K_b, b, gamma1, gamma2`` and ``log(p / p_start)``
  for ``C1`` and ``R2`` (the ones whose declared range spans >= 1.5 decades; identify's rule), same
  bounds (the parameters' declared ranges mapped to those coordinates), same ``ftol=1e-8``,
  ``xtol=gtol=1e-10`` and ``x_scale="jac"``.
* Same residual: ``(y_model - y_measured) / std(y_measured)`` per channel, cost ``0.5 * sum(r**2)``.
  Both final parameter sets are re-scored with one evaluator (our CVODES simulation at rtol 1e-8,
  and also the baseline's LSODA simulation), so the costs compared come from the same code.
* Same tolerances: ``rtol=1e-8``; our ``atol`` is ``1e-10`` on the scaled states ``x / s``
  (``s = StateInfo.typical``), so LSODA gets ``atol = 1e-10 * s``.
* The baseline's LSODA is given the exact (lambdified) state Jacobian: it halves LSODA's time here.
  The finite-difference step of ``least_squares`` is scipy's default unless ``--diff-step`` is given
  (``--diff-step 1e-4`` ~ ``sqrt(rtol)`` is the textbook choice for differences of a solution computed
  to ``rtol``; the default ``~1.5e-8`` is at the integration error's level).
* Sympy differentiation and lambdify (baseline) and our code generation are setup, printed separately and
  not in the ratio; our ``identify`` call is timed whole (building the sensitivity integrators included).
  Our C compilation is setup too: the libraries are cached on disk by a hash of the model (once per
  model, number of free parameters and fitted channels, whatever the data), so setup runs a short
  fit on the first 0.2 s that builds them (or finds them cached) and prints how long that took: the
  first fit of this model on a machine pays it once (``--cold`` measures that case: an empty cache,
  compilation inside the timed call).
* The baseline may be slow: it stops after ``--budget`` seconds (default 1200) or ``--max-sims``
  simulations; then its best point so far is scored, ``baseline_capped`` is true and the ratio is a
  lower bound (said in the text).
* Wall-clock and CPU seconds (``time.process_time``, plus the C compiler's when it runs inside the timed
  call) are both reported; on a shared machine the CPU ratio is the steadier figure.

Run ``python bench/identify_curling_hasel.py`` (``--quick``: 2 s of data, 2 free parameters ``K_b, gamma1``,
baseline capped at a few simulations, for the smoke test).  The last line printed is one JSON object
with at least ``ratio_vs_scipy_fd``, ``seconds``, ``baseline_seconds``, ``cost``, ``baseline_cost``,
``baseline_capped``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time

import numpy as np

TARGET_RATIO, TARGET_SECONDS = 20.0, 60.0
FREE = ["K_b", "b", "gamma1", "gamma2", "C1", "R2"]
FREE_QUICK = ["K_b", "gamma1"]
N_SEG = 4
RTOL = 1e-8
FTOL = 1e-8


def _cpu() -> float:
    """CPU seconds of this process and its finished children (the C compiler, when it runs)."""
    t = os.times()
    return time.process_time() + t.children_user + t.children_system


class _Capped(Exception):
    """Raised inside the baseline's residual when its budget is spent."""


def _synthetic(duration: float, seed: int):
    """(system, t, U, recording, x0 dict) of the noisy synthetic experiment."""
    from codegen.simulator import simulate
    from phs.signals import staircase
    from phs.workflows.recording import Recording
    from systems.curling_hasel import curling_hasel

    system = curling_hasel(N_SEG)
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0
    U = np.asarray(staircase(-1000.0, every=2.0, n_steps=5)(t), dtype=float)
    x0 = {f"seg{i}.l_p": 0.015 for i in range(1, N_SEG + 1)}
    truth = simulate(system, t, u={"U": U}, x0=x0, rtol=RTOL)
    rng = np.random.default_rng(seed)
    signals = {"U": U}
    for ch in ("tip", "current"):
        y = truth[ch]
        signals[ch] = y + 0.01 * np.ptp(y) * rng.standard_normal(len(t))
    return system, t, U, Recording.from_arrays(t, signals, source="synthetic curling HASEL"), x0


def _perturbed(system, free) -> dict:
    """Start values +30 %, -30 %, +30 %, ... away from the system's (true) values."""
    return {k: system.param(k).value * (1.3 if i % 2 == 0 else 0.7) for i, k in enumerate(free)}


def _log_scaled(system, free) -> list:
    """identify's default rule: positive parameters whose declared range spans >= 1.5 decades."""
    out = []
    for k in free:
        p = system.param(k)
        if p.value > 0 and p.range[0] > 0 and p.range[1] / p.range[0] >= 10**1.5:
            out.append(k)
    return out


# -- the baseline -------------------------------------------------------------------------------
class _Baseline:
    """Lambdified model + solve_ivp(LSODA) + least_squares with a finite-difference Jacobian."""

    def __init__(self, system, rec, free, start, x0_vec, scale, weights, log_scaled):
        import sympy as sp

        t0 = time.perf_counter()
        rhs = system.dynamics
        jac = rhs.jacobian(system.x)
        t1 = time.perf_counter()
        args = (system.x, system.u, system.p)
        self.f = sp.lambdify(args, rhs, cse=True)
        self.fx = sp.lambdify(args, jac, cse=True)
        self.h = [sp.lambdify(args, e, cse=True) for e in system.measured_expressions]
        t2 = time.perf_counter()
        self.symbolic_seconds, self.lambdify_seconds = t1 - t0, t2 - t1
        self.system, self.rec, self.free, self.log_scaled = system, rec, list(free), list(log_scaled)
        self.t, self.U = rec.t, rec["U"]
        self.outputs = ["tip", "current"]
        self.Y = np.vstack([rec[ch] for ch in self.outputs])
        self.W = np.array([weights[ch] for ch in self.outputs])[:, None]
        self.x0, self.atol = np.asarray(x0_vec, dtype=float), 1e-10 * np.asarray(scale, dtype=float)
        self.names = system.param_names
        self.p_start = system.with_params(start).param_vector()
        self.nominal = np.array([start[k] for k in free])
        self.sims = 0
        self.best = (np.inf, None)

    def params(self, z) -> np.ndarray:
        p = self.p_start.copy()
        for i, k in enumerate(self.free):
            p[self.names.index(k)] = self.nominal[i] * (np.exp(z[i]) if k in self.log_scaled else z[i])
        return p

    def values(self, z) -> dict:
        p = self.params(z)
        return {k: float(p[self.names.index(k)]) for k in self.free}

    def outputs_of(self, p):
        """Simulated measured outputs (n_out, N) with parameter vector ``p``, or None if LSODA fails."""
        from scipy.integrate import solve_ivp

        t, U = self.t, self.U

        def fun(tt, x):
            return self.f(x, [np.interp(tt, t, U)], p).ravel()

        def jac(tt, x):
            return self.fx(x, [np.interp(tt, t, U)], p)

        with np.errstate(all="ignore"):
            sol = solve_ivp(fun, (t[0], t[-1]), self.x0, method="LSODA", t_eval=t, jac=jac, rtol=RTOL,
                            atol=self.atol)
        self.sims += 1
        if not sol.success or sol.y.shape[1] != len(t) or not np.all(np.isfinite(sol.y)):
            return None
        return np.vstack([np.broadcast_to(np.asarray(h(sol.y, [U], p), dtype=float), t.shape) for h in self.h])

    def residual_of(self, p):
        Yhat = self.outputs_of(p)
        if Yhat is None:
            return None
        return ((Yhat - self.Y) * self.W).ravel()

    def fit(self, diff_step, budget, max_sims):
        """Run least_squares; returns (z, seconds, cpu seconds, capped, message, nfev, njev)."""
        import scipy.optimize

        lo, hi = [], []
        for i, k in enumerate(self.free):
            b = self.system.param(k).range
            nom = self.nominal[i]
            if k in self.log_scaled:
                lo.append(np.log(b[0] / nom))
                hi.append(np.log(b[1] / nom))
            else:
                lo.append(b[0] / nom)
                hi.append(b[1] / nom)
        z0 = np.array([0.0 if k in self.log_scaled else 1.0 for k in self.free])
        n_res = self.Y.size
        wall, cpu = time.perf_counter(), time.process_time()
        last = {}

        def fun(z):
            if time.perf_counter() - wall > budget or self.sims >= max_sims:
                raise _Capped
            r = self.residual_of(self.params(z))
            if r is None:  # a failed simulation: a large residual so that the step is rejected
                r0 = last.get("r")
                return np.full(n_res, 1e6) if r0 is None else 10 * np.abs(r0) + 1e3
            cost = 0.5 * float(r @ r)
            if cost < self.best[0]:
                self.best = (cost, np.array(z, dtype=float))
            last["r"] = r
            return r

        try:
            sol = scipy.optimize.least_squares(fun, z0, jac="2-point", bounds=(lo, hi), method="trf",
                                               x_scale="jac", ftol=FTOL, xtol=1e-10, gtol=1e-10,
                                               diff_step=diff_step, max_nfev=1000)
            z, capped, message, nfev, njev = sol.x, False, str(sol.message), int(sol.nfev), int(sol.njev or 0)
        except _Capped:
            z, capped, message, nfev, njev = self.best[1], True, "stopped by the budget", -1, -1
            if z is None:
                z = z0
        self.fit_sims = self.sims
        return z, time.perf_counter() - wall, time.process_time() - cpu, capped, message, nfev, njev


# -- one evaluator for both ---------------------------------------------------------------------------
def _cost_cvodes(system, rec, values, x0, weights) -> float:
    """0.5 sum r^2 of the weighted output error, simulated by our CVODES simulator."""
    from codegen.simulator import simulate

    res = simulate(system.with_params(values), rec.t, u={"U": rec["U"]}, x0=x0, rtol=RTOL)
    r = np.concatenate([(res[ch] - rec[ch]) * weights[ch] for ch in ("tip", "current")])
    return 0.5 * float(r @ r)


def _cost_lsoda(base: _Baseline, values: dict) -> float:
    p = base.p_start.copy()
    for k, v in values.items():
        p[base.names.index(k)] = v
    r = base.residual_of(p)
    return float("nan") if r is None else 0.5 * float(r @ r)


# -- main -----------------------------------------------------------------------------------------------
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 s of data, K_b and gamma1 free, baseline capped")
    ap.add_argument("--seed", type=int, default=20240611, help="noise seed")
    ap.add_argument("--budget", type=float, default=None, help="baseline wall-time cap [s] (default 1200)")
    ap.add_argument("--max-sims", type=int, default=None, help="baseline cap on simulations (quick: 9)")
    ap.add_argument("--diff-step", type=float, default=None,
                    help="relative finite-difference step of the baseline (default: scipy's)")
    ap.add_argument("--cold", action="store_true",
                    help="an empty compile cache: our compilation happens inside the timed identify call")
    args = ap.parse_args(argv)

    from codegen.functions import generate
    from codegen.simulator import Simulator
    from phs.workflows.identify import identify

    duration, free = (2.0, FREE_QUICK) if args.quick else (10.0, FREE)
    budget = args.budget if args.budget is not None else (120.0 if args.quick else 1200.0)
    max_sims = args.max_sims if args.max_sims is not None else (9 if args.quick else 10**9)

    t0 = time.perf_counter()
    system, t, U, rec, x0 = _synthetic(duration, args.seed)
    generate(system)  # already built by the truth simulation: cached
    setup_ours = time.perf_counter() - t0
    truth = {k: system.param(k).value for k in free}
    start = _perturbed(system, free)
    log_scaled = _log_scaled(system, free)
    weights = {ch: 1.0 / float(np.std(rec[ch])) for ch in ("tip", "current")}
    print(f"curling HASEL, {N_SEG} segments: {duration:g} s at 1 kHz ({len(t)} samples), staircase -1 kV every 2 s; "
          f"tip and current with 1 % noise (seed {args.seed}); free {', '.join(free)} from +-30 %; "
          f"log scale: {', '.join(log_scaled) or 'none'}")
    compile_seconds = 0.0
    if args.cold:  # a fresh, empty cache directory for this run
        import tempfile

        os.environ["PHS_CACHE_DIR"] = tempfile.mkdtemp(prefix="phs-cold-cache-")
    elif not args.quick:
        # what a previous fit of this model on this machine leaves behind: the compiled libraries
        wall = time.perf_counter()
        identify(system, rec.window(0.0, 0.2), free, x0=x0, initial=start, rtol=RTOL, ftol=FTOL, max_iter=1,
                 compile=True)
        compile_seconds = time.perf_counter() - wall

    # ours
    wall, cpu = time.perf_counter(), _cpu()
    fit = identify(system, rec, free, x0=x0, initial=start, rtol=RTOL, ftol=FTOL)
    seconds, cpu_ours = time.perf_counter() - wall, _cpu() - cpu
    if args.cold:
        shutil.rmtree(os.environ["PHS_CACHE_DIR"], ignore_errors=True)
    assert sorted(fit.log_scaled) == sorted(log_scaled), (fit.log_scaled, log_scaled)

    # baseline
    sim = Simulator(system, rtol=RTOL)
    base = _Baseline(system, rec, free, start, sim.initial_state(x0), sim.scale, fit.weights, log_scaled)
    z, b_seconds, b_cpu, capped, b_message, b_nfev, b_njev = base.fit(args.diff_step, budget, max_sims)
    b_values = base.values(z)

    cost = _cost_cvodes(system, rec, fit.values, x0, weights)
    b_cost = _cost_cvodes(system, rec, b_values, x0, weights)
    cost_l, b_cost_l = _cost_lsoda(base, fit.values), _cost_lsoda(base, b_values)
    true_cost = _cost_cvodes(system, rec, truth, x0, weights)
    ratio, ratio_cpu = b_seconds / seconds, b_cpu / cpu_ours
    cost_ok = cost <= b_cost * (1 + 1e-6)
    bound = ">= " if capped else ""

    print()
    print(f"{'':<34}{'wall [s]':>10}{'CPU [s]':>10}{'cost (CVODES)':>16}{'cost (LSODA)':>15}  evaluations")
    print(f"{'ours (identify, CVODES sens.)':<34}{seconds:>10.2f}{cpu_ours:>10.2f}{cost:>16.6g}{cost_l:>15.6g}"
          f"  {fit.iterations} residual+Jacobian")
    print(f"{'baseline (least_squares 2-point)':<34}{b_seconds:>10.2f}{b_cpu:>10.2f}{b_cost:>16.6g}{b_cost_l:>15.6g}"
          f"  {base.fit_sims} LSODA simulations" + (" (CAPPED)" if capped else ""))
    print(f"cost at the true parameters (CVODES): {true_cost:.6g}")
    print(f"ratio baseline / ours: wall {bound}{ratio:.1f}x, CPU {bound}{ratio_cpu:.1f}x"
          + (f"  -- the baseline was stopped by its cap ({budget:g} s / {max_sims} simulations), so these are "
             "lower bounds" if capped else ""))
    print(f"ours: {fit.message}; baseline: {b_message}"
          + (f" (nfev {b_nfev}, njev {b_njev})" if b_nfev >= 0 else ""))
    print(f"{'parameter':<10}{'truth':>12}{'start':>12}{'ours':>14}{'rel. err':>10}{'baseline':>14}{'rel. err':>10}")
    for k in free:
        print(f"{k:<10}{truth[k]:>12.5g}{start[k]:>12.5g}{fit.values[k]:>14.6g}{fit.values[k] / truth[k] - 1:>+10.2%}"
              f"{b_values[k]:>14.6g}{b_values[k] / truth[k] - 1:>+10.2%}")
    print("fit % ours: " + ", ".join(f"{ch} {v:.2f}" for ch, v in fit.fit_percent.items()))
    print(f"setup (not in the ratio): synthetic data incl. our code generation {setup_ours:.2f} s; our C compilation "
          f"(or cache lookup) {compile_seconds:.2f} s; baseline sympy Jacobian {base.symbolic_seconds:.2f} s, lambdify "
          f"{base.lambdify_seconds:.2f} s" + (f"; finite-difference step {args.diff_step:g}" if args.diff_step
                                              else "; scipy's default FD step"))
    print(f"ours ran {'compiled C' if fit.compiled else 'CasADi interpreted functions'}"
          + ("; --cold: its compilation is inside the timed call" if args.cold else ""))
    print(f"targets: >= {TARGET_RATIO:g}x at equal or better cost: "
          f"{'met' if ratio >= TARGET_RATIO and cost_ok else 'NOT met'} (cost {'equal or better' if cost_ok else 'WORSE'}); "
          f"under {TARGET_SECONDS:g} s: {'met' if seconds < TARGET_SECONDS else 'NOT met'}")

    figures = {
        "ratio_vs_scipy_fd": ratio,
        "ratio_vs_scipy_fd_cpu": ratio_cpu,
        "seconds": seconds,
        "cpu_seconds": cpu_ours,
        "baseline_seconds": b_seconds,
        "baseline_cpu_seconds": b_cpu,
        "cost": cost,
        "baseline_cost": b_cost,
        "cost_lsoda": cost_l,
        "baseline_cost_lsoda": b_cost_l,
        "cost_reported_by_identify": fit.cost,
        "true_parameters_cost": true_cost,
        "baseline_capped": capped,
        "baseline_simulations": base.fit_sims,
        "baseline_message": b_message,
        "iterations": fit.iterations,
        "values": fit.values,
        "baseline_values": b_values,
        "truth": truth,
        "start": start,
        "relative_errors": {k: fit.values[k] / truth[k] - 1 for k in free},
        "baseline_relative_errors": {k: b_values[k] / truth[k] - 1 for k in free},
        "fit_percent": fit.fit_percent,
        "free": free,
        "log_scaled": log_scaled,
        "diff_step": args.diff_step,
        "budget_seconds": budget,
        "duration": duration,
        "quick": bool(args.quick),
        "compiled": fit.compiled,
        "cold": bool(args.cold),
        "setup_compile_seconds": compile_seconds,
        "baseline_symbolic_seconds": base.symbolic_seconds,
        "baseline_lambdify_seconds": base.lambdify_seconds,
        "targets_met": {"ratio": ratio >= TARGET_RATIO, "cost_equal_or_better": cost_ok,
                        "seconds": seconds < TARGET_SECONDS},
    }
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
