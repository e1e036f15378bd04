# %% [markdown]
# Diagnosis on a real recording: the seal friction rig of a 3D-printed pneumatic actuator (TU Delft,
# E. Zillen).  A drive pushes the piston in and out through about 35 mm at a constant supply
# pressure while a load cell measures the rod force.  The nominal model has a viscous seal (force
# proportional to speed); the seal's friction is really Coulomb-like (a force level that flips at
# each reversal).  Does the diagnosis find it?
# Run: python docs/examples/diagnose_seal_friction.py [--quick] [--file NAME] [--out DIR]
# Reads ../shared/data/pneumatic_actuator_tudelft/friction_*.csv relative to the repository root
# (skips with a message if absent); writes docs/figures/diagnose_friction_{fits,locate,hypotheses}.png.

# %%
import argparse
import os
import sys
import time

import numpy as np
from scipy.signal import savgol_filter

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, ROOT)
DATA = os.path.join(ROOT, "..", "shared", "data", "pneumatic_actuator_tudelft")

ap = argparse.ArgumentParser(description="Diagnosis of a viscous-seal model of a pneumatic piston")
ap.add_argument("--quick", action="store_true", help="20 s to train and 20 s to validate")
ap.add_argument("--file", default="friction_O-ring257_7bar", help="which friction record (without .csv)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

path = os.path.join(DATA, f"{args.file}.csv")
if not os.path.isfile(path):
    print(f"pneumatic actuator data not found at {os.path.normpath(path)}: skipping this example.")
    sys.exit(0)

from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.lab import seal_friction_rig  # noqa: E402

DT = 0.02  # s: the 100 Hz record (with a few late samples) resampled onto a uniform 50 Hz grid

# %% The data: chamber pressure [bar] and rod force [N] as recorded; the drive's velocity from the
# position (Savitzky-Golay derivative over 0.1 s).  The position grows as the drive pushes the piston
# in, so the velocity in the model's direction of extension is minus its derivative
raw = np.genfromtxt(path, delimiter=",", names=True)
t_raw = raw["time_ms"] / 1000.0
span = 20.0 if args.quick else 40.0
t = np.arange(0.0, 2 * span, DT)
pos = np.interp(t, t_raw, raw["position_mm"]) * 1e-3
signals = {"P": np.interp(t, t_raw, raw["pressure_bar"]) * 1e5,
           "v": -savgol_filter(pos, 5, 2, deriv=1, delta=DT),
           "force": np.interp(t, t_raw, raw["force_N"])}
half = len(t) // 2
train = Recording.from_arrays(t[:half], {k: v[:half] for k, v in signals.items()}, source=f"{args.file}.csv (first half)",
                              units={"P": "Pa", "v": "m/s", "force": "N"})
val = Recording.from_arrays(t[half:] - t[half], {k: v[half:] for k, v in signals.items()},
                            source=f"{args.file}.csv (second half)", units={"P": "Pa", "v": "m/s", "force": "N"})

# %% Starting values: the piston area from the force per pressure at rest, the seal's damping from the
# force difference between the strokes in and out divided by their speed difference
A0 = float(np.median(train["force"] / train["P"]))
v, dF = train["v"], train["force"] - A0 * train["P"]
b0 = float(max(-np.polyfit(v, dF, 1)[0], 10.0))
model = seal_friction_rig(A=A0, b=b0)
x0 = {"q": float(train["force"][0]) / 2e5, "p": 0.0}
print(f"start: A = {A0:.4e} m², b = {b0:.0f} N s/m")

# %% Diagnose (nominal: area and viscous seal refitted)
wall = time.perf_counter()
d = diagnose(model, train, validation=val, free=["A", "b"], x0=x0)
print(d)
print(f"diagnose: {time.perf_counter() - wall:.1f} s wall")

# %% Figures
for path in write_figures(d, args.out, "diagnose_friction"):
    print(f"wrote {path}")
