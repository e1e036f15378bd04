# %% [markdown]
# Passivity certificates: the curling HASEL (passive over its physical ranges; energy accounts per element;
# local indices at rest and under a DC bias), a fitted damper law that stops being passive beyond the range
# it was fitted on, and the passivity margin in a 1000-variant design sweep.
# Run: python docs/examples/passivity_curling_hasel.py [--quick]
# Writes docs/figures/passivity_*.png (or into $PHS_DOCS_OUT) and prints the numbers of docs/workflows/passivity.md.

# %%
import os
import sys
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402

from codegen.passivity import certify, dissipation_inequality, dissipation_margin, local_passivity  # noqa: E402
from phs import InputInfo, Param, PHSystem, StateInfo  # noqa: E402
from phs.signals import square  # noqa: E402
from systems.curling_hasel import curling_hasel  # noqa: E402

QUICK = "--quick" in sys.argv
HERE = os.path.dirname(os.path.abspath(__file__))
FIG = os.environ.get("PHS_DOCS_OUT") or os.path.join(HERE, "..", "figures")  # tests write elsewhere
os.makedirs(FIG, exist_ok=True)
SIZE = {"samples": 400, "starts": 3} if QUICK else {"samples": 2000, "starts": 8}

# %% 1. The 4-segment curling HASEL over its declared ranges, with a 5 kV / 2 Hz square-wave run and the
# local test at rest
N = 4
hasel = curling_hasel(N, network="printed")  # Table 4 as printed: the numbers of docs/workflows/passivity.md
X0 = {f"seg{i}.l_p": 0.015 for i in range(1, N + 1)}
T = 0.5 if QUICK else 4.0
t = np.linspace(0.0, T, int(T * 1000) + 1)
wall = time.perf_counter()
rep = certify(hasel, trajectory={"t": t, "u": {"U": square(5000.0, 2.0)}, "x0": X0}, u={"U": 0.0}, x0=X0, **SIZE)
print(rep)
print(f"certify: {time.perf_counter() - wall:.1f} s wall")
traj = rep["trajectory"].numbers
print(f"supplied {traj['supplied']:.4f} J = stored {traj['stored']:.4g} J + dissipated {traj['dissipated']:.4f} J; "
      f"split error {traj['split_relative_error']:.1e}, balance error {traj['balance_error']:.1e}")
kinds = {"leakage R2": ".R2", "retention R1": ".D.R1", "connector R0": ".R0", "damping b": ".b"}
by_kind = {k: sum(v for label, v in traj["dissipated_by"].items() if label.endswith(suffix)) for k, suffix in kinds.items()}
print("dissipated per kind of element: " + ", ".join(f"{k} {v:.4g} J" for k, v in by_kind.items()))

# %% local indices at rest and at a 3 kV bias (incremental supply δu δy)
loc0 = rep["local"].numbers
print(f"at rest: nu = {loc0['input_index']:.4g} A/V, rho = {loc0['output_index']:.4g} V/A "
      f"({loc0['conserved_directions_removed']} conserved directions removed, {loc0['states_after_reduction']} states left; "
      f"eigenvalue spread {loc0['eigenvalue_spread']:.2g})")
for U in (3000.0, 5000.0):
    loc = local_passivity(hasel, u_eq={"U": U}, x0=X0)
    print(f"at {U / 1000:g} kV: {loc.verdict}: nu = {loc.input_index:.4g} A/V at {loc.details['nu_frequency']:.3g} rad/s, "
          f"rho = {loc.output_index:.4g} V/A; Hessian storage certifies: {loc.details['storage_kyp']['certifies']}"
          + (f"; python-control LMI (cvxopt): nu = {loc.details['lmi']['input_index']:.4g} A/V" if "lmi" in loc.details else ""))

# %% figure: energy accounts of the run
res_t = rep["trajectory"].series
fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
ax[0].plot(res_t["t"], res_t["supplied"], label="supplied ∫ U·i dt")
ax[0].plot(res_t["t"], res_t["dissipated"], label="dissipated")
ax[0].plot(res_t["t"], res_t["stored"], label="stored H(t) − H(0)")
ax[0].set_xlabel("t [s]")
ax[0].set_ylabel("energy [J]")
ax[0].legend(fontsize=8)
ax[0].set_title("dissipation inequality: supplied − stored ≥ 0")
for kind, suffix in kinds.items():
    curve = sum(v for label, v in res_t["parts"].items() if label.endswith(suffix))
    ax[1].plot(res_t["t"], np.maximum(curve, 1e-12), label=kind)
ax[1].set_yscale("log")
ax[1].set_xlabel("t [s]")
ax[1].set_ylabel("dissipated energy [J]")
ax[1].set_title("per kind of element (4 segments each)")
ax[1].legend(fontsize=8)
labels = list(traj["dissipated_by"])
colors = {suffix: f"C{i}" for i, suffix in enumerate(kinds.values())}
ax[2].bar(range(len(labels)), [traj["dissipated_by"][k] for k in labels],
          color=[next(c for s, c in colors.items() if k.endswith(s)) for k in labels])
ax[2].set_xticks(range(len(labels)), labels, rotation=90, fontsize=7)
ax[2].set_yscale("log")
ax[2].set_ylabel("dissipated energy at T [J]")
ax[2].set_title("per element")
fig.tight_layout()
fig.savefig(os.path.join(FIG, "passivity_curling_energy.png"), dpi=90)


# %% 2. A non-passive model: a damper law fitted on |v| <= 0.5 m/s, b(v) = b0 (1 - (v / v_c)^2)
def fitted_damper():
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    m, k = Param("m", 0.1, "kg", "mass"), Param("k", 40.0, "N/m", "stiffness")
    b0, v_c = Param("b0", 0.05, "N*s/m", "damping at rest"), Param("v_c", 0.8, "m/s", "velocity of zero damping")
    b = b0.symbol * (1 - (p / m.symbol / v_c.symbol) ** 2)
    return PHSystem("fitted_damper", [StateInfo("q", "m", (-0.05, 0.05)), StateInfo("p", "kg*m/s", (-0.05, 0.05), kind="I")],
                    H=k.symbol * q**2 / 2 + p**2 / (2 * m.symbol), J=[[0, 1], [-1, 0]], R=[[0, 0], [0, b]], G=[[0], [1]],
                    inputs=[InputInfo("F", "N", output="F.v", output_unit="m/s")], params=[m, k, b0, v_c],
                    dissipators=[("damper", {(1, 1): b})])


damper = fitted_damper()
inside = certify(damper, samples=400, starts=3)
outside = certify(damper, box={"p": (-0.12, 0.12)}, samples=400, starts=3)
print(f"\nfitted damper over its fitted range: passive = {inside.passive}, margin {inside.margin:.3f}")
print(outside)
d = outside["dissipation"]
print(f"worst point v = {d.worst['p'] / 0.1:+.3f} m/s, element {d.element}, unscaled eigenvalue "
      f"{d.numbers['min_eigenvalue_unscaled']:.4g} N*s/m (b0 (1 - 1.5^2) = {0.05 * (1 - 1.5**2):.4g})")
tt = np.linspace(0.0, 1.0, 1001)
runs = {v0: dissipation_inequality(damper, tt, x0={"p": 0.1 * v0}) for v0 in (0.9, 1.0)}
for v0, test in runs.items():
    n_ = test.numbers
    print(f"released at {v0} m/s: {test.verdict} (element {test.element}): supplied - stored reaches "
          f"{n_['min_slack']:+.3g} J at t = {n_['min_slack_time']:.3g} s; after 1 s stored {n_['stored']:+.3g} J, "
          f"damper {n_['dissipated_by']['damper']:+.3g} J")

fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
s = d.series
v = s["V"][:, 1] / 0.1
order = np.argsort(v)
ax[0].plot(v[order], s["lambda"][order], ".", ms=3, label="sampled states")
ax[0].axvspan(-1.2, -0.8, color="tab:red", alpha=0.12, label="b(v) < 0")
ax[0].axvspan(0.8, 1.2, color="tab:red", alpha=0.12)
ax[0].axvspan(-0.5, 0.5, color="tab:green", alpha=0.08, label="fitted (declared) range")
ax[0].plot([d.worst["p"] / 0.1], [d.numbers["full_form_min_eigenvalue"]], "kx", ms=10, mew=2, label="worst point (nlpsol)")
ax[0].axhline(0.0, color="k", lw=0.6)
ax[0].set_xlabel("velocity v = p / m [m/s]")
ax[0].set_ylabel("smallest scaled eigenvalue of R")
ax[0].legend(fontsize=8)
for v0, test in runs.items():
    sr = test.series
    ax[1].plot(sr["t"], sr["stored"], label=f"stored, released at {v0} m/s")
    ax[1].plot(sr["t"], sr["parts"]["damper"], "--", label=f"dissipated by the damper ({v0} m/s)")
ax[1].axhline(0.0, color="k", lw=0.6)
ax[1].set_xlabel("t [s]")
ax[1].set_ylabel("energy [J] (nothing supplied)")
ax[1].legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(FIG, "passivity_nonpassive.png"), dpi=90)

# %% 3. The margin in a design sweep: 1000 variants of the curling HASEL's resistances
n = 6 if QUICK else 32
R0s, R2s = np.geomspace(1e2, 1e5, n), np.geomspace(1e5, 1e7, n)
dissipation_margin(hasel)  # the first call generates the function and draws the sample
wall = time.perf_counter()
M = np.array([[dissipation_margin(hasel, params={"R0": a, "R2": b}) for a in R0s] for b in R2s])
per_call = (time.perf_counter() - wall) / M.size
print(f"\nmargin sweep: {M.size} variants, {per_call * 1e3:.2f} ms per call; margin from {M.min():.3g} to {M.max():.3g}")
fig, ax = plt.subplots(figsize=(5.5, 4))
cs = ax.contourf(R0s, R2s, np.log10(M), levels=20)
ax.plot([hasel.param("R0").value], [hasel.param("R2").value], "wx", ms=9, mew=2, label="default")
ax.set_xscale("log")
ax.set_yscale("log")
ax.set_xlabel("R0 [Ohm]")
ax.set_ylabel("R2 [Ohm]")
ax.legend(fontsize=8)
fig.colorbar(cs, label="log10 margin")
ax.set_title("passivity margin of the curling HASEL")
fig.tight_layout()
fig.savefig(os.path.join(FIG, "passivity_margin_sweep.png"), dpi=90)
print("wrote", ", ".join(os.path.join(os.path.normpath(FIG), f) for f in
                         ("passivity_curling_energy.png", "passivity_nonpassive.png", "passivity_margin_sweep.png")))
