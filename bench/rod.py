"""Benchmark: the planar Cosserat rod (``components.CosseratRod``): build cost, and a damped cantilever under a
tip load, against a fine reference and, when ``pyelastica`` is importable, against pyelastica.

    python bench/rod.py             # n = 10, 20, 40
    python bench/rod.py --full      # n = 10, 20, 40, 80
    python bench/rod.py --quick     # n = 6, 12, one timed run each (smoke test)
    python bench/rod.py --no-elastica

The problem: a rod of length 1 m, circular cross-section of radius 0.02 m, density 1000 kg/m**3,
E = 1 MPa, G = E/3 (Poisson ratio 0.5), shear factor 27/28 (pyelastica's), clamped at the base along +x,
under a constant tip force F_y = -2 EI/L**2 in the fixed frame (static tip deflection about 0.5 L), from rest.

* **Build**: ``interconnect`` (assembly of the port-Hamiltonian system) and ``codegen.generate`` for each n,
  timed once each; the growth exponent is the least-squares slope of log(seconds) against log(n).
* **Reference**: the static tip position of the same continuum rod (extension, shear and bending,
  ``scipy.integrate.solve_bvp`` at tolerance 1e-10), independent of both discretisations.
* **Ours**: ``codegen.simulator`` (CasADi + CVODES, rtol 1e-8) from rest to ``T = 30/omega_1``; the first run
  (which builds the integrator) and the median of 3 further runs are reported; the tip error is the distance
  of the final tip from the reference, in units of L.
* **pyelastica** (3-D rod, the same material, geometry and load; ``PositionVerlet`` with its customary
  ``dt = 0.01 dx``): run once on a tiny problem first so numba's compilation is not timed, then the
  median of 3 runs to the same ``T``.

How damping was matched.  pyelastica's ``AnalyticalLinearDamper`` with ``uniform_damping_constant = nu``
multiplies every nodal velocity and angular velocity by ``exp(-nu dt)`` each step: mass-proportional
damping, ``v' = -nu v``, modal decay rate ``nu/2`` for every mode.  Ours gets the same law for the
translations from the rod's viscous drag, ``c_v = rho A nu`` (force ``c_v h_k v_k = nu m_k v_k`` with the
same lumped masses, half at the tip, as pyelastica's), and a tiny Kelvin–Voigt ``tau = 1e-6 s`` for the
cross-section rotations (it damps the shear modes, about 1.8e3 rad/s, at a rate near ``nu/2``, as
pyelastica's angular damping does).  The rod's default stiffness-proportional damping ``R = tau K_0`` is
not used for the matching: it is taken at the straight configuration, so at a large deflection it damps
the rigid rotation of the elements through the axial stiffness and the cantilever creeps to its rest
state orders of magnitude slower than pyelastica's (a first attempt with ``tau = 1/omega_1`` had covered
0.4 of the static deflection at ``T``).  With ``nu = omega_1`` (first-mode damping ratio 0.5) and
``T = 30/omega_1`` the transient has decayed by ``exp(-15) = 3e-7`` in both codes, far below the
discretisation errors compared; only the settled tip is compared, not the trajectories.

How accuracy was matched.  At each n both codes' tip errors against the reference are printed.  The two
discretisations do not have the same error at the same n, so the ratio "at equal tip accuracy" fits
``error = C n**-p`` and ``seconds = D n**q`` to each code's measured points and compares the wall time each
would need to reach our error at our largest n (an interpolation when pyelastica's measured errors
bracket ours, an extrapolation otherwise — the JSON says which).  The ratio at equal n is printed too.

What is not compared: our build time (assembly and code generation, reported separately) has no
counterpart in pyelastica, whose set-up is a few milliseconds; the ratios use run times only, and the
JSON also carries first-run times.  The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time

import numpy as np
from scipy.integrate import solve_bvp

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from codegen import generate, simulator  # noqa: E402
from components import CosseratRod, ForceSource, TorqueSource  # noqa: E402
from phs import interconnect, series  # noqa: E402

L, RADIUS, RHO, E = 1.0, 0.02, 1000.0, 1e6
G, KS = E / 3, 27 / 28
A, I = math.pi * RADIUS**2, math.pi * RADIUS**4 / 4  # noqa: E741
EI = E * I
FY = -2 * EI / L**2
OMEGA1 = 1.875104069**2 * math.sqrt(EI / (RHO * A * L**4))  # first clamped-free bending frequency [rad/s]
T_END = 30 / OMEGA1
NU = OMEGA1  # damping rate [1/s] of pyelastica's uniform damper
C_V, TAU = RHO * A * NU, 1e-6  # the same translational damping in ours; Kelvin-Voigt for the rotations


def _reference_tip() -> tuple[float, float]:
    """Static tip of the continuum rod under the tip force (``solve_bvp``)."""
    EA, GA = E * A, KS * G * A

    def rhs(s, Y):
        x, y, th, nx, ny, m = Y
        c, sn = np.cos(th), np.sin(th)
        nu1, nu2 = (c * nx + sn * ny) / EA, (-sn * nx + c * ny) / GA
        xp, yp = (1 + nu1) * c - nu2 * sn, (1 + nu1) * sn + nu2 * c
        return np.vstack([xp, yp, m / EI, 0 * s, 0 * s, -(xp * ny - yp * nx)])

    def bc(a, b):
        return np.array([a[0], a[1], a[2], b[3], b[4] - FY, b[5]])

    s = np.linspace(0, L, 101)
    Y0 = np.zeros((6, s.size))
    Y0[0] = s
    sol = solve_bvp(rhs, bc, s, Y0, tol=1e-10, max_nodes=200000)
    if not sol.success:
        raise RuntimeError(f"reference solve_bvp failed: {sol.message}")
    return float(sol.y[0, -1]), float(sol.y[1, -1])


def _cantilever(n: int):
    rod = CosseratRod("rod", n=n, L=L, E=E, G=G, k_s=KS, I=I, A=A, rho=RHO, tau=TAU, c_v=C_V, tip="force")
    return interconnect("cantilever", [rod, ForceSource("Fx"), ForceSource("Fy"), TorqueSource("M")],
                        [series("Fx", "rod.tip_x"), series("Fy", "rod.tip_y"), series("M", "rod.tip_m")])


def _ours(n: int, ref: tuple[float, float], runs: int) -> dict:
    t0 = time.perf_counter()
    system = _cantilever(n)
    t1 = time.perf_counter()
    generate(system)
    t2 = time.perf_counter()
    sim = simulator(system, rtol=1e-8)
    t = np.linspace(0.0, T_END, 271)  # output every 0.1 s: CVODES limits the steps between outputs
    seconds = []
    for _ in range(runs + 1):
        s0 = time.perf_counter()
        res = sim.run(t, u={"Fx": 0.0, "Fy": FY, "M": 0.0})
        seconds.append(time.perf_counter() - s0)
    tip = (L + res[f"rod.ux{n}"][-1], res[f"rod.uy{n}"][-1])
    return {"assembly_seconds": round(t1 - t0, 3), "codegen_seconds": round(t2 - t1, 3),
            "first_run_seconds": round(seconds[0], 4), "run_seconds": round(statistics.median(seconds[1:]), 4),
            "tip_error": float(math.hypot(tip[0] - ref[0], tip[1] - ref[1]) / L)}


def _elastica_run(ea, n: int, final_time: float) -> tuple[float, tuple[float, float]]:
    class Cantilever(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    dt = 0.01 * L / n
    sim = Cantilever()
    rod = ea.CosseratRod.straight_rod(n, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), L, RADIUS,
                                      RHO, youngs_modulus=E, shear_modulus=G)
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), np.array([0.0, FY, 0.0]), ramp_up_time=dt)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=NU, time_step=dt)
    sim.finalize()
    steps = int(round(final_time / dt))
    t0 = time.perf_counter()
    ea.integrate(ea.PositionVerlet(), sim, steps * dt, steps, progress_bar=False)
    sec = time.perf_counter() - t0
    return sec, (float(rod.position_collection[0, -1]), float(rod.position_collection[1, -1]))


def _elastica(ea, n: int, ref: tuple[float, float], runs: int) -> dict:
    seconds, tip = [], None
    for _ in range(runs):
        sec, tip = _elastica_run(ea, n, T_END)
        seconds.append(sec)
    return {"run_seconds": round(statistics.median(seconds), 4), "steps": int(round(T_END / (0.01 * L / n))),
            "tip_error": float(math.hypot(tip[0] - ref[0], tip[1] - ref[1]) / L)}


def _slope(ns, values) -> float:
    return float(np.polyfit(np.log(ns), np.log(values), 1)[0])


def _at_equal_accuracy(ns, ours: dict, theirs: dict, target: float) -> dict:
    """Wall time each code needs for the tip error ``target``, from power-law fits over the measured n."""
    out = {"target_tip_error": target}
    for label, rows in (("ours", ours), ("pyelastica", theirs)):
        err = [rows[n]["tip_error"] for n in ns]
        pe, ce = np.polyfit(np.log(ns), np.log(err), 1)
        ps, cs = np.polyfit(np.log(ns), np.log([rows[n]["run_seconds"] for n in ns]), 1)
        n_needed = math.exp((math.log(target) - ce) / pe) if pe < 0 else None
        out[label] = {"error_order": round(-pe, 2), "time_exponent": round(ps, 2),
                      "n_needed": None if n_needed is None else round(n_needed, 1),
                      "seconds_needed": None if n_needed is None else float(math.exp(cs + ps * math.log(n_needed))),
                      "interpolated": min(err) <= target <= max(err)}
    sec_o, sec_p = out["ours"]["seconds_needed"], out["pyelastica"]["seconds_needed"]
    out["ratio_pyelastica_over_ours"] = round(sec_p / sec_o, 3) if sec_o and sec_p else None
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="n = 6, 12 and one timed run each")
    ap.add_argument("--full", action="store_true", help="also n = 80")
    ap.add_argument("--no-elastica", action="store_true", help="skip the pyelastica comparison")
    args = ap.parse_args(argv)
    ns = [6, 12] if args.quick else [10, 20, 40] + ([80] if args.full else [])
    runs = 1 if args.quick else 3
    ref = _reference_tip()
    print(f"reference tip ({ref[0]:.6f}, {ref[1]:.6f}) m; omega_1 {OMEGA1:.4f} rad/s; T = {T_END:.2f} s; "
          f"nu = {NU:.4f} 1/s; c_v = {C_V:.4g} N*s/m**2; tau = {TAU:g} s", flush=True)
    ours = {}
    for n in ns:
        ours[n] = _ours(n, ref, runs)
        r = ours[n]
        print(f"ours n={n:<3} assembly {r['assembly_seconds']:7.2f} s  codegen {r['codegen_seconds']:6.2f} s  "
              f"first run {r['first_run_seconds']:7.3f} s  run {r['run_seconds']:7.3f} s  tip error {r['tip_error']:.2e} L",
              flush=True)
    out = {"quick": args.quick, "n": ns, "reference_tip": ref, "T": T_END, "ours": {str(n): ours[n] for n in ns},
           "assembly_exponent": round(_slope(ns, [ours[n]["assembly_seconds"] for n in ns]), 2),
           "codegen_exponent": round(_slope(ns, [ours[n]["codegen_seconds"] for n in ns]), 2)}
    print(f"growth exponents: assembly n^{out['assembly_exponent']}, codegen n^{out['codegen_exponent']}")
    try:
        import elastica as ea
    except ImportError:
        ea = None
    if ea is None or args.no_elastica:
        print("pyelastica comparison not run (" + ("skipped" if args.no_elastica else "pyelastica not importable") + ")")
        out["pyelastica"] = None
    else:
        s0 = time.perf_counter()
        _elastica_run(ea, 4, 0.01)  # numba compilation, not timed below
        out["pyelastica_warmup_seconds"] = round(time.perf_counter() - s0, 2)
        theirs = {}
        for n in ns:
            theirs[n] = _elastica(ea, n, ref, runs)
            r = theirs[n]
            print(f"pyelastica n={n:<3} run {r['run_seconds']:7.3f} s ({r['steps']} steps)  tip error {r['tip_error']:.2e} L"
                  f"  ratio at equal n {r['run_seconds'] / ours[n]['run_seconds']:.2f}", flush=True)
        out["pyelastica"] = {str(n): theirs[n] for n in ns}
        out["ratio_at_equal_n"] = {str(n): round(theirs[n]["run_seconds"] / ours[n]["run_seconds"], 3) for n in ns}
        out["equal_accuracy"] = {}
        for label, target in (("ours_best", ours[ns[-1]]["tip_error"]), ("pyelastica_best", theirs[ns[-1]]["tip_error"])):
            eq = out["equal_accuracy"][label] = _at_equal_accuracy(ns, ours, theirs, target)
            print(f"equal tip accuracy {target:.2e} L ({label.replace('_', ' ')}): "
                  + ", ".join(f"{who} n={eq[who]['n_needed']} {eq[who]['seconds_needed'] or float('nan'):.3g} s "
                              f"({'interpolated' if eq[who]['interpolated'] else 'extrapolated'})"
                              for who in ("ours", "pyelastica"))
                  + f"; ratio pyelastica/ours {eq['ratio_pyelastica_over_ours']}")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
