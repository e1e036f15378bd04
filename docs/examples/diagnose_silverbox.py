# %% [markdown]
# Diagnosis on a real recording: the Silverbox (an electronic Duffing oscillator, Wigren & Schoukens
# 2013) seen through a linear mass-spring-damper.  The diagnosis should name the missing physics:
# cubic stiffness.
# Run: python docs/examples/diagnose_silverbox.py [--quick] [--out DIR]
# Reads ../shared/data/silverbox/SNLS80mV.csv relative to the repository root (skips with a message
# if absent); writes docs/figures/diagnose_silverbox_{fits,locate,hypotheses}.png (or into --out DIR).

# %%
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
DATA = os.path.join(ROOT, "..", "shared", "data", "silverbox", "SNLS80mV.csv")

ap = argparse.ArgumentParser(description="Diagnosis of a linear model of the Silverbox")
ap.add_argument("--quick", action="store_true", help="a shorter window (test size)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

if not os.path.isfile(DATA):
    print(f"Silverbox data not found at {os.path.normpath(DATA)}: skipping this example.")
    sys.exit(0)

from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.identify.starts import second_order_start  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.examples import mass_spring_damper  # noqa: E402

FS = 1e7 / 2**14  # sampling frequency [Hz] (README of the data set)
FORCE_PER_VOLT = 1e5  # N/V: the input voltage V1 read as a force (a choice of units, as in identify_silverbox.py)

# %% The data: V1 (input), V2 (output, the "displacement"); offsets removed.  A window of the arrow's end
# (filtered noise of large amplitude, where the linear model fails, docs/studies/identification.md), starting
# where the signal is still small so the model's rest state is a fair initial state
raw = np.genfromtxt(DATA, delimiter=",", skip_header=1, usecols=(0, 1))
v1, v2 = raw[:, 0] - raw[:, 0].mean(), raw[:, 1] - raw[:, 1].mean()
n = 600 if args.quick else 1200
start = 40000 - n
t = np.arange(n) / FS
rec = Recording.from_arrays(t, {"F": v1[start:start + n] * FORCE_PER_VOLT, "position": v2[start:start + n]},
                            source="SNLS80mV arrow", units={"F": "N", "position": "m"})

# %% Start values from a second-order ARX fit (as in identify_silverbox.py)
start = second_order_start(rec["position"], rec["F"], FS)
model = mass_spring_damper(m=start["m"], k=start["k"], b=start["b"])

# %% Diagnose (the first 70 % of the window trains, the last 30 % validates)
wall = time.perf_counter()
d = diagnose(model, rec, free=["m.m", "k.K", "b.b"], outputs=["position"])
print(d)
print(f"diagnose: {time.perf_counter() - wall:.1f} s wall")

# %% Figures
for path in write_figures(d, args.out, "diagnose_silverbox"):
    print(f"wrote {path}")
