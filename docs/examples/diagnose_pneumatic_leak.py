# %% [markdown]
# Diagnosis on real recordings: charged compressed-air chambers (3D-printed and aluminium, TU Delft,
# E. Zillen) modelled as closed, leak-free chambers.  Where a chamber leaks, the diagnosis should
# name the physics left out — a leak — and say whether a linear conductance (an exponential decay,
# the fluid analogue of an RC leak) explains it or a pressure-dependent one does better.
# Run: python docs/examples/diagnose_pneumatic_leak.py [--quick] [--out DIR] [--chambers A,B,...]
# Reads ../shared/data/pneumatic_actuator_tudelft/chamber_leak_*.csv relative to the repository root
# (skips with a message if absent); writes docs/figures/diagnose_leak_{fits,hypotheses,locate}.png.

# %%
import argparse
import os
import sys
import time

import numpy as np
import sympy as sp

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, ROOT)
DATA = os.path.join(ROOT, "..", "shared", "data", "pneumatic_actuator_tudelft")

ap = argparse.ArgumentParser(description="Diagnosis of leak-free models of compressed-air chambers")
ap.add_argument("--quick", action="store_true", help="the leaking chamber only, first 60 s")
ap.add_argument("--chambers", default="Ultimaker_015,Ultimaker_020,Prusa,Aluminium", help="comma-separated")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figures")
args = ap.parse_args()

if not os.path.isdir(DATA):
    print(f"pneumatic actuator data not found at {os.path.normpath(DATA)}: skipping this example.")
    sys.exit(0)

from components.candidates import LIBRARY, Augmentation, Candidate, add_damping, stored_quantity_states  # noqa: E402
from phs.workflows.diagnose import diagnose  # noqa: E402
from phs.workflows.diagnose.report import write_figures  # noqa: E402
from phs.workflows.recording import Recording  # noqa: E402
from systems.lab import air_chamber  # noqa: E402

P_ATM = 1.013e5  # Pa


# %% A candidate of our own: gas seeping through the porous walls of a print.  Laminar (Darcy) flow of
# an ideal gas through a porous wall carries a mass flow proportional to p_abs² − p_atm², i.e. a
# conductance that grows with the gauge pressure p: G(p) = G_p (1 + p / (2 p_atm)).  Passive: the
# dissipation R = G(p) ≥ 0 for every p > −2 p_atm.
class PorousLeak(Candidate):
    effect = "porous_leak"
    summary = "gas seeping through porous walls (a conductance growing with pressure, flow ∝ p_abs² − p_atm²)"

    def attach_points(self, system):
        return stored_quantity_states(system)

    def augment(self, system, where, scales):
        self._check_where(system, where)
        i = system.state_names.index(where)
        effort = sp.diff(system.H, system.states[i].symbol)  # the gauge pressure
        g_ref = scales.get("level", where) / scales.get("coenergy", where) / scales.duration  # drains it in one record
        G = self.param("G_p", g_ref, "m**3/(s*Pa)", f"porous conductance at {where} (at p = 0)", (1e-5 * g_ref, 1e3 * g_ref))
        s = add_damping(system, where, G.symbol * (1 + effort / (2 * P_ATM)), [G], self.effect)
        return Augmentation(self.effect, where, "conductance G_p (1 + p/(2 p_atm))", s, [G.name], {G.name: G.range}, [G.name])


def recording(name: str) -> Recording:
    """Pressure record of one chamber from the moment its supply valve closes (the last sample of the
    first 20 s within 10 mbar of the highest pressure: until then the supply holds the pressure), on
    a uniform 0.1 s grid (the files have a few late samples); the supply is closed throughout
    (input q = 0)."""
    raw = np.genfromtxt(os.path.join(DATA, f"chamber_leak_{name}.csv"), delimiter=",", names=True)
    t, p = raw["time_ms"] / 1000.0, raw["pressure_bar"] * 1e5
    early = t <= 20.0
    i0 = int(np.nonzero(early & (p >= p[early].max() - 1e3))[0][-1])
    t = t[i0:] - t[i0]
    keep = t <= (60.0 if args.quick else t[-1])
    return Recording.from_arrays(t[keep], {"q": 0 * t[keep], "pressure": p[i0:][keep]},
                                 source=f"chamber_leak_{name}.csv", units={"q": "m**3/s", "pressure": "Pa"}, resample=0.1)


# %% Diagnose every chamber: the nominal model is closed (no parameter to fit: the pressure scale and
# the capacitance are one unknown, so only the initial charge is estimated).  A discharge has no
# independent second half to validate on (its tail is flat: the NRMSE of a flat tail measures noise),
# so each record is fitted and scored whole; the information criterion (BIC) decides what is accepted
chambers = ["Ultimaker_015"] if args.quick else [c.strip() for c in args.chambers.split(",")]
results = {}
for name in chambers:
    rec = recording(name)
    wall = time.perf_counter()
    d = diagnose(air_chamber(), rec, validation=rec, free=[], estimate_x0=["V_a"], candidates=[*LIBRARY, PorousLeak()])
    sec = time.perf_counter() - wall
    results[name] = d
    ranked = [(h.augmentation.effect, round(h.fit_percent["pressure"], 1), round(h.bic - d.nominal.bic)) for h in d.hypotheses if h.ok][:3]
    print(f"{name:<15} effects {d.verdict['effects']}  fit {d.nominal.fit_percent['pressure']:5.1f} -> "
          f"{d.final.fit_percent['pressure']:5.1f} %  ({sec:.1f} s)  first round (effect, fit %, ΔBIC): {ranked}")
    print("   ", d.verdict["explanation"])

# %% Figures of the strongly leaking chamber
d = results.get("Ultimaker_015") or next(iter(results.values()))
for path in write_figures(d, args.out, "diagnose_leak"):
    print(f"wrote {path}")
