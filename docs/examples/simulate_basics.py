# %% [markdown]
# Declaring, assembling, checking and simulating a model.
# Run: python docs/examples/simulate_basics.py [--quick]
# Writes the figures of docs/workflows/simulate.md into docs/figures/.

# %%
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codegen import simulate  # noqa: E402
from components import Capacitor, DriftBranch, Resistor, VoltageSource  # noqa: E402
from phs import Param, equilibrium, interconnect, parallel, series  # noqa: E402
from phs.signals import square  # noqa: E402

QUICK = "--quick" in sys.argv
OUT = os.environ.get("PHS_DOCS_OUT") or os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "figures")  # tests write elsewhere

# %% One segment's electrical network of the curling HASEL paper (with a fixed electrode capacitance):
# source -> R0 -> (C1 || R1) -> (C2 || R2)
R0 = Param("R0", 1e3, "Ohm", "connector resistance")
net = interconnect(
    "hasel_network",
    [
        VoltageSource("U"),
        Resistor("R0", R=R0),
        DriftBranch("D", C1=1.75e-5, R1=1e6, state="Q1"),
        Capacitor("C2", C=4e-10, state="Q2", range=(-4e-10 * 5e3, 4e-10 * 5e3)),
        Resistor("R2", R=1.47e6),
    ],
    [series("U", "R0", "D", parallel("C2", "R2"))],
    description="source, connector resistance, charge-retention branch, electrode capacitor with leakage",
)
print(net)
print(net.check())

# %% Simulate a 5 kV step followed by a 0.5 Hz bipolar square wave
t_end = 20.0 if QUICK else 60.0
t = np.linspace(0.0, t_end, 2001 if QUICK else 6001)
u = square(5000.0, 0.05 if QUICK else 0.025)
res = simulate(net, t, u={"U": u}, rtol=1e-9)
print("energy balance error:", res.energy_balance_error())

eq = equilibrium(net, u={"U": 5000.0})
print("DC equilibrium:", eq.as_dict())

# %%
fig, ax = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
ax[0].plot(res.t, res["U"] / 1e3)
ax[0].set_ylabel("U [kV]")
ax[1].plot(res.t, res["Q2"] / 4e-10 / 1e3, label="V across C2")
ax[1].plot(res.t, res["Q1"] / 1.75e-5 / 1e3, label="V across C1 (retained)")
ax[1].set_ylabel("voltage [kV]")
ax[1].legend()
E_in = res.quadratures["E_supplied"]
E_out = res.quadratures["E_dissipated"]
ax[2].plot(res.t, res.H, label="stored H(t)")
ax[2].plot(res.t, E_in - E_out, "--", label="supplied - dissipated")
ax[2].set_ylabel("energy [J]")
ax[2].set_xlabel("t [s]")
ax[2].legend()
fig.tight_layout()
os.makedirs(OUT, exist_ok=True)
fig.savefig(os.path.join(OUT, "simulate_network.png"), dpi=90)
print("wrote", os.path.join(OUT, "simulate_network.png"))
