"""Benchmark: recorded (sampled) smooth inputs, spline windows against the linear interpolant.

The electrostatic actuator driven by ``15 + 10 sin(2π 1.5 t) + 3 sin(2π 4.1 t)`` V sampled at 1 kHz,
given to the simulator as an array (as a recording is).  Two rules run in the same process on the
same machine:

* ``windows``: the default (``codegen.simulator.step_windows``): a cubic spline through the samples
  where the input is smooth, longer steps allowed;
* ``linear``: the previous rule, the linear interpolant everywhere with steps of at most one sample
  (``_STEP_FACTORS`` emptied), whose kink at every sample holds CVODES to about a step per sample.

Both are compared with a run given the exact sine as an expression (rtol 1e-11): the error of each
is printed relative to the peak.  Then an identification of ``k`` and ``b`` (from +20 % and +50 %)
on a 1.5 s recording of the same drive runs under both rules.

Then a piecewise-linear recorded drive (the concealed cases' steps, ``examples.concealed_effects``):

* ``kinks``: the default (``Sampled.kinks``): a straight line between consecutive kinks, restarts at each;
* ``windows``: the same samples through the step windows (``Sampled.kinks`` disabled), whose steps may
  cross a kink;

each at rtol 1e-7 against the default at rtol 1e-11 (the error of the current, which jumps at every
step, relative to its spread), and ten runs of the drive delayed by 0.1 ms more each (as a search over
an input element's parameter does: a new input every run).

Then a mixed recorded drive (the concealed cases' validation drive: holds, a sine and a chirp, with
jumps between them), at the diagnosis's scoring tolerance (rtol 1e-8) and at 1e-7:

* ``pieces``: the default: lines over the holds (``Sampled.lines``), the step windows elsewhere, one
  interval only next to a jump or a kink (``FINE_WINDOW``);
* ``windows``: the previous rule: no lines, a rough window and both its neighbours at one interval
  (``FINE_WINDOW`` = ``STEP_WINDOW``);

each against itself at rtol 1e-11 (the current's error relative to its spread: the integration's error,
not the difference between the two interpolants of the samples).

Then a lab-protocol drive (``examples.lab_protocols``, ``esa:none@1kHz``: rests, raised-cosine edges,
held squares, a staircase, a chirp burst, a PRBS), against the truth's own outputs (scipy's integration of
the continuous command, before noise), at rtol 1e-8 and 1e-7:

* ``local``: the default: a smooth stretch kept to one interval (an edge between two holds, the ends of a
  chirp burst) through the spline of its own samples (``codegen._grid.bounded_runs``, ``local``);
* ``lines``: the previous rule, the straight lines between its samples there;

the current's error in units of the recording's noise (its RMS and largest value over the recording).

Then a command delayed by a fraction of a sample (the ``time_delay`` element's course, an RC circuit with
R C = 10 us at 1 kHz driven through raised-cosine edges; delays of 1e-7, 0.3 and 2.6 samples), the source's
current (``U.i``, which feeds the command through) against ``C du/dt`` at ``t - tau``:

* ``course``: the default (``TimeDelay.course``): the moved samples stay evenly spaced, the held first value
  a row of samples back to the start, so the delayed command goes through the local splines as the command
  itself does;
* ``held``: the previous course, the first value held once at the recording's start: its first interval is
  shorter than the others (read with today's simulator: a delay shorter than a sample then goes through
  straight lines, a longer one through the splines of the evenly spaced samples around each edge);

the largest error of the current over its peak.

    python bench/sampled_inputs.py            # 10 s simulations, median of 3 runs
    python bench/sampled_inputs.py --quick    # 2 s, one run

The last line is one JSON object with the seconds, the ratios (``linear / windows``) and the errors.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from codegen import Simulator, simulate  # noqa: E402
from phs.signals import Sampled  # noqa: E402
from phs.workflows.identify import identify  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

simmod = importlib.import_module("codegen._grid")  # the module of step_windows and its step factors
SIGNAL = "15 + 10*sin(2*pi*1.5*t) + 3*sin(2*pi*4.1*t)"
FACTORS = simmod._STEP_FACTORS


def signal(t):
    return 15 + 10 * np.sin(2 * np.pi * 1.5 * t) + 3 * np.sin(2 * np.pi * 4.1 * t)


def timed(fn, repeats):
    out, secs = None, []
    for _ in range(repeats):
        w = time.perf_counter()
        out = fn()
        secs.append(time.perf_counter() - w)
    return out, statistics.median(secs)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 s simulations, one run each")
    args = ap.parse_args(argv)
    seconds, repeats = (2.0, 1) if args.quick else (10.0, 3)
    s = electrostatic_actuator()
    t = np.arange(0.0, seconds, 1e-3)
    exact = simulate(s, t, u={"U": SIGNAL}, rtol=1e-11)["position"]
    peak = float(np.max(np.abs(exact)))
    res = {}
    for rule, factors in (("windows", FACTORS), ("linear", ())):
        simmod._STEP_FACTORS = factors
        simulate(s, t[:100], u={"U": signal(t[:100])}, rtol=1e-7)  # warm-up (integrator construction)
        y, sec = timed(lambda: simulate(s, t, u={"U": signal(t)}, rtol=1e-7)["position"], repeats)
        res[rule] = {"simulate_seconds": round(sec, 4), "error_of_peak": float(np.max(np.abs(y - exact)) / peak)}
        print(f"simulate {rule:<8} {sec:8.3f} s  error {res[rule]['error_of_peak']:.2e} of the peak", flush=True)
    simmod._STEP_FACTORS = FACTORS
    tf = np.arange(0.0, 1.5, 1e-3)
    r = simulate(s, tf, u={"U": SIGNAL}, rtol=1e-10)
    rec = Recording.from_arrays(tf, {"U": signal(tf), "position": r["position"], "current": r["current"]})
    for rule, factors in (("windows", FACTORS), ("linear", ())):
        simmod._STEP_FACTORS = factors
        fit, sec = timed(lambda: identify(electrostatic_actuator(k=60.0, b=0.03), rec, ["k", "b"], rtol=1e-7), 1)
        res[rule]["identify_seconds"] = round(sec, 3)
        res[rule]["identify_k"] = fit.values["k"]
        print(f"identify {rule:<8} {sec:8.3f} s  k = {fit.values['k']:.6g} (truth 50)", flush=True)
    simmod._STEP_FACTORS = FACTORS
    res.update(_steps(seconds, repeats))
    res.update(_mixed(2 * seconds, repeats))
    res.update(_lab(1.7 * seconds, repeats))
    res.update(_delayed(repeats))
    out = {"seconds_simulated": seconds, **res,
           "ratio_simulate_linear_vs_windows": round(res["linear"]["simulate_seconds"] / res["windows"]["simulate_seconds"], 2),
           "ratio_identify_linear_vs_windows": round(res["linear"]["identify_seconds"] / res["windows"]["identify_seconds"], 2),
           "ratio_steps_windows_vs_kinks": round(res["steps_windows"]["simulate_seconds"] / res["steps_kinks"]["simulate_seconds"], 2),
           "ratio_delayed_windows_vs_kinks": round(res["steps_windows"]["ten_delayed_seconds"]
                                                   / res["steps_kinks"]["ten_delayed_seconds"], 2),
           **{f"ratio_mixed_windows_vs_pieces_rtol{r:.0e}": round(res["mixed_windows"][f"seconds_rtol{r:.0e}"]
                                                               / res["mixed_pieces"][f"seconds_rtol{r:.0e}"], 2) for r in MIXED_RTOLS},
           **{f"ratio_lab_lines_vs_local_rtol{r:.0e}": round(res["lab_lines"][f"seconds_rtol{r:.0e}"]
                                                            / res["lab_local"][f"seconds_rtol{r:.0e}"], 2) for r in MIXED_RTOLS},
           **{f"ratio_delayed_error_held_vs_course_{d:g}": round(res["delayed_held"][f"current_max_error_of_peak_{d:g}"]
                                                                 / res["delayed_course"][f"current_max_error_of_peak_{d:g}"], 1)
              for d in DELAYS}}
    print(json.dumps(out))
    return out


def _steps(seconds, repeats) -> dict:
    """The piecewise-linear drive under both rules (see the module docstring)."""
    from examples.concealed_effects import generate

    s = electrostatic_actuator()
    rec, _ = generate("none", seconds=seconds, seed=1)
    t, U = rec.t, np.asarray(rec["U"])

    def run(rtol, u=U, sim=None):
        return (sim or Simulator(s, rtol=rtol, energy=False)).run(t, u={"U": Sampled(tuple(t), tuple(u))})["current"]

    ref = run(1e-11)
    spread = float(np.std(ref))
    kinks, lines, out = Sampled.kinks, Sampled.lines, {}
    for rule in ("kinks", "windows"):
        if rule == "windows":
            Sampled.kinks = lambda self: None
            Sampled.lines = lambda self: np.zeros((0, 2))
        try:
            sim = Simulator(s, rtol=1e-7, energy=False)
            run(1e-7, sim=sim)  # warm-up (integrator construction)
            y, sec = timed(lambda sim=sim: run(1e-7, sim=sim), repeats)
            delayed = [np.interp(t - 1e-4 * (k + 1), t, U) for k in range(10)]
            _, ten = timed(lambda sim=sim, delayed=delayed: [run(1e-7, u=u, sim=sim) for u in delayed], 1)
        finally:
            Sampled.kinks, Sampled.lines = kinks, lines
        out[f"steps_{rule}"] = {"simulate_seconds": round(sec, 4), "ten_delayed_seconds": round(ten, 3),
                                "current_error_of_spread": float(np.max(np.abs(y - ref)) / spread)}
        err = out[f"steps_{rule}"]["current_error_of_spread"]
        print(f"steps    {rule:<8} {sec:8.3f} s  ten delayed {ten:6.2f} s  current error {err:.2e} of its spread", flush=True)
    return out


MIXED_RTOLS = (1e-8, 1e-7)


def _mixed(seconds, repeats) -> dict:
    """The mixed drive under both rules (see the module docstring)."""
    from examples.concealed_effects import generate

    s = electrostatic_actuator()
    rec, _ = generate("none", seconds=seconds, seed=2, validation=True)
    t, U = rec.t, np.asarray(rec["U"])

    def run(sim):
        return sim.run(t, u={"U": Sampled(tuple(t), tuple(U))})["current"]

    lines, fine, out = Sampled.lines, simmod.FINE_WINDOW, {}
    for rule in ("pieces", "windows"):
        if rule == "windows":
            Sampled.lines = lambda self: np.zeros((0, 2))
            simmod.FINE_WINDOW = simmod.STEP_WINDOW
        try:
            out[f"mixed_{rule}"] = entry = {}
            ref = run(Simulator(s, rtol=1e-11, energy=False))  # the rule's own interpolant: its integration error only
            spread = float(np.std(ref))
            for rtol in MIXED_RTOLS:
                sim = Simulator(s, rtol=rtol, energy=False)
                run(sim)  # warm-up (integrator construction)
                y, sec = timed(lambda sim=sim: run(sim), repeats)
                entry[f"seconds_rtol{rtol:.0e}"] = round(sec, 4)
                entry[f"current_error_of_spread_rtol{rtol:.0e}"] = err = float(np.max(np.abs(y - ref)) / spread)
                print(f"mixed    {rule:<8} {sec:8.3f} s at rtol {rtol:.0e}  current error {err:.2e} of its spread", flush=True)
        finally:
            Sampled.lines, simmod.FINE_WINDOW = lines, fine
    return out


def _lab(seconds, repeats) -> dict:
    """The lab-protocol drive under both rules (see the module docstring)."""
    from examples import lab_protocols

    rec, info = lab_protocols.generate("esa:none@1kHz", seconds=seconds, seed=1)
    s = lab_protocols.truth_of("esa", "none").system
    t, U = rec.t, np.asarray(rec["U"])
    clean, noise = info["clean"]["current"], info["noise_std"]["current"]

    def run(sim):
        return sim.run(t, u={"U": Sampled(tuple(t), tuple(U))}, x0=info["x0"])["current"]

    plans = importlib.import_module("codegen._plan")._PLANS  # the plans of a grid and its inputs, kept per process
    pieces, out = simmod._local_pieces, {}
    for rule in ("local", "lines"):
        plans.clear()
        if rule == "lines":
            simmod._local_pieces = lambda samp, start, step, n, splits=0: [(0, n, False)]
        try:
            out[f"lab_{rule}"] = entry = {}
            for rtol in MIXED_RTOLS:
                sim = Simulator(s, rtol=rtol, energy=False)
                run(sim)  # warm-up (integrator construction)
                y, sec = timed(lambda sim=sim: run(sim), repeats)
                e = (y - clean) / noise
                entry[f"seconds_rtol{rtol:.0e}"] = round(sec, 4)
                entry[f"current_rms_error_of_noise_rtol{rtol:.0e}"] = rms = float(np.sqrt(np.mean(e**2)))
                entry[f"current_max_error_of_noise_rtol{rtol:.0e}"] = mx = float(np.max(np.abs(e)))
                print(f"lab      {rule:<8} {sec:8.3f} s at rtol {rtol:.0e}  current error RMS {rms:.3g}, largest {mx:.3g} of its noise",
                      flush=True)
        finally:
            simmod._local_pieces = pieces
            plans.clear()
    return out


DELAYS = (1e-7, 0.3, 2.6)
"""Delays of :func:`_delayed`, in samples: one that tends to zero, one inside a sample, one beyond two."""


def _edges(t, level=16.0, width=0.04, starts=(0.1, 0.3, 0.45)):
    """Raised-cosine edges of ``width`` s between ``-level`` and ``level`` at ``starts``, held between them;
    the command and its time derivative."""
    u, du, sign = np.full_like(t, -level), np.zeros_like(t), 1.0
    for a in starts:
        s = np.clip((t - a) / width, 0.0, 1.0)
        lo, hi = (-level, level) if sign > 0 else (level, -level)
        u = np.where(t >= a, lo + (hi - lo) * 0.5 * (1 - np.cos(np.pi * s)), u)
        du = np.where((t > a) & (t < a + width), (hi - lo) * 0.5 * np.pi / width * np.sin(np.pi * s), du)
        sign = -sign
    return u, du


def _delayed(repeats) -> dict:
    """The delayed command under both courses (see the module docstring)."""
    from components.candidates import TimeDelay
    from systems.examples import rc_circuit

    R, C, dt = 100.0, 1e-7, 1e-3
    t = np.arange(0.0, 0.6, dt)
    u, _ = _edges(t)
    sim = Simulator(rc_circuit(), rtol=1e-9)
    out = {"delayed_course": {}, "delayed_held": {}}
    for d in DELAYS:
        tau = d * dt
        _, du = _edges(t - tau)
        exact = C * du
        peak = float(np.max(np.abs(exact)))
        times, values = TimeDelay().course(t, u, [tau])
        first = int(np.searchsorted(times, t[0] + tau))  # the previous course: the first value held once at the start
        courses = {"course": (times, values), "held": (np.r_[t[0], times[first:]], np.r_[values[0], values[first:]])}
        for rule, (tt, vv) in courses.items():
            def run(tt=tt, vv=vv):
                res = sim.run(t, u={"U": Sampled(tuple(tt), tuple(vv), hold="linear")}, x0={"C.Q": -16.0 * C},
                              params={"R.R": R, "C.C": C})
                return np.asarray(res["U.i"], dtype=float)
            run()  # warm-up (integrator construction)
            y, sec = timed(run, repeats)
            err = float(np.max(np.abs(y - exact)) / peak)
            out[f"delayed_{rule}"][f"current_max_error_of_peak_{d:g}"] = err
            out[f"delayed_{rule}"][f"seconds_{d:g}"] = round(sec, 4)
            print(f"delayed  {rule:<8} {sec:8.3f} s at {d:g} samples  current error {err:.2e} of its peak", flush=True)
    return out


if __name__ == "__main__":
    main()
