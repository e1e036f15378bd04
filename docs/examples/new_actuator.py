# %% [markdown]
# Tutorial: a new actuator from components, end to end (docs/tutorials/new_actuator.md).
# Run: python docs/examples/new_actuator.py [--quick]

# %%
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codegen import simulate  # noqa: E402
from phs import equilibrium  # noqa: E402
from phs.errors import DomainError, EquilibriumError  # noqa: E402
from phs.signals import step  # noqa: E402
from systems.electrostatic_actuator import electrostatic_actuator  # noqa: E402

QUICK = "--quick" in sys.argv
FIG = os.environ.get("PHS_DOCS_OUT") or os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "figures")  # tests write elsewhere
os.makedirs(FIG, exist_ok=True)

act = electrostatic_actuator()
print(act)
print(act.check())
pv = act.param_values()
k, g0, eps, A = pv["k"], pv["g0"], pv["eps"], pv["A"]
V_pi = np.sqrt(8 * k * g0**3 / (27 * eps * A))
print(f"pull-in voltage {V_pi:.3f} V at x = g0/3 = {g0 / 3:.3e} m")

# %% static curve: phs.equilibrium versus the force balance k x = eps A V^2 / (2 (g0 - x)^2)
volts = np.linspace(0, 0.98 * V_pi, 8 if QUICK else 25)
xs, x_ref = [], []
for V in volts:
    xs.append(equilibrium(act, u={"U": float(V)})["x"])
    # the stable root of the cubic 2 k x (g0 - x)^2 = eps A V^2 lies in [0, g0/3]
    roots = np.roots([2 * k, -4 * k * g0, 2 * k * g0**2, -eps * A * V**2])
    real = sorted(r.real for r in roots if abs(r.imag) < 1e-12 * g0 and -1e-12 <= r.real <= g0 / 3 + 1e-12)
    x_ref.append(real[0])
err = np.max(np.abs(np.array(xs) - np.array(x_ref))) / g0
print(f"equilibrium versus the analytic force balance: max error {err:.2e} g0")
try:
    equilibrium(act, u={"U": 1.05 * V_pi})
except EquilibriumError as exc:
    print("above pull-in:", str(exc)[:100], "...")

# %% step responses below and above pull-in
t = np.linspace(0, 0.1 if QUICK else 0.3, 3001)
fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
ax[0].plot(volts, np.array(xs) / g0, "o", label="phs.equilibrium")
ax[0].plot(volts, np.array(x_ref) / g0, "-", label="k x = eps A V² / 2(g0 - x)²")
ax[0].set_xlabel("U [V]")
ax[0].set_ylabel("x / g0")
ax[0].legend(fontsize=8)
for frac in (0.5, 0.9):
    res = simulate(act, t, u={"U": step(frac * V_pi, at=0.005)})
    ax[1].plot(res.t * 1e3, res["position"] / g0, label=f"{frac:.1f} V_pi")
    print(f"step to {frac:.1f} V_pi: energy balance error {res.energy_balance_error():.1e}")
try:
    simulate(act, t, u={"U": step(1.2 * V_pi, at=0.005)})
except DomainError as exc:
    print("1.2 V_pi:", str(exc).split("; state")[0])
ax[1].axhline(1 / 3, color="k", ls=":", label="pull-in x = g0/3")
ax[1].set_xlabel("t [ms]")
ax[1].set_ylabel("x / g0")
ax[1].legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(FIG, "new_actuator.png"), dpi=90)
