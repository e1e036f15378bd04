"""Benchmark: one diagnosis of a 20 s, 1 kHz recording with the full candidate library.

The nominal model is the 1-DOF electrostatic actuator (position and current measured); each case's
recording comes from a truth that contains one effect the nominal model lacks, in a functional form
different from the library's candidate (``examples/concealed_effects.py``), with a validation
recording of its own.  The closed-loop cases (``examples/concealed_loops.py``: a plant under a known
PD loop, the reference recorded as the input; dry friction read by a quantised encoder beside a
noisy force channel, absorbed by the nominal damping, or with a hardening spring; a delay or a clip
of the force between the controller and the plant) are named ``loop:CASE``; ``loop:loop_delay`` and
``loop:drive_saturation`` are not among the default cases (run them with ``--effects``) and are right
only with the element at the controller's command.  For every case the script runs ``phs.diagnose``
with every candidate, times it, and checks the verdict against the truth.  Target: 40 s per case on an
idle 2-core machine, 60 s under load (other jobs running: a 1-min load average above the CPUs before the
cases).

    python bench/diagnose.py                       # default cases, 20 s recordings
    python bench/diagnose.py --effects all         # every effect of both generators (long)
    python bench/diagnose.py --effects loop:absorbed,time_delay --seconds 8
    python bench/diagnose.py --quick               # 4 s recordings, two cases (smoke test)
    python bench/diagnose.py --lab --no-baseline   # lab-protocol recordings, 17 s, five free parameters
    python bench/diagnose.py --lab --quick --no-baseline   # two 3 s lab cases (smoke test)

    python bench/diagnose.py --pairs 20 --no-baseline   # 20 random pairs of effects in one truth
    python bench/diagnose.py --pairs 2 --seconds 4 --no-baseline   # smoke test of the pairs
    python bench/diagnose.py --lab --pairs 4 --no-baseline   # 4 random pairs under the lab protocols
    python bench/diagnose.py --lab --effects esa:time_delay+cubic_stiffness@1kHz --no-baseline   # one lab pair

The baseline, measured in the same run (``--no-baseline`` skips it), is the same diagnosis without
screening: every hypothesis fitted jointly to convergence (``refit_top=0``).

``--pairs N [--pair-seed S]`` runs N distinct pairs drawn from ``examples.concealed_effects.PAIRS``
(:func:`examples.concealed_effects.random_pairs`, seed 0 by default) instead of the single-effect cases:
each truth holds two effects ``A+B`` at their single-effect strengths.  A verdict is "both named" when
its effects are exactly the two, "one named" when exactly one of the two is among them; every case
reports ``truth_effects``, ``named`` (how many of the two the verdict names), ``both_named`` and
``one_named``, and the JSON line gains ``both_named_rate``, ``one_named_rate``, ``pairs`` and
``pair_seed`` (``verdict_correct`` is then the both-named rate).  With ``--lab`` the pairs are lab cases
of the electrostatic actuator (:func:`lab_pairs`: the same pairs, each at a rate drawn from 500 Hz, 1 kHz
and 2 kHz, five free nominal parameters); ``--effects`` with ``--lab`` takes any case
:func:`examples.lab_protocols.parse_case` reads.

The last line printed is one JSON object: ``seconds_per_case`` (mean), ``max_seconds``,
``verdict_correct`` (share of cases whose verdict names the truth's effect), ``cases`` (per case:
seconds, verdict, expected, fit before/after on validation, ``load_before`` the 1-min load average as it
started, the baseline's), ``load_before_max`` and ``cpus`` (to read the run against ``target_seconds``
idle or ``target_seconds_loaded``), ``speedup_vs_baseline``, ``baseline_verdict_correct`` and
``same_verdicts_as_baseline``.

Every case also reports ``cpu_seconds`` (this process and its forked workers: ``getrusage`` SELF +
CHILDREN) and ``phases``, where the wall and CPU seconds went: ``nominal fit``, ``location``,
``screening``, ``refits`` (joint refits, deferred and located-family refits, polish; every fit when
``refit_top=0``), ``discovery`` and ``other`` (the rest of the diagnosis).  The phases are timed from
outside: the bench wraps functions of :mod:`phs.workflows.diagnose` with timers (:func:`install_clock`).
``integrations`` counts what the time is spent integrating (:func:`install_counter`, summed over the forked
workers): ``simulations`` (the simulator's runs: scores, element searches, locations), ``fit integrations``
(a fit's residual, one CVODES call per segment) and ``sensitivity integrations`` (a fit's Jacobian: the same
with a forward-sensitivity direction per free parameter), each with its ``calls``, ``samples``,
``sample_directions`` (samples times directions) and ``seconds`` (CPU seconds inside the calls, summed over processes).

``--lab`` runs the lab-protocol recordings of :mod:`examples.lab_protocols` instead (17 s by default:
rests, smooth-edged and held squares, staircases, chirp bursts, PRBS, at 500 Hz to 2 kHz; the
electrostatic actuator and the MSD HASEL, five free nominal parameters each, truths integrated by
scipy outside the framework's simulator); ``--lab --quick`` runs two 3 s lab cases.  The JSON then has
``lab: true`` and the same keys.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from examples import concealed_loops, lab_protocols  # noqa: E402
from examples.concealed_effects import EFFECTS, NOMINAL_FREE, generate, random_pairs  # noqa: E402
from phs.errors import InputDataError  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

DEFAULT = ["charge_retention", "cubic_stiffness", "coulomb_friction", "time_delay", "none", "loop:absorbed",
           "loop:quantised_encoder"]
LOOPS = [f"loop:{c}" for c in concealed_loops.CASES]
LAB_QUICK = ["esa:cubic_stiffness@500Hz", "msd:none@500Hz"]
PHASES = ("nominal fit", "location", "screening", "refits", "discovery", "other")


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of its waited-for children (the forked workers)."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


class PhaseClock:
    """Wall and CPU seconds spent in the outermost call of each wrapped function, by phase."""

    def __init__(self):
        self.depth, self.wall, self.cpu, self.wrapped = 0, {}, {}, []

    def reset(self):
        self.wall, self.cpu = {}, {}

    def wrap(self, module, attr, phase_of):
        fn = getattr(module, attr, None)
        if fn is None or getattr(fn, "_bench_clock", False):
            return
        clock = self

        def timed(*a, **k):
            if clock.depth:  # inside another timed phase (or in a forked worker): counted there
                return fn(*a, **k)
            phase = phase_of(a, k)
            clock.depth += 1
            w0, c0 = time.perf_counter(), cpu_seconds()
            try:
                return fn(*a, **k)
            finally:
                clock.depth -= 1
                clock.wall[phase] = clock.wall.get(phase, 0.0) + time.perf_counter() - w0
                clock.cpu[phase] = clock.cpu.get(phase, 0.0) + cpu_seconds() - c0

        timed._bench_clock = True
        setattr(module, attr, timed)
        self.wrapped.append(f"{module.__name__}.{attr}")

    def split(self, wall: float, cpu: float) -> dict:
        """Per phase ``{"wall": s, "cpu": s}``; ``other`` is what the wrapped phases leave of ``wall``, ``cpu``."""
        out = {p: {"wall": round(self.wall.get(p, 0.0), 2), "cpu": round(self.cpu.get(p, 0.0), 2)} for p in PHASES[:-1]}
        out["other"] = {"wall": round(max(0.0, wall - sum(self.wall.values())), 2),
                        "cpu": round(max(0.0, cpu - sum(self.cpu.values())), 2)}
        return out


def install_clock() -> PhaseClock:
    """Wrap the diagnosis' phases with timers (before any fork, so the workers inherit the wrappers): the
    nominal fit, the location of the mismatch, each batch of hypothesis fits (screening or refit by its
    label) and the discovery of a correction outside the library.  A function that is not there is not
    timed (its seconds fall to ``other``)."""
    import phs.workflows.diagnose.discover as disc
    import phs.workflows.diagnose.nominal as nom
    import phs.workflows.diagnose.run as run
    import phs.workflows.diagnose.screening as scr

    clock = PhaseClock()
    clock.wrap(nom, "fit_nominal", lambda a, k: "nominal fit")
    clock.wrap(run, "_locate", lambda a, k: "location")

    def batch(a, k):
        label = k.get("label", a[5] if len(a) > 5 else "")
        return "screening" if "screening" in str(label) else "refits"
    clock.wrap(scr, "_run_all", batch)
    clock.wrap(disc, "discover", lambda a, k: "discovery")
    clock.wrap(disc, "without_library", lambda a, k: "discovery")
    return clock


CLOCK: PhaseClock | None = None


INTEGRATIONS = ("simulations", "fit integrations", "sensitivity integrations")
"""What :class:`IntegrationCounter` counts: the simulator's runs (scores, element searches, locations, the
discovery's screens), the fits' plain integrations (a residual without its Jacobian: one CVODES call per
segment) and their integrations with forward sensitivities (a Jacobian: one CVODES call per segment, with a
direction per free parameter and estimated initial state)."""


class IntegrationCounter:
    """Calls, samples, sample-directions and CPU seconds of the integrations (:data:`INTEGRATIONS`), summed over
    this process and the workers it forks (counters in shared memory made before any fork; a forked worker
    adds to them).  The seconds are each process's CPU time inside the calls (``time.process_time``), summed:
    a share of the case's CPU seconds, whatever else runs on the machine."""

    FIELDS = ("calls", "samples", "directions", "seconds")

    def __init__(self):
        import multiprocessing as mp

        self.values = mp.get_context("fork").Array("d", len(INTEGRATIONS) * len(self.FIELDS))
        self.wrapped = []

    def add(self, kind: str, samples: int, directions: int, seconds: float):
        k = INTEGRATIONS.index(kind) * len(self.FIELDS)
        with self.values.get_lock():
            self.values[k] += 1
            self.values[k + 1] += samples
            self.values[k + 2] += samples * directions
            self.values[k + 3] += seconds

    def reset(self):
        with self.values.get_lock():
            for i in range(len(self.values)):
                self.values[i] = 0.0

    def read(self) -> dict:
        """Per kind ``{"calls", "samples", "sample_directions", "seconds"}`` (seconds rounded to 0.01)."""
        n = len(self.FIELDS)
        with self.values.get_lock():
            v = list(self.values)
        return {kind: {"calls": int(v[i * n]), "samples": int(v[i * n + 1]), "sample_directions": int(v[i * n + 2]),
                       "seconds": round(v[i * n + 3], 2)} for i, kind in enumerate(INTEGRATIONS)}


def install_counter() -> IntegrationCounter:
    """Count the integrations (:class:`IntegrationCounter`): wrap ``codegen.Simulator.run`` (samples: the
    output times) and the fits' CVODES calls in :mod:`phs.workflows.identify.sensitivities` (samples: the
    segment's output times; directions: the sensitivities' seeds).  Before any fork, so that the workers
    inherit the wrappers and the shared counters."""
    import importlib

    import phs.workflows.identify.sensitivities as sens

    simulator = importlib.import_module("codegen.simulator")  # the module (``codegen.simulator`` is also a function)
    counter = IntegrationCounter()
    run = simulator.Simulator.run
    if not getattr(run, "_bench_count", False):
        def counted_run(self, t, *a, **k):
            t0 = time.process_time()
            try:
                return run(self, t, *a, **k)
            finally:
                counter.add("simulations", len(np.atleast_1d(t)), 0, time.process_time() - t0)
        counted_run._bench_count = True
        simulator.Simulator.run = counted_run
        counter.wrapped.append("codegen.simulator.Simulator.run")
    plain, with_sens = sens._integrate, sens._integrate_sensitivities
    if not getattr(plain, "_bench_count", False):
        def counted_plain(F, z0, P, nx, n):
            t0 = time.process_time()
            try:
                return plain(F, z0, P, nx, n)
            finally:
                counter.add("fit integrations", n, 0, time.process_time() - t0)

        def counted_sens(Fs, z0, S0, P, seed_p, n):
            t0 = time.process_time()
            try:
                return with_sens(Fs, z0, S0, P, seed_p, n)
            finally:
                counter.add("sensitivity integrations", n, int(np.shape(seed_p)[0]), time.process_time() - t0)
        counted_plain._bench_count = counted_sens._bench_count = True
        sens._integrate, sens._integrate_sensitivities = counted_plain, counted_sens
        counter.wrapped += ["phs.workflows.identify.sensitivities._integrate",
                            "phs.workflows.identify.sensitivities._integrate_sensitivities"]
    return counter


COUNTER: IntegrationCounter | None = None


def _is_lab(case: str) -> bool:
    """Whether ``case`` is a lab-protocol case (:func:`examples.lab_protocols.parse_case`)."""
    try:
        lab_protocols.parse_case(case)
    except InputDataError:
        return False
    return True


def lab_pairs(n: int, seed: int = 0) -> list[str]:
    """``n`` random pairs of effects (:func:`examples.concealed_effects.random_pairs`) as lab cases of the
    electrostatic actuator, each at a rate drawn from :data:`examples.lab_protocols.RATE_NAMES` (the same for
    the same seed)."""
    rates = list(lab_protocols.RATE_NAMES)
    rng = np.random.default_rng([int(seed), 7])
    return [f"esa:{p}@{rates[i]}" for p, i in zip(random_pairs(n, seed), rng.integers(len(rates), size=n), strict=True)]


def run_case(effect: str, seconds: float, jobs: int | None, refit_top: int = 3) -> dict:
    kw = {}
    if effect.startswith("loop:"):
        case = effect.split(":", 1)[1]
        train, info = concealed_loops.generate(case, seconds=seconds, seed=1)
        val, _ = concealed_loops.generate(case, seconds=seconds, seed=2, validation=True)
        model, free = concealed_loops.nominal(), concealed_loops.NOMINAL_FREE

        def right(d):  # every concealed effect named, nothing else (and at its place, when the case says)
            where = info.get("place")
            return (sorted(d.verdict["effects"]) == sorted(info["effects"])
                    and (where is None or all(a.augmentation.attached_to == where for a in d.accepted)))
    elif _is_lab(effect):
        train, info = lab_protocols.generate(effect, seconds=seconds, seed=1)
        val, _ = lab_protocols.generate(effect, seconds=seconds, seed=2, validation=True)
        act = lab_protocols.ACTUATORS[info["actuator"]]
        model, free = act.nominal(), info["free"]
        kw = {"x0": info["x0"], "outputs": list(act.channels)}
        truth_effect = info["effect"]
        pair = truth_effect.split("+")

        def right(d):  # the verdict names the concealed effect (both of a pair, nothing else)
            return sorted(d.verdict["effects"]) == sorted(pair) if len(pair) == 2 else d.effect == truth_effect
    elif "+" in effect:  # a pair of effects in one truth
        train, info = generate(effect, seconds=seconds, seed=1)
        val, _ = generate(effect, seconds=seconds, seed=2, validation=True)
        model, free = electrostatic_actuator(), NOMINAL_FREE
        pair = info["effects"]

        def right(d):  # both concealed effects named, nothing else
            return sorted(d.verdict["effects"]) == sorted(pair)
    else:
        train, _ = generate(effect, seconds=seconds, seed=1)
        val, _ = generate(effect, seconds=seconds, seed=2, validation=True)
        model, free = electrostatic_actuator(), NOMINAL_FREE

        def right(d):  # the verdict names the concealed effect
            return d.effect == effect
    if CLOCK is not None:
        CLOCK.reset()
    if COUNTER is not None:
        COUNTER.reset()
    c0, t0 = cpu_seconds(), time.perf_counter()
    d = diagnose(model, train, validation=val, free=list(free), n_jobs=jobs, refit_top=refit_top, **kw)
    sec, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    phases = CLOCK.split(sec, cpu) if CLOCK is not None else None
    out = {
        "seconds": round(sec, 2), "cpu_seconds": round(cpu, 2), "phases": phases,
        "integrations": COUNTER.read() if COUNTER is not None else None,
        "diagnosis_seconds": round(d.seconds, 2), "samples": len(train),
        "hypotheses_fitted": sum(len(r) for r in d.rounds),
        "verdict": d.effect, "effects": d.verdict["effects"], "expected": effect,
        "correct": right(d), "confidence": d.verdict["confidence"],
        "validation_fit_before": {k: round(v, 2) for k, v in d.nominal.validation_fit_percent.items()},
        "validation_fit_after": {k: round(v, 2) for k, v in d.final.validation_fit_percent.items()},
    }
    if "+" in effect and not effect.startswith("loop:"):  # a pair (of the concealed effects or a lab case)
        named = sum(e in d.verdict["effects"] for e in pair)
        out.update(truth_effects=list(pair), named=named, both_named=out["correct"], one_named=named == 1)
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="recording length [s] (default 20)")
    ap.add_argument("--effects", default=",".join(DEFAULT), help="comma-separated effects, or 'all'")
    ap.add_argument("--jobs", type=int, default=None, help="processes (default: CPUs, at most 4)")
    ap.add_argument("--quick", action="store_true", help="4 s recordings, two cases (with --lab: 3 s, two lab cases)")
    ap.add_argument("--lab", action="store_true",
                    help="the lab-protocol recordings of examples/lab_protocols.py (17 s by default; --effects picks among them)")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the baseline: every hypothesis fitted to convergence (refit_top=0), no screening")
    ap.add_argument("--pairs", type=int, default=None, metavar="N",
                    help="run N random pairs of effects (each truth holds two) instead of the single-effect cases")
    ap.add_argument("--pair-seed", type=int, default=0, help="seed of the random pairs (default 0)")
    args = ap.parse_args(argv)
    if args.pairs is not None and args.quick:
        ap.error("--pairs runs the pair cases alone: not with --quick")
    global CLOCK, COUNTER
    CLOCK = CLOCK or install_clock()
    COUNTER = COUNTER or install_counter()
    effects = EFFECTS + LOOPS if args.effects == "all" else [e.strip() for e in args.effects.split(",")]
    seconds = args.seconds
    if args.lab:
        lab = list(lab_protocols.LAB_CASES)
        effects = lab if args.effects in ("all", ",".join(DEFAULT)) else effects
        unknown = [e for e in effects if not _is_lab(e)]
        if unknown:
            ap.error(f"--lab: unknown case(s) {unknown}; listed: {', '.join(lab)}, or any actuator:effect@rate "
                     "(examples/lab_protocols.py, parse_case)")
        seconds = 17.0 if args.seconds == 20.0 else args.seconds
        if args.quick:
            effects, seconds = LAB_QUICK, 3.0
    elif args.quick:
        effects, seconds = ["charge_retention", "none"], 4.0
    if args.pairs is not None:
        try:
            effects = (lab_pairs if args.lab else random_pairs)(args.pairs, args.pair_seed)
        except ValueError as err:
            ap.error(str(err))
    cases = {}
    load_start = os.getloadavg() if hasattr(os, "getloadavg") else None
    for e in effects:
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
        r = run_case(e, seconds, args.jobs)
        r["load_before"] = None if load is None else round(load, 2)
        cases[e] = r
        if "truth_effects" in r:
            said = ("both named" if r["both_named"] else "one named" if r["one_named"]
                    else "both named among others" if r["named"] == 2 else "neither named")
            print(f"{e:<40} {r['seconds']:7.1f} s  verdict {'+'.join(r['effects']) or 'nothing missing'}  truth "
                  f"{'+'.join(r['truth_effects'])}: {said}  validation fit {r['validation_fit_before']} -> "
                  f"{r['validation_fit_after']}", flush=True)
        else:
            print(f"{e:<24} {r['seconds']:7.1f} s  verdict {r['verdict']:<20} {'ok' if r['correct'] else 'WRONG'}  "
                  f"validation fit {r['validation_fit_before']} -> {r['validation_fit_after']}", flush=True)
        print(f"{'':<24} cpu {r['cpu_seconds']:.1f} s, load {r['load_before']}; wall/cpu s: "
              + ", ".join(f"{p} {v['wall']:.1f}/{v['cpu']:.1f}" for p, v in r["phases"].items()), flush=True)
        print(f"{'':<24} " + "; ".join(f"{k}: {v['calls']} calls, {v['samples']} samples"
                                       + (f" ({v['sample_directions']} with directions)" if v["sample_directions"] else "")
                                       + f", {v['seconds']:.1f} s" for k, v in r["integrations"].items()), flush=True)
        if not args.no_baseline:  # the same diagnosis with every hypothesis fitted jointly to convergence
            b = run_case(e, seconds, args.jobs, refit_top=0)
            r["baseline"] = {k: b[k] for k in ("seconds", "verdict", "effects", "correct", "validation_fit_after")}
            r["same_verdict_as_baseline"] = b["effects"] == r["effects"]
            print(f"{'  every fit to convergence':<24} {b['seconds']:7.1f} s  verdict {b['verdict']:<20} "
                  f"{'ok' if b['correct'] else 'WRONG'}  screening {b['seconds'] / r['seconds']:.1f}x faster", flush=True)
    secs = [c["seconds"] for c in cases.values()]
    out = {"seconds_per_case": round(sum(secs) / len(secs), 2), "max_seconds": max(secs),
           "verdict_correct": sum(c["correct"] for c in cases.values()) / len(cases), "recording_seconds": seconds,
           "target_seconds": 40, "target_seconds_loaded": 60, "cpus": os.cpu_count(),
           "load_before_max": max((c["load_before"] for c in cases.values() if c["load_before"] is not None), default=None),
           "cases": cases, "lab": bool(args.lab),
           "cpu_seconds_per_case": round(sum(c["cpu_seconds"] for c in cases.values()) / len(cases), 2),
           "load_average_start": None if load_start is None else [round(v, 2) for v in load_start],
           "load_average_end": [round(v, 2) for v in os.getloadavg()] if hasattr(os, "getloadavg") else None,
           "timed_functions": CLOCK.wrapped, "counted_functions": COUNTER.wrapped}
    if args.pairs is not None:
        out.update(both_named_rate=sum(c["both_named"] for c in cases.values()) / len(cases),
                   one_named_rate=sum(c["one_named"] for c in cases.values()) / len(cases),
                   pairs=list(cases), pair_seed=args.pair_seed)
    if not args.no_baseline:
        base = [c["baseline"]["seconds"] for c in cases.values()]
        out["baseline_seconds_per_case"] = round(sum(base) / len(base), 2)
        out["speedup_vs_baseline"] = round(sum(base) / sum(secs), 2)
        out["baseline_verdict_correct"] = sum(c["baseline"]["correct"] for c in cases.values()) / len(cases)
        out["same_verdicts_as_baseline"] = sum(c["same_verdict_as_baseline"] for c in cases.values()) / len(cases)
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
