# %% [markdown]
# Identification on a real recording: a linear mass-spring-damper fitted to the Silverbox
# (an electronic Duffing oscillator, Wigren & Schoukens 2013), and where it fails.
# Run: python docs/examples/identify_silverbox.py [--quick] [--out DIR]
# Reads ../shared/data/silverbox/SNLS80mV.csv relative to the repository root (skips with a
# message if the folder is absent); writes docs/figures/identify_silverbox.png (or into --out DIR).

# %%
import argparse
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
DATA = os.path.join(ROOT, "..", "shared", "data", "silverbox", "SNLS80mV.csv")

ap = argparse.ArgumentParser(description="Linear fit of the Silverbox and its failure at large amplitude")
ap.add_argument("--quick", action="store_true", help="shorter estimation window, half of the validation windows")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figure")
args = ap.parse_args()

if not os.path.isfile(DATA):
    print(f"Silverbox data not found at {os.path.normpath(DATA)}: skipping this example.")
    sys.exit(0)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from codegen import simulator  # noqa: E402
from phs.workflows.identify import identify, nrmse_fit  # noqa: E402
from phs.workflows.identify.starts import second_order_start  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.examples import mass_spring_damper  # noqa: E402

FS = 1e7 / 2**14  # sampling frequency [Hz] (README of the data set)
FORCE_PER_VOLT = 1e5  # N/V: the input voltage V1 read as a force F (a choice of units, see the docs page)
LEAD = 200  # samples simulated before each validation window and discarded (transients decay in ~30)

# %% The data: V1 (input voltage), V2 (output voltage, the oscillator's "displacement"); offsets removed
raw = np.genfromtxt(DATA, delimiter=",", skip_header=1, usecols=(0, 1))
v1, v2 = raw[:, 0] - raw[:, 0].mean(), raw[:, 1] - raw[:, 1].mean()
print(f"Silverbox: {len(v1)} samples at {FS:.2f} Hz")


def recording(sl, name):
    """Samples ``sl`` as a Recording (time from 0): force F = 1e5 N/V * V1, position = V2 (1 m/V)."""
    t = np.arange(sl.stop - sl.start) / FS
    return Recording.from_arrays(t, {"F": v1[sl] * FORCE_PER_VOLT, "position": v2[sl]}, source=name,
                                 units={"F": "N", "position": "m"})


# Estimation: a window of the first odd random-phase multisine (moderate amplitude; it starts near
# sample 40,600).  Validation: the "arrow" (samples 0 .. 40,000: filtered noise whose amplitude grows
# linearly), whose end extrapolates beyond the amplitude of the estimation data.
rec_est = recording(slice(40650, 40650 + (300 if args.quick else 1500)), "SNLS80mV multisine")

# %% Start values from a second-order ARX least-squares fit of the estimation window
start = second_order_start(rec_est["position"], rec_est["F"], FS)
k0, m0, b0 = start["k"], start["m"], start["b"]  # k: static stiffness F/x
print(f"ARX start: f_n = {start['f_n']:.2f} Hz, zeta = {start['zeta']:.4f}, k = {k0:.4g} N/m, m = {m0:.4g} kg, b = {b0:.4g}")

# %% Output-error fit of m, k, b (and the initial state) of the linear mass-spring-damper
model = mass_spring_damper(m=m0, k=k0, b=b0)
wall = time.perf_counter()
fit = identify(model, rec_est, ["m.m", "k.K", "b.b"], outputs=["position"], estimate_x0=["m.p", "k.l"])
print(fit)
print(f"identify: {time.perf_counter() - wall:.2f} s wall")
fitted = fit.fitted_system
m, k, b = fit.values["m.m"], fit.values["k.K"], fit.values["b.b"]
print(f"fitted natural frequency {np.sqrt(k / m) / 2 / np.pi:.3f} Hz, damping ratio {b / (2 * np.sqrt(k * m)):.4f}")

# %% Validation on the arrow in 16 windows (--quick: every other one), each simulated from rest with a
# lead-in of LEAD samples that is discarded
sim = simulator(fitted)


def position(rec, x0=None, block=250):
    """Simulated position on ``rec``'s grid, in blocks of ``block`` samples with the state carried over.

    One run over n samples of a sampled input costs O(n^2) in this version of the simulator (every
    right-hand-side evaluation sees all n samples); blocks of equal length share one integrator.
    """
    out, i = np.empty(len(rec)), 0
    while i < len(rec) - 1:
        j = min(i + block, len(rec) - 1)
        run = sim.run(rec.t[i:j + 1] - rec.t[i], u={"F": rec["F"][i:j + 1]}, x0=x0)
        out[i:j + 1], x0, i = run["position"], run.x[-1], j
    return out


windows = np.array_split(np.arange(40000), 16)[:: 2 if args.quick else 1]
peak, fits, ys, res, forces = [], [], [], [], []
for w in windows:
    start = max(int(w[0]) - LEAD, 0)
    rec = recording(slice(start, int(w[-1]) + 1), "SNLS80mV arrow")
    y_hat = position(rec)[w[0] - start:]
    y_w = rec["position"][w[0] - start:]
    peak.append(float(np.max(np.abs(y_w))))
    fits.append(nrmse_fit(y_w, y_hat))
    ys.append(y_w)
    res.append(y_w - y_hat)
    forces.append(rec["F"][w[0] - start:])
val_fit = nrmse_fit(np.concatenate(ys), np.concatenate(ys) - np.concatenate(res))
print(f"validation: fit {val_fit:.1f} % on {sum(len(w) for w in windows)} arrow samples")
print(f"estimation data: rms {np.std(rec_est['position']):.3f} V, peak {np.max(np.abs(rec_est['position'])):.3f} V")
print("arrow windows (peak |position| [V] -> fit %): "
      + ", ".join(f"{pk:.2f} -> {f:.1f}" for pk, f in zip(peak, fits, strict=True)))

# %% Residual against position.  The output residual is a filtered image of the missing force, so look
# at the force the linear model leaves unexplained: r_F = F - (m y'' + b y' + k y) with the measured
# position (5-point derivatives), minus its part linear in (y'', y', y): a component-plus-residual plot.
h = 1 / FS
Y, D1, D2, RF = [], [], [], []
for y_w, f_w in zip(ys, forces, strict=True):
    yc = y_w[2:-2]
    d1 = (-y_w[4:] + 8 * y_w[3:-1] - 8 * y_w[1:-3] + y_w[:-4]) / (12 * h)
    d2 = (-y_w[4:] + 16 * y_w[3:-1] - 30 * yc + 16 * y_w[1:-3] - y_w[:-4]) / (12 * h**2)
    Y.append(yc)
    D1.append(d1)
    D2.append(d2)
    RF.append(f_w[2:-2] - (m * d2 + b * d1 + k * yc))
Y, D1, D2, RF = (np.concatenate(v) for v in (Y, D1, D2, RF))
c = np.linalg.lstsq(np.column_stack([D2, D1, Y, Y**3]), RF, rcond=None)[0]
partial = RF - c[0] * D2 - c[1] * D1 - c[2] * Y
k3 = c[3]
print(f"force residual of the linear model ~ {k3:.4g} y^3 (+ linear terms); k3 y^2 / k at |y| = 0.3 V: "
      f"{100 * k3 * 0.09 / k:.0f} %; corr(partial residual, y^3) = {np.corrcoef(partial, Y**3)[0, 1]:.3f}")
edges = np.linspace(Y.min(), Y.max(), 31)
bins = [(Y >= lo) & (Y <= hi) for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
centres = [float(np.mean(Y[sel])) for sel in bins if sel.sum() >= 20]
means = [float(np.mean(partial[sel])) for sel in bins if sel.sum() >= 20]

# %%
fig, ax = plt.subplots(2, 2, figsize=(10, 6.5))
n = min(len(rec_est), int(0.5 * FS))
ax[0, 0].plot(rec_est.t[:n], rec_est["position"][:n], lw=1, label="measured V2")
ax[0, 0].plot(rec_est.t[:n], position(rec_est, x0=fit.x0)[:n], lw=1,
              label=f"linear model (fit {fit.fit_percent['position']:.1f} %)")
ax[0, 0].set_title("estimation: multisine")
ax[0, 0].set_xlabel("t [s]")
ax[0, 0].legend(fontsize=8)
last = windows[-1]
tt = last / FS
ax[0, 1].plot(tt, ys[-1], lw=0.6, label="measured")
ax[0, 1].plot(tt, res[-1], lw=0.6, label="residual (measured - model)")
ax[0, 1].set_title(f"validation: end of the arrow (fit {fits[-1]:.1f} %)")
ax[0, 1].set_xlabel("t [s]")
ax[0, 1].legend(fontsize=8)
order = np.argsort(peak)
ax[1, 0].plot(np.array(peak)[order], np.array(fits)[order], "o-")
ax[1, 0].axvline(np.max(np.abs(rec_est["position"])), color="k", ls=":", label="peak of the estimation data")
ax[1, 0].set_xlabel("peak |position| in the window [V]")
ax[1, 0].set_ylabel("fit % in the window")
ax[1, 0].set_title("arrow windows: the fit depends on amplitude")
ax[1, 0].legend(fontsize=8, loc="lower center")
ax[1, 1].plot(Y, partial, ",", alpha=0.3, label="samples")
ax[1, 1].plot(centres, means, "ko", ms=3, label="mean per bin")
yy = np.linspace(Y.min(), Y.max(), 200)
ax[1, 1].plot(yy, k3 * yy**3, "r", label=f"{k3:.3g} y³")
ax[1, 1].set_xlabel("position y (V2) [V]")
ax[1, 1].set_ylabel("unexplained force [N]")
ax[1, 1].set_title("force residual against position: cubic stiffness")
ax[1, 1].legend(fontsize=8)
fig.tight_layout()
os.makedirs(args.out, exist_ok=True)
path = os.path.join(args.out, "identify_silverbox.png")
fig.savefig(path, dpi=90)
print("wrote", os.path.normpath(path))
