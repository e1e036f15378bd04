# %% [markdown]
# A design study of the MSD HASEL (Hainsworth et al.): stroke, overshoot, rise time and energy of a voltage step
# against the step amplitude, the carried load and the damping; then a Monte Carlo band of the step response
# under uncertain load and damping.
# Run: python docs/examples/sweep_msd_hasel.py [--quick]
# Writes the figures of docs/workflows/sweep.md into docs/figures/ ($PHS_DOCS_OUT instead when set: tests).

# %%
import functools
import os
import shutil
import sys
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from phs import equilibrium  # noqa: E402
from phs.signals import step  # noqa: E402
from phs.workflows.sweep import LogNormal, Study, StudyResult, sweep  # noqa: E402
from phs.workflows.sweep.metrics import final, peak, rise_time, values_at  # noqa: E402
from systems.msd_hasel import msd_hasel  # noqa: E402

QUICK = "--quick" in sys.argv
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.environ.get("PHS_DOCS_OUT") or os.path.join(HERE, "..", "figures")  # tests write elsewhere
os.makedirs(OUT, exist_ok=True)
WORK = tempfile.mkdtemp(prefix="phs-sweep-")  # the results files of the studies


def save(fig, name):
    path = os.path.join(OUT, name)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print("wrote", path)


system = msd_hasel(fit_length="mm")  # the fits read in mm (the figures of docs/workflows/sweep.md)
T_STEP = 0.05  # the voltage step comes after 50 ms at rest
t = np.linspace(0.0, 0.3 if QUICK else 0.6, 301 if QUICK else 1201)


# %% Each run starts at rest under its load: the 0 kV equilibrium, computed once per load value
@functools.cache
def rest(m: float) -> dict:
    return equilibrium(system, u={"V": 0.0}, x0={"x": 0.1e-3}, params={"m": m}).as_dict()


def inputs(values):  # the step amplitude V_kV is a design variable that is not a parameter
    return {"V": step(values["V_kV"] * 1e3, T_STEP)}


# %% The design grid: step amplitude x carried load x damping (the printed 1 kg/s and 10 kg/s)
study = Study(
    system, t,
    u_for=inputs, x0_for=lambda values: rest(values["m"]),
    grid={"b": [1.0, 10.0],
          "m": np.linspace(0.02, 0.10, 3 if QUICK else 9),
          "V_kV": np.linspace(1.0, 5.0, 3 if QUICK else 9)},
    metrics={"stroke": final("displacement"), "peak": peak("displacement"),
             "rise_time": rise_time("displacement", start=T_STEP), "energy": "energy",
             "passivity_margin": "passivity_margin"},
)
print(study)
out = os.path.join(WORK, "msd_design.csv")
wall = time.perf_counter()
result = sweep(study, out, progress=False)
print(result.summary())
print(f"{len(result)} runs in {time.perf_counter() - wall:.1f} s, written to {out}")

# an interrupted or extended study resumes from its file: nothing is left to do here
again = sweep(study, out, resume=True, progress=False)
print(f"resumed: {again.new_runs} new runs, {len(again)} rows")

# %% Summary figure: every metric against every variable (failed runs as red crosses)
fig = result.plot(metrics=["stroke", "peak", "rise_time", "energy"], variables=["V_kV", "m", "b"])
save(fig, "sweep_msd_hasel_summary.png")

# %% Stroke map over voltage and load (b = 10 kg/s), and where the printed damping leaves the validity domain
V_axis, m_axis = study.grid["V_kV"], study.grid["m"]


def grid_of(column, b):
    sel = result["b"] == b
    Z = np.full((len(m_axis), len(V_axis)), np.nan)
    for v, m, z in zip(result["V_kV"][sel], result["m"][sel], result[column][sel]):
        Z[np.argmin(abs(m_axis - m)), np.argmin(abs(V_axis - v))] = z
    return Z


fig, ax = plt.subplots(1, 2, figsize=(11, 4))
cs = ax[0].contourf(V_axis, m_axis * 9.81, grid_of("stroke", 10.0) * 1e3, levels=15, cmap="viridis")
fig.colorbar(cs, ax=ax[0], label="stroke (final displacement) [mm]")
ax[0].set_title("b = 10 kg/s")
over = (grid_of("peak", 10.0) - grid_of("stroke", 10.0)) * 1e3
cs = ax[1].contourf(V_axis, m_axis * 9.81, over, levels=15, cmap="magma")
fig.colorbar(cs, ax=ax[1], label="overshoot (peak - stroke) [mm]")
failed_b1 = (result["b"] == 1.0) & ~result.ok
ax[1].scatter(result["V_kV"][failed_b1], result["m"][failed_b1] * 9.81, marker="x", color="c", s=40, clip_on=False,
              label="b = 1 kg/s leaves the validity domain")
ax[1].set_title("b = 10 kg/s (crosses: failures with b = 1 kg/s)")
ax[1].legend(loc="lower left", fontsize=8)
for a in ax:
    a.set_xlabel("voltage step [kV]")
    a.set_ylabel("load m g [N]")
fig.tight_layout()
save(fig, "sweep_msd_hasel_stroke.png")
for b in (1.0, 10.0):
    sel = result["b"] == b
    print(f"b = {b:g} kg/s: {int((~result.ok & sel).sum())} of {int(sel.sum())} runs leave the validity domain")

# %% Monte Carlo band: a 3 kV step with load and damping uncertain by 10 % (log-normal), Latin hypercube samples
times = np.linspace(T_STEP - 0.01, T_STEP + 0.12, 66 if QUICK else 131)  # the transient after the step
mc = Study(system, t, u={"V": step(3e3, T_STEP)}, x0_for=lambda values: rest(values["m"]),
           distributions={"m": LogNormal(0.05, 0.1), "b": LogNormal(10.0, 0.1)}, samples=16 if QUICK else 200,
           metrics=[values_at("displacement", times), final("displacement")])
band = sweep(mc, os.path.join(WORK, "msd_band.parquet"), progress=False)
cols = [f"displacement@{x:g}" for x in times]
Y = np.column_stack([band[c] for c in cols]) * 1e3
q05, q50, q95 = np.nanquantile(Y, [0.05, 0.5, 0.95], axis=0)
fig, ax = plt.subplots(figsize=(7, 4))
ax.fill_between(times, q05, q95, alpha=0.3, label="5-95 % of the runs")
ax.plot(times, q50, label="median")
for k in range(min(5, len(band))):
    ax.plot(times, Y[k], lw=0.6, color="gray")
ax.set_xlabel("t [s]")
ax.set_ylabel("displacement [mm]")
ax.set_title(f"3 kV step, m and b log-normal (10 %): {len(band)} runs")
ax.legend()
fig.tight_layout()
save(fig, "sweep_msd_hasel_band.png")
s = band["final_displacement"] * 1e3
print(f"Monte Carlo: stroke {np.median(s):.4f} mm, 90 % band [{np.quantile(s, 0.05):.4f}, {np.quantile(s, 0.95):.4f}] mm")
print(StudyResult.read(os.path.join(WORK, "msd_band.parquet")))

# %% The same design study from a terminal
print("phs sweep systems.msd_hasel:msd_hasel --range b=1,10 --range m=0.02:0.1:9 --range V_kV=1:5:9 "
      "--input 'V=step(1000*V_kV, 0.05)' --metric final:displacement --metric peak:displacement "
      "--metric energy --t-end 0.6 --dt 0.0005 --out msd_design.parquet --plot msd_design.png")
shutil.rmtree(WORK)
