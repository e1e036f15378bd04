# %% [markdown]
# Identification of the manta-ray fin with the protocol of the curling HASEL paper (section 4.6): a 5 kV,
# 1 Hz sine for identification and a 5 kV, 0.5 Hz sine for validation, the fin's movement measured.  The
# truth is the fin with Table 6's parameters (systems.manta_ray_fin); the noise on each recording is
# scaled so that the truth itself scores the paper's fit (80.11 % and 77 %).
# Run: python docs/examples/identify_manta_ray_fin.py [--quick] [--out DIR]
# Writes docs/figures/identify_manta_ray_fin.png (or into --out DIR) and prints the tables of
# docs/systems/manta_ray_fin.md.

# %%
import argparse
import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

from codegen import simulate, simulator  # noqa: E402
from phs.workflows.identify import identify  # noqa: E402
from phs.workflows.identify.scoring import nrmse_fit  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.manta_ray_fin import manta_ray_fin  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ap = argparse.ArgumentParser(description="Identification and validation of the manta-ray fin (synthetic data)")
ap.add_argument("--quick", action="store_true", help="4 s recordings instead of 10 s (test size)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figure")
args = ap.parse_args()

N = 4
X0 = {f"shell{i}.l_p": 0.015 for i in range(1, N + 1)}
PAPER_FIT = {"identification": 80.11, "validation": 77.0}  # %, section 4.6
FREE = ["K_b", "b", "gamma2"]  # what one tip recording of a sine determines (steps 1 and 2 below)
DRIFT = ["C1", "R1", "R2"]
truth = manta_ray_fin(N)
rng = np.random.default_rng(11)
duration = 4.0 if args.quick else 10.0


def experiment(freq, fit_percent, name):
    """5 kV sine of ``freq`` Hz sampled at 1 kHz (the laser's 1 ms); white noise on the tip scaled so that
    the truth's fit on the noisy recording is ``fit_percent``."""
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0
    U = 5000.0 * np.sin(2 * np.pi * freq * t)
    tip = simulate(truth, t, u={"U": U}, x0=X0)["tip"]
    draw = rng.standard_normal(len(t))
    noise = draw * brentq(lambda s: nrmse_fit(tip + s * draw, tip) - fit_percent, 0.0, np.ptp(tip))
    rec = Recording.from_arrays(t, {"U": U, "tip": tip + noise}, source=name, units={"U": "V", "tip": "m"})
    print(f"{name}: tip {1e3 * tip.min():.2f}..{1e3 * tip.max():.2f} mm, noise RMS {1e3 * np.std(noise):.3f} mm, "
          f"truth's fit {nrmse_fit(rec['tip'], tip):.2f} % (paper {fit_percent} %)")
    return rec


train = experiment(1.0, PAPER_FIT["identification"], "identification, 1 Hz")
valid = experiment(0.5, PAPER_FIT["validation"], "validation, 0.5 Hz")

# %% 1. A symmetry of the tip: the electrostatic torque goes with (gamma1 U)^2, so scaling K_b, b and I_s by
# lam and gamma1 by sqrt(lam) moves the shells exactly as before; only the current (not measured) changes.
sim = simulator(truth, rtol=1e-10)
lam = 2.0
scaled = {"K_b": lam * truth.param("K_b").value, "b": lam * truth.param("b").value,
          "I_s": lam * truth.param("I_s").value, "gamma1": np.sqrt(lam) * truth.param("gamma1").value}
a = sim.run(train.t, u={"U": train["U"]}, x0=X0)
b = sim.run(train.t, u={"U": train["U"]}, x0=X0, params=scaled)
print(f"symmetry: K_b, b, I_s x {lam:g} and gamma1 x sqrt({lam:g}): tip changes by "
      f"{np.max(np.abs(a['tip'] - b['tip'])) / np.ptp(a['tip']):.1e} of its range, the current by "
      f"{np.max(np.abs(a['current'] - b['current'])) / np.ptp(a['current']):.2f}")

# %% 2. The drift branch: fitted from the truth together with the mechanics, which combinations does the
# tip determine?
wall = time.perf_counter()
drift = identify(truth, train, FREE + DRIFT, x0=X0, validation=valid, outputs=["tip"])
print(f"drift parameters free ({time.perf_counter() - wall:.1f} s wall):")
for sentence in drift.identifiability_sentences():
    print("  " + sentence)
print("  truth: C1*R2 = {:.4g} s, R1/R2 = {:.4g}".format(truth.param("C1").value * truth.param("R2").value,
                                                     truth.param("R1").value / truth.param("R2").value))

# %% 3. The identifiable parameters, from starts 30 % off (alternating signs)
start = {k: truth.param(k).value * (1.3 if i % 2 == 0 else 0.7) for i, k in enumerate(FREE)}
wall = time.perf_counter()
fit = identify(truth, train, FREE, x0=X0, initial=start, validation=valid, outputs=["tip"])
print(fit)
print(f"identify: {time.perf_counter() - wall:.1f} s wall")
print("\n| parameter | truth (Table 6) | start | fitted | 95 % interval | error |")
print("| --- | ---: | ---: | ---: | --- | ---: |")
for k in FREE:
    v = truth.param(k).value
    lo, hi = fit.intervals[k]
    print(f"| `{k}` | {v:.4g} | {start[k]:.4g} | {fit.values[k]:.4g} | [{lo:.4g}, {hi:.4g}] | "
          f"{100 * (fit.values[k] / v - 1):+.2f} % |")
print(f"\nfit tip: {fit.fit_percent['tip']:.2f} % identification (paper {PAPER_FIT['identification']} %), "
      f"{fit.validation_fit_percent['tip']:.2f} % validation (paper {PAPER_FIT['validation']} %)")

# %% Figure
sim_t = simulate(fit.fitted_system, train.t, u={"U": train["U"]}, x0=X0)
sim_v = simulate(fit.fitted_system, valid.t, u={"U": valid["U"]}, x0=X0)
fig, ax = plt.subplots(1, 3, figsize=(13, 3.8), gridspec_kw={"width_ratios": [1.3, 1.3, 1]})
for axis, rec, res, title, key in ((ax[0], train, sim_t, "identification: 5 kV, 1 Hz", "identification"),
                                    (ax[1], valid, sim_v, "validation: 5 kV, 0.5 Hz", "validation")):
    fit_pct = fit.fit_percent["tip"] if key == "identification" else fit.validation_fit_percent["tip"]
    axis.plot(rec.t, rec["tip"] * 1e3, lw=0.4, color="0.6", label=f"measured (synthetic; truth scores {PAPER_FIT[key]} %)")
    axis.plot(rec.t, res["tip"] * 1e3, lw=1.2, label=f"fitted model ({fit_pct:.1f} %)")
    axis.set_title(title)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("fin tip [mm]")
    axis.legend(fontsize=8, loc="lower right")
x = np.arange(len(FREE))
true = np.array([truth.param(k).value for k in FREE])
err = 100 * (np.array([fit.values[k] for k in FREE]) / true - 1)
lo = 100 * (np.array([fit.intervals[k][0] for k in FREE]) / true - 1)
hi = 100 * (np.array([fit.intervals[k][1] for k in FREE]) / true - 1)
ax[2].plot(x, 100 * (np.array([start[k] for k in FREE]) / true - 1), "x", color="grey", label="start")
ax[2].errorbar(x, err, yerr=[err - lo, hi - err], fmt="o", capsize=3, label="fitted, 95 % interval")
ax[2].axhline(0.0, color="k", lw=0.5)
ax[2].set_xticks(x, FREE)
ax[2].set_ylabel("relative to Table 6 [%]")
ax[2].set_title("parameter recovery")
ax[2].legend(fontsize=8)
fig.tight_layout()
os.makedirs(args.out, exist_ok=True)
path = os.path.join(args.out, "identify_manta_ray_fin.png")
fig.savefig(path, dpi=90)
print("wrote", os.path.normpath(path))
