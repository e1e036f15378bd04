# %% [markdown]
# Grey-box identification and validation of the curling HASEL on synthetic data, with the
# +-5/+-10 % sensitivity table compared with Table 5 of the curling HASEL paper.
# Run: python docs/examples/identify_curling_hasel.py [--quick] [--out DIR]
# Writes docs/figures/identify_curling_hasel.png (or into --out DIR) and prints the tables of
# docs/studies/identification.md.

# %%
import argparse
import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codegen import simulate  # noqa: E402
from phs.signals import square, staircase  # noqa: E402
from phs.workflows.identify import identify  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.curling_hasel import curling_hasel  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ap = argparse.ArgumentParser(description="Identification and validation of the curling HASEL (synthetic data)")
ap.add_argument("--quick", action="store_true", help="2 s of training and validation data (test size)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figure")
args = ap.parse_args()

N = 4
FREE = ["K_b", "b", "gamma1", "gamma2", "C1", "R2"]
PAPER_SD = {"gamma1": 6.7834, "gamma2": 1.5172, "K_b": 1.0908, "R2": 0.4219, "C1": 0.2539, "b": 0.0370}  # Table 5
X0 = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}
truth = curling_hasel(N, network="printed")  # Table 4 as printed: the numbers of docs/studies/identification.md
rng = np.random.default_rng(7)


def experiment(drive, duration, name):
    """Simulate the true model at 1 kHz; record U, tip and current with 1 % (of range) Gaussian noise."""
    t = np.arange(int(round(duration * 1000)) + 1) / 1000.0
    U = np.asarray(drive(t), dtype=float)
    res = simulate(truth, t, u={"U": U}, x0=X0)
    noisy = {ch: res[ch] + 0.01 * np.ptp(res[ch]) * rng.standard_normal(len(t)) for ch in ("tip", "current")}
    return Recording.from_arrays(t, {"U": U, **noisy}, source=name, units={"U": "V", "tip": "m", "current": "A"})


# %% Training: a staircase down to -5 kV in 1 kV steps every 2 s; validation: a -4 kV / 0 square wave at 1 Hz
# (both start with a step at t = 0)
duration = 2.0 if args.quick else 10.0
train = experiment(staircase(-1000.0, every=2.0, n_steps=5), duration, "staircase")
valid = experiment(square(-2000.0, 1.0, offset=-2000.0), duration, "square wave")

# %% Fit six parameters from starts 30 % off (alternating signs)
start = {k: truth.param(k).value * (1.3 if i % 2 == 0 else 0.7) for i, k in enumerate(FREE)}
wall = time.perf_counter()
fit = identify(truth, train, FREE, x0=X0, initial=start, validation=valid)
print(fit)
print(f"identify: {time.perf_counter() - wall:.1f} s wall")
print(f"{'parameter':<8}{'truth':>11}{'start':>11}{'fitted':>12}{'error':>9}")
for k in FREE:
    v = truth.param(k).value
    print(f"{k:<8}{v:>11.4g}{start[k]:>11.4g}{fit.values[k]:>12.5g}{fit.values[k] / v - 1:>+9.2%}")

# %% Sensitivity of the tip fit (Table 5 of the paper): each parameter alone at -10, -5, 0, +5, +10 %
wall = time.perf_counter()
table = fit.sensitivity_table(channel="tip")
print(f"sensitivity table: {time.perf_counter() - wall:.1f} s wall")
steps = [-0.10, -0.05, 0.0, 0.05, 0.10]
ours_rank = sorted(FREE, key=lambda k: -table[k]["std"])
paper_rank = sorted(FREE, key=lambda k: -PAPER_SD[k])
print("\n| parameter | -10 % | -5 % | 0 % | +5 % | +10 % | SD (ours) | rank | SD (paper) | rank (paper) |")
print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
for k in paper_rank:
    row = table[k]
    print(f"| `{k}` | " + " | ".join(f"{row[s]:.2f}" for s in steps)
          + f" | {row['std']:.4f} | {ours_rank.index(k) + 1} | {PAPER_SD[k]:.4f} | {paper_rank.index(k) + 1} |")
print(f"\nranking, ours:  {' > '.join(ours_rank)}\nranking, paper: {' > '.join(paper_rank)}")

# %%
sim_t = simulate(fit.fitted_system, train.t, u={"U": train["U"]}, x0=fit.x0)
sim_v = simulate(fit.fitted_system, valid.t, u={"U": valid["U"]}, x0=fit.x0)
fig, ax = plt.subplots(2, 2, figsize=(11, 6.5))
ax[0, 0].plot(train.t, train["tip"] * 1e3, lw=0.6, label="measured (synthetic, 1 % noise)")
ax[0, 0].plot(train.t, sim_t["tip"] * 1e3, lw=1.2, label=f"fitted model ({fit.fit_percent['tip']:.1f} %)")
ax[0, 0].set_title("training: staircase to -5 kV")
ax[0, 0].set_ylabel("tip [mm]")
ax[0, 1].plot(valid.t, valid["tip"] * 1e3, lw=0.6, label="measured (synthetic, 1 % noise)")
ax[0, 1].plot(valid.t, sim_v["tip"] * 1e3, lw=1.2, label=f"fitted model ({fit.validation_fit_percent['tip']:.1f} %)")
ax[0, 1].set_title("validation: -4 kV / 0 square wave, 1 Hz")
for a in ax[0]:
    a.set_xlabel("t [s]")
    a.legend(fontsize=8)
x = np.arange(len(FREE))
true = np.array([truth.param(p).value for p in FREE])
err = 100 * (np.array([fit.values[p] for p in FREE]) / true - 1)
lo = 100 * (np.array([fit.intervals[p][0] for p in FREE]) / true - 1)
hi = 100 * (np.array([fit.intervals[p][1] for p in FREE]) / true - 1)
ax[1, 0].plot(x, 100 * (np.array([start[p] for p in FREE]) / true - 1), "x", color="grey", label="start")
ax[1, 0].errorbar(x, err, yerr=[err - lo, hi - err], fmt="o", capsize=3, label="fitted, 95 % interval")
ax[1, 0].axhline(0.0, color="k", lw=0.5)
ax[1, 0].set_xticks(x, FREE)
ax[1, 0].set_ylabel("relative to the truth [%]")
ax[1, 0].set_title("parameter recovery")
ax[1, 0].legend(fontsize=8)
ax[1, 1].bar(x - 0.2, [table[p]["std"] for p in paper_rank], 0.4, label="ours (synthetic data)")
ax[1, 1].bar(x + 0.2, [PAPER_SD[p] for p in paper_rank], 0.4, label="paper, Table 5")
ax[1, 1].set_xticks(x, paper_rank)
ax[1, 1].set_yscale("log")
ax[1, 1].set_ylabel("SD of the tip fit % over -10..+10 %")
ax[1, 1].set_title("sensitivity of the tip fit")
ax[1, 1].legend(fontsize=8)
fig.tight_layout()
os.makedirs(args.out, exist_ok=True)
path = os.path.join(args.out, "identify_curling_hasel.png")
fig.savefig(path, dpi=90)
print("wrote", os.path.normpath(path))
