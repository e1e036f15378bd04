# %% [markdown]
# IDA-PBC of the curling HASEL (4 segments): hold the tip at 30 mm.  Design, certificates, closed loop from
# rest, plant/controller mismatch with the drift branch active (plain law, passive integral action, integral of
# the tip error), the electrostatic actuator beyond pull-in (voltage versus charge shaping), and the C export.
# Run: python docs/examples/idapbc_curling_hasel.py [--quick] [--out DIR]
# Writes docs/figures/idapbc_curling_hasel.png and idapbc_curling_hasel_mismatch.png (or into --out DIR /
# $PHS_DOCS_OUT) and prints the numbers quoted in docs/workflows/idapbc.md.

# %%
import argparse
import os
import shutil
import subprocess
import tempfile
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codegen.idapbc import design  # noqa: E402
from systems.curling_hasel import curling_hasel  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ap = argparse.ArgumentParser(description="IDA-PBC of the curling HASEL")
ap.add_argument("--quick", action="store_true", help="fewer rays and runs, shorter mismatch runs (test size)")
ap.add_argument("--out", default=os.environ.get("PHS_DOCS_OUT") or os.path.join(HERE, "..", "figures"),
                help="directory of the figures")
args = ap.parse_args()
os.makedirs(args.out, exist_ok=True)

N, TIP = 4, 0.03
REST = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}  # theta = 0, l_p = L_v: the leaf of the conserved quantities
hasel = curling_hasel(N, network="printed")  # Table 4 as printed: the numbers of docs/workflows/idapbc.md

# %% Design on the model with the charge-retention capacitor shorted (its charge is a disturbance for the design)
wall = time.perf_counter()
ctrl = design(hasel, {"tip": TIP}, x0=REST, neglect=["seg*.Q1"])
print(ctrl.summary())
print(f"design: {time.perf_counter() - wall:.2f} s")

# %% Certificates
wall = time.perf_counter()
rep = ctrl.certify(rays=12 if args.quick else 48, simulations=3 if args.quick else 8)
print(rep)
print(f"certify: {time.perf_counter() - wall:.2f} s")
ev = np.array(rep["linearization"].numbers["eigenvalues"])
print("closed-loop modes on the leaf (1/s):", ", ".join(f"{v:.4g}" for v in sorted(ev, key=lambda v: -v.real)[:6]))
print("scaled Hessian eigenvalues (J):", ", ".join(f"{v:.3g}" for v in rep["hessian"].numbers["eigenvalues"]))

# %% Closed loop from rest on the design model
t = np.linspace(0.0, 0.4, 4001)
res = ctrl.simulate(t)
print(f"from rest: within 1 % of {1e3 * TIP:g} mm after {1e3 * res.settling_time(0.01):.1f} ms; "
      f"tip at 2 s error {abs(ctrl.simulate(np.linspace(0, 2, 201)).error()[-1]):.2e}; "
      f"largest increase of H_d {res.max_increase('H_d'):.2e} J from H_d(0) - H_d* = {res.H_d[0]:.4g} J")
drift_2s = ctrl.simulate(np.linspace(0, 2, 2001), plant=hasel)
print(f"same law on the model with the drift branch: tip error at 2 s {100 * drift_2s.error()[-1]:+.2f} %")

fig, axes = plt.subplots(3, 1, figsize=(7.5, 7.5), sharex=True, constrained_layout=True)
axes[0].plot(1e3 * t, 1e3 * res["tip"], label="tip")
axes[0].axhspan(1e3 * TIP * 0.99, 1e3 * TIP * 1.01, color="0.85", label="±1 %")
axes[0].set_ylabel("tip [mm]")
for i in range(1, N + 1):
    axes[1].plot(1e3 * t, res[f"seg{i}.theta"], label=f"seg{i}.theta")
axes[1].set_ylabel("angle [rad]")
axes[2].semilogy(1e3 * t, np.maximum(res.H_d, 1e-16), label="H_d - H_d(x*)")
axes[2].set_ylabel("H_d - H_d(x*) [J]")
axes[2].set_xlabel("t [ms]")
for ax in axes:
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
fig.suptitle(f"curling HASEL, IDA-PBC: tip to {1e3 * TIP:g} mm from rest (U* = {ctrl.u_star[0]:.1f} V)")
fig.savefig(os.path.join(args.out, "idapbc_curling_hasel.png"), dpi=110)
plt.close(fig)

# %% Plant/controller mismatch: K_b 10 % stiffer and the drift branch active
T = 40.0 if args.quick else 150.0
tm = np.linspace(0.0, T, int(10 * T) + 1)
variants = {"IDA-PBC": ctrl, "+ passive integral": ctrl.with_integral("passive"),
            "+ integral of the tip error": ctrl.with_integral("output")}
runs = {}
for name, c in variants.items():
    runs[name] = c.simulate(tm, plant=hasel, params={"K_b": 0.044})
    r = runs[name]
    print(f"mismatch, {name:<28}: tip error at {T:g} s {100 * r.error()[-1]:+.4f} %, U from {r['U'].min():.0f} to "
          f"{r['U'].max():.0f} V" + (f", K_i = {c.K_i[0, 0]:.4g}" if c.integral else ""))

fig, axes = plt.subplots(2, 1, figsize=(7.5, 6), sharex=True, constrained_layout=True)
for name, r in runs.items():
    axes[0].plot(tm, 100 * r.error(), label=name)
    axes[1].plot(tm, 1e-3 * r["U"], label=name)
axes[0].set_ylabel("tip error [%]")
axes[0].set_ylim(-55, 10)
axes[1].set_ylabel("U [kV]")
axes[1].set_xlabel("t [s]")
for ax in axes:
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
fig.suptitle("plant: K_b + 10 %, charge-retention branch active; controller: nominal, drift shorted")
fig.savefig(os.path.join(args.out, "idapbc_curling_hasel_mismatch.png"), dpi=110)
plt.close(fig)

# %% The electrostatic actuator beyond pull-in: holding the voltage versus shaping the charge
ea = electrostatic_actuator()
for label, kw in (("voltage (lambda only)", {}), ("charge shaping K_Q = 1e12 J/C^2", {"stiffness": {"Q": 1e12}})):
    c = design(ea, {"position": 5e-5}, **kw)
    r = c.certify(rays=8, simulations=2)
    print(f"electrostatic actuator at x* = g0/2 = 50 um, beyond pull-in at g0/3 ({label}): Hessian {r['hessian'].verdict} "
          f"(smallest scaled eigenvalue {min(r['hessian'].numbers['eigenvalues']):.3g} J), linearisation "
          f"{r['linearization'].verdict} (max real part {r['linearization'].numbers['max_real']:.4g} 1/s)")

# %% C export: a standalone .c/.h pair, compiled when gcc is available
with tempfile.TemporaryDirectory() as tmp:
    c_file, h_file = ctrl.with_integral("passive").export_c(tmp)
    print(f"C export: {os.path.basename(c_file)} ({os.path.getsize(c_file)} bytes), {os.path.basename(h_file)}")
    gcc = shutil.which("gcc")
    if gcc:
        proc = subprocess.run([gcc, "-std=c99", "-O2", "-c", c_file, "-o", os.path.join(tmp, "law.o")],
                              capture_output=True, text=True)
        print("gcc -std=c99 -O2 -c:", "ok" if proc.returncode == 0 else proc.stderr[-500:])
