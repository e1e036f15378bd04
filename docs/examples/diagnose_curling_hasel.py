# %% [markdown]
# Diagnosis of a curling HASEL model that lacks the charge-retention (drift) branch: the paper's own
# story, where the drift after each voltage step had to be explained by adding an RC branch by hand.
# Run: python docs/examples/diagnose_curling_hasel.py [--quick] [--out DIR]
# Writes docs/figures/diagnose_curling_hasel_{fits,locate,hypotheses}.png (or into --out DIR) and prints
# the numbers quoted in docs/studies/diagnosis.md.

# %%
import argparse
import os
import time

import numpy as np

from codegen import simulate
from phs.signals import square, staircase
from phs.workflows.diagnose import diagnose
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording
from systems.curling_hasel import curling_hasel

HERE = os.path.dirname(os.path.abspath(__file__))
ap = argparse.ArgumentParser(description="Diagnosis of the curling HASEL without its drift branch")
ap.add_argument("--quick", action="store_true", help="3 s recordings (test size)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

N = 2  # segments: two keep the run short; the model structure (per-segment drift branch) is the paper's
X0 = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}
truth = curling_hasel(N, network="printed")                 # with the retention branch C1 || R1 of every segment
nominal = curling_hasel(N, drift=False, network="printed")  # the model before the drift was explained
rng = np.random.default_rng(11)


def experiment(drive, duration, name):
    """The true actuator at 1 kHz; tip recorded with Gaussian noise of 1 % of its range, the current with
    2 % of its standard deviation (its range is set by the spikes at the steps)."""
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0
    U = np.asarray(drive(t), dtype=float)
    res = simulate(truth, t, u={"U": U}, x0=X0)
    noisy = {"tip": res["tip"] + 0.01 * np.ptp(res["tip"]) * rng.standard_normal(len(t)),
             "current": res["current"] + 0.02 * np.std(res["current"]) * rng.standard_normal(len(t))}
    return Recording.from_arrays(t, {"U": U, **noisy}, source=name, units={"U": "V", "tip": "m", "current": "A"})


# %% Training: the paper's negative staircase (1 kV steps every 4 s); validation: a 0/-4 kV square wave
duration = 6.0 if args.quick else 20.0
train = experiment(staircase(-1000.0, every=duration / 5, n_steps=5), duration, "staircase")
valid = experiment(square(-2000.0, 2.0 / duration, offset=-2000.0), duration, "square wave")

# %% Diagnose: refit K_b, b, gamma1, gamma2, R2 with every hypothesis of the library (--quick: with the
# electrical candidates and two mechanical ones, to keep the test short)
from components.candidates import LIBRARY  # noqa: E402

quick_set = {"charge_retention", "leakage", "series_resistance", "offset", "coulomb_friction", "cubic_stiffness"}
wall = time.perf_counter()
d = diagnose(nominal, train, validation=valid, free=["K_b", "b", "gamma1", "gamma2", "R2"], x0=X0, max_effects=1,
             candidates=[c for c in LIBRARY if c.effect in quick_set] if args.quick else None)
print(d)
print(f"diagnose: {time.perf_counter() - wall:.1f} s wall")
print("structural checks of the augmented model:", "passed" if d.structure_checks()["ok"] else "FAILED")
aug = d.accepted[0] if d.accepted else None
if aug is not None:
    C1, R1 = truth.param("C1").value, truth.param("R1").value
    print(f"truth: C1 = {C1:.3g} F, tau = R1 C1 = {R1 * C1:.3g} s;  found: "
          + ", ".join(f"{k} = {aug.values[k]:.3g}" for k in aug.augmentation.free))

# %% Figures
for path in write_figures(d, args.out, "diagnose_curling_hasel"):
    print(f"wrote {path}")
