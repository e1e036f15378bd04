# %% [markdown]
# Diagnosis on a real recording: the cascaded tanks benchmark (Schoukens, Mattsson, Wigren, Noël 2016)
# seen through the textbook Torricelli model, which has no level limit.  The recordings overflow: at
# the largest inputs the upper tank spills and the lower tank's level sensor reads exactly 10 V.
# What does the diagnosis locate, and what does it name?
# Run: python docs/examples/diagnose_cascaded_tanks.py [--quick] [--out DIR]
# Reads ../shared/data/cascaded_tanks/dataBenchmark.csv relative to the repository root (skips with a
# message if absent); writes docs/figures/diagnose_tanks_{fits,locate,hypotheses}.png.

# %%
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, ROOT)
DATA = os.path.join(ROOT, "..", "shared", "data", "cascaded_tanks", "dataBenchmark.csv")

ap = argparse.ArgumentParser(description="Diagnosis of a Torricelli model of the cascaded tanks")
ap.add_argument("--quick", action="store_true", help="the first half of each record")
ap.add_argument("--library-only", action="store_true", help="without the Overflow candidate defined here")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

if not os.path.isfile(DATA):
    print(f"cascaded tanks data not found at {os.path.normpath(DATA)}: skipping this example.")
    sys.exit(0)

import sympy as sp  # noqa: E402

from components.candidates import LIBRARY, Augmentation, Candidate, add_damping, stored_quantity_states  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.lab import cascaded_tanks  # noqa: E402

TS = 4.0  # s (README of the data set)


# %% A candidate of our own: a tank that spills over its rim.  Above the level V_max the tank loses
# water at a rate growing steeply with the excess, q_s = c w softplus((V − V_max)/w) (w = 0.1 level
# units: a rim, not a step), as a drain R[V, V] += q_s / e with e = ∂H/∂V the tank's pressure: passive
# (q_s ≥ 0, e > 0).  It attaches where the pressure stays positive on an empty tank (the upper tank,
# whose outlet sits h0 above the lower one), so the drain is finite everywhere.
class Overflow(Candidate):
    effect = "overflow"
    summary = "the tank spilling over its rim above a level V_max"
    W = 0.1

    def attach_points(self, system):
        zero = {st.symbol: 0.0 for st in system.states} | {p.symbol: p.value for p in system.params}
        return [n for n in stored_quantity_states(system)
                if float(sp.diff(system.H, system.states[system.state_names.index(n)].symbol).subs(zero)) > 0]

    def augment(self, system, where, scales):
        self._check_where(system, where)
        V = system.states[system.state_names.index(where)].symbol
        e = sp.diff(system.H, V)
        level = scales.get("level", where)
        vmax = self.param("V_max", 1.5 * level, "m**3", f"level at which {where} spills", (0.5 * level, 5 * level))
        c = self.param("c", 1.0, "m**2/s", "spill rate per unit of excess level", (1e-3, 1e2))
        q_s = c.symbol * self.W * sp.log(1 + sp.exp((V - vmax.symbol) / self.W))
        s = add_damping(system, where, q_s / e, [vmax, c], self.effect)
        return Augmentation(self.effect, where, "spill c·w·softplus((V − V_max)/w) over the rim", s, [vmax.name, c.name],
                            {vmax.name: vmax.range, c.name: c.range}, [c.name],
                            starts=tuple({vmax.name: f * level} for f in (1.2, 2.0)))

# %% The data: estimation (uEst, yEst) trains, validation (uVal, yVal) validates; pump voltage and the
# lower tank's level sensor, both in volts (the model reads the level's volts as its unit of level)
raw = np.genfromtxt(DATA, delimiter=",", skip_header=1, usecols=(0, 1, 2, 3))
n = 512 if args.quick else len(raw)
t = np.arange(n) * TS
train = Recording.from_arrays(t, {"u": raw[:n, 0], "level2": raw[:n, 2]}, source="dataBenchmark.csv (estimation)",
                              units={"u": "V"})  # the level sensor reads volts, which the model takes as its level
val = Recording.from_arrays(t, {"u": raw[:n, 1], "level2": raw[:n, 3]}, source="dataBenchmark.csv (validation)",
                            units={"u": "V"})
print(f"lower tank at the sensor's limit (10 V): {int(np.sum(raw[:n, 2] >= 10.0))} estimation samples, "
      f"{int(np.sum(raw[:n, 3] >= 10.0))} validation samples")

# %% Starting values from the steady state of the Torricelli model: k4 u = k1 sqrt(V1) = k2 sqrt(V2) at
# the records' means; the initial levels are estimated with the fit (the tanks do not start at rest)
u_m, y_m = float(np.mean(train["u"])), float(np.mean(train["level2"]))
k2 = 0.02
k4 = k2 * np.sqrt(y_m) / u_m
model = cascaded_tanks(k1=k2, k2=k2, k4=k4)
x0 = {"V1": y_m, "V2": float(train["level2"][0])}

# %% Diagnose
wall = time.perf_counter()
d = diagnose(model, train, validation=val, free=["k1", "k2", "k4"], x0=x0, estimate_x0=["V1", "V2"],
             candidates=LIBRARY if args.library_only else [*LIBRARY, Overflow()])
print(d)
print(f"diagnose: {time.perf_counter() - wall:.1f} s wall")

# %% Where the nominal model misses: the residual above and below the sensor's limit
res = d.nominal.residuals["level2"]
clip = train["level2"][: len(res)] >= 9.99
if clip.any():
    print(f"nominal residual (measured - model) at the 10 V samples: mean {np.mean(res[clip]):+.3f} V; "
          f"elsewhere {np.mean(res[~clip]):+.3f} V (RMS {np.sqrt(np.mean(res[~clip] ** 2)):.3f} V)")

# %% Figures
for path in write_figures(d, args.out, "diagnose_tanks"):
    print(f"wrote {path}")
