"""Benchmark: an element between a controller and the plant, fed the raw or the smoothed recorded command.

The concealed 4 ms loop delay (``examples.concealed_loops``, case ``loop_delay``: PD loop, command with
2 % noise, 1 kHz): the servo with the element's deviation input (``with_deviation``) simulated through
the deviation of the delayed command, computed from the raw recorded command and from the command
smoothed above ``COMMAND_BAND`` of the Nyquist frequency (``smoothed_command``, the default).  Both in
the same process: seconds per simulation (median of five) and the difference of the outputs relative to
each channel's standard deviation (the recording's noise is 1 % of the position's range, 2 % of the
command's standard deviation).

    python bench/loop_command.py [--seconds 4]

The last line printed is one JSON object: ``seconds_raw``, ``seconds_smoothed``, ``speedup``,
``difference`` (per channel).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="recording length [s]")
    args = ap.parse_args(argv)

    import components.candidates.elements as elements
    from codegen.simulator import Simulator
    from components.candidates import InLoop, TimeDelay
    from examples.concealed_loops import LOOP_DELAY, generate, nominal
    from phs.workflows.diagnose.hypotheses import _simulate, _transformed

    rec, _ = generate("loop_delay", seconds=args.seconds, seed=1)
    system = elements.with_deviation(nominal(), "u_c", "time_delay")
    sim = Simulator(system, rtol=1e-6, energy=False)
    el, x0 = InLoop(TimeDelay(), "u_c"), [0.0] * len(system.states)
    smooth = elements.smoothed_command
    out, secs = {}, {}
    for rule, fn in (("raw", lambda u: np.asarray(u, float)), ("smoothed", smooth)):
        elements.smoothed_command = fn
        try:
            r = _transformed(rec, el, "u_c", [LOOP_DELAY])
        finally:
            elements.smoothed_command = smooth
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            out[rule] = _simulate(system, r, x0, sim=sim)
            times.append(time.perf_counter() - t0)
        secs[rule] = float(np.median(times))
        print(f"{rule:<9} {secs[rule]:.3f} s per simulation", flush=True)
    diff = {ch: float(np.std(np.asarray(out["raw"][ch]) - np.asarray(out["smoothed"][ch])) / np.std(rec[ch]))
            for ch in ("position", "u_c")}
    print("difference / std: " + ", ".join(f"{ch} {v:.2e}" for ch, v in diff.items()))
    print(json.dumps({"seconds_raw": round(secs["raw"], 4), "seconds_smoothed": round(secs["smoothed"], 4),
                      "speedup": round(secs["raw"] / secs["smoothed"], 2), "difference": {k: round(v, 6) for k, v in diff.items()}}))


if __name__ == "__main__":
    main()
