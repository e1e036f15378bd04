"""Benchmark: a simulation whose integrator calls are planned once per recording against one that plans them
every time, and measured outputs through a mapped function built once against one built every time.

The recording is a concealed-effect training recording of the electrostatic actuator (``examples.
concealed_effects``, 20 s at 1 kHz; the ``time_delay`` case's drive steps 726 times, the ``cubic_stiffness``
case's 92); the model is the nominal actuator, simulated at rtol 1e-6 as a diagnosis's screening fits do.
Baseline, in the same run: the plan cache emptied before every simulation (``codegen._plan._PLANS``: what
every simulation did before the plan was kept) and the measured outputs mapped by ``Function.map(n,
"thread", 2)`` built for each result.  Both paths give the same numbers (checked: the largest difference
of the states is printed).

    python bench/simulation_plan.py [--effect time_delay] [--repeat 5]

The last line printed is one JSON object: ``seconds_planned``, ``seconds_replanned`` (median per
simulation), ``speedup_simulation``, ``seconds_outputs_mapped_once``, ``seconds_outputs_mapped_each``,
``speedup_outputs``, ``runs`` (integrator calls per simulation), ``max_state_difference``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def _median_seconds(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effect", default="time_delay", help="concealed-effect case whose training recording is simulated")
    ap.add_argument("--repeat", type=int, default=5, help="simulations timed per path (median)")
    args = ap.parse_args(argv)

    import codegen._plan as plan
    from codegen import Simulator
    from codegen.functions import generate as functions
    from examples.concealed_effects import generate
    from phs.signals import Sampled
    from systems.electrostatic_actuator import electrostatic_actuator

    rec, _ = generate(args.effect, seconds=20, seed=1)
    system = electrostatic_actuator()
    sim = Simulator(system, rtol=1e-6, energy=False)
    x0 = [0.0] * len(system.states)

    def run(replan: bool):
        if replan:
            plan._PLANS.clear()
        u = {n: Sampled(tuple(rec.t), tuple(rec[n])) for n in system.input_names}
        return sim.run(rec.t, u=u, x0=x0)

    run(False)  # integrators built, plan kept
    planned, a = _median_seconds(lambda: run(False), args.repeat)
    replanned, b = _median_seconds(lambda: run(True), args.repeat)
    diff = float(np.max(np.abs(a.x - b.x)))
    print(f"simulation   planned once {planned:.3f} s, planned each time {replanned:.3f} s "
          f"({replanned / planned:.2f}x; {a.stats['runs']} integrator calls; states differ by {diff:.1e})", flush=True)

    f, n = functions(system).measured, len(a.t)

    def each():
        fm = f.map(n, "thread", 2)
        return np.asarray(fm(a.x.T, a.u.T, np.repeat(a.p[:, None], n, axis=1))).T

    def once():
        a.__dict__.pop("measured", None)  # the cached property, computed again through the kept map
        return a.measured

    once()
    mapped_once, y1 = _median_seconds(once, args.repeat)
    mapped_each, y2 = _median_seconds(each, args.repeat)
    diff = max(diff, float(np.max(np.abs(y1 - y2.reshape(y1.shape)))))
    print(f"measured outputs   map kept {mapped_once * 1e3:.1f} ms, map built each time {mapped_each * 1e3:.1f} ms "
          f"({mapped_each / mapped_once:.1f}x)", flush=True)
    print(json.dumps({"effect": args.effect, "seconds_planned": round(planned, 4), "seconds_replanned": round(replanned, 4),
                      "speedup_simulation": round(replanned / planned, 2), "seconds_outputs_mapped_once": round(mapped_once, 5),
                      "seconds_outputs_mapped_each": round(mapped_each, 5), "speedup_outputs": round(mapped_each / mapped_once, 1),
                      "runs": int(a.stats["runs"]), "max_state_difference": diff}))


if __name__ == "__main__":
    main()
