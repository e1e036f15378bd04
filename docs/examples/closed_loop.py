# %% [markdown]
# Diagnosis inside a feedback loop.  A mass-spring-damper actuator is recorded under PD position
# control: the reference ``r``, the position and the controller's output force ``u_c`` are recorded
# (1 kHz, with noise); the plant's drive is what the controller computes.  The plant really has
# Coulomb-like (dry) friction, which the nominal model leaves out.  The model is plant + known
# controller, built from components (``PositionLoop`` with the controller's gains), and the
# diagnosis gets the reference as the input and position + controller force as its two channels.
# Run: python docs/examples/closed_loop.py [--quick] [--out DIR]
# Writes docs/figures/closed_loop_{fits,locate,hypotheses}.png.

# %%
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, ROOT)

from codegen import simulator  # noqa: E402
from examples.concealed_loops import B, plant  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402

ap = argparse.ArgumentParser(description="Diagnosis of an actuator recorded under PD position control")
ap.add_argument("--quick", action="store_true", help="4 s to train and 4 s to validate (8 s each otherwise)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

# plant: mass 0.5 kg, spring 40 N/m, damping B = 1 N s/m; controller K_p 400 N/m, K_d 6 N s/m, reference
# filter 10 ms, known from its firmware (``examples.concealed_loops``)
F_C, V_S = 0.4, 2e-3              # concealed dry friction [N] and its smoothing speed [m/s]
DT = 1e-3
SPAN = 4.0 if args.quick else 8.0


def model(friction: bool):
    """Plant + PD loop (``examples.concealed_loops.plant``); the truth adds a smooth Coulomb friction
    ``F_c v / sqrt(v^2 + v_s^2)``.  The gains are known: fixed to the firmware's values, not fitted."""
    return plant(b=B, friction=(F_C, V_S) if friction else None)


def reference(t, seed):
    """Steps between held set points and a slow sweep: what a test bench commands."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-0.02, 0.02, size=int(t[-1] / 0.5) + 1)
    steps = levels[(t / 0.5).astype(int)]
    return steps + 0.005 * np.sin(2 * np.pi * 0.7 * t)


# %% Record the truth under the loop (reference, position and controller force; 1 % / 2 % noise)
truth = model(friction=True)
sim = simulator(truth)
rng = np.random.default_rng(1)
recs = []
for k in range(2):
    t = np.arange(0.0, SPAN, DT)
    r = reference(t, seed=10 + k)
    res = sim.run(t, u={"r": r})
    pos, uc = res["position"], res["u_c"]
    recs.append(Recording.from_arrays(t, {"r": r, "position": pos + 0.01 * np.ptp(pos) * rng.standard_normal(t.size),
                                          "u_c": uc + 0.02 * np.std(uc) * rng.standard_normal(t.size)},
                                      source=f"closed-loop bench run {k + 1} (simulated)",
                                      units={"r": "m", "position": "m", "u_c": "N"}))
train, val = recs

# %% Diagnose plant + known controller: the plant's mass, stiffness and damping refitted
nominal = model(friction=False)
wall = time.perf_counter()
d = diagnose(nominal, train, validation=val, free=["m.m", "k.K", "b.b"], outputs=["position", "u_c"])
print(d)
print(f"verdict {d.effect}")
print(f"diagnose: {time.perf_counter() - wall:.1f} s wall")

# %% Figures
for path in write_figures(d, args.out, "closed_loop"):
    print(f"wrote {path}")
