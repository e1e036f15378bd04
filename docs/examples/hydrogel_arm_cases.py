# %% [markdown]
# The hydrogel arm against Table II of Doroudchi et al.: the eight open-loop cases (15 s pulses, 40 s runs)
# simulated and compared with the measured tip ranges; the readings of eq. 7 and Table I checked against
# what the paper says of the force; the lever arms of the two rows fitted to the table with 95 % intervals
# through phs.identify (each case a run known by one statistic, its tip range), checked against the same fit
# by scipy's least squares over the simulated ranges; the water drag of eq. 5 and the buoyant weight
# measured for what they change.
# Run: python docs/examples/hydrogel_arm_cases.py [--quick] [--out DIR]
# (--quick: 8 rod elements, 64 states; default: 16 rod elements, the 128-state arm, and both compared)

# %%
import argparse
import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codegen import simulator  # noqa: E402
from phs.signals import Piecewise  # noqa: E402
from systems.hydrogel_arm import LEVER, hydrogel_arm  # noqa: E402
from systems.hydrogel_cases import (  # noqa: E402
    AS_FIXED,
    MEASURED,
    TABLE_II,
    case_ranges,
    eq7_readings,
    fit_levers,
    fit_levers_least_squares,
    table_arm,
)

HERE = os.path.dirname(os.path.abspath(__file__))
ap = argparse.ArgumentParser(description="The hydrogel arm against Table II of Doroudchi et al.")
ap.add_argument("--quick", action="store_true", help="8 rod elements (64 states) instead of 16 (128 states)")
ap.add_argument("--out", default=os.path.join(HERE, "..", "figures"), help="directory of the figure")
args = ap.parse_args()
os.makedirs(args.out, exist_ok=True)
M = 1 if args.quick else 2
V_T = 1.08  # V, the voltage of Fig. 4, the one step response the paper shows against its measurement
wall = time.perf_counter()


def trends(x):
    """Voltage ratios (3.6 V / 1.8 V, upper and lower row) and row ratios (lower / upper, 1.8 V and 3.6 V)."""
    return x[1] / x[0], x[3] / x[2], x[2] / x[0], x[3] / x[1]


def both_routes(label, V_t, sim, start):
    """The lever arms fitted through phs.identify and by least squares over case_ranges, timed and compared."""
    t0 = time.perf_counter()
    arm = table_arm(M, V_t=V_t)
    t1 = time.perf_counter()
    fit = fit_levers(arm, start=start)
    t2 = time.perf_counter()
    lsq = fit_levers_least_squares(sim, start=start)
    t3 = time.perf_counter()
    print(f"  {label} fit: {fit}   (phs.identify, {fit.identification.iterations} evaluations, {t2 - t1:.1f} s; "
          f"arm built in {t1 - t0:.1f} s)")
    print(f"  least squares over case_ranges: {lsq}   ({t3 - t2:.1f} s)")
    print(f"  identify and least squares: lever arms differ by at most "
          f"{np.max(np.abs(np.array(fit.levers) / lsq.levers - 1)):.2e}, standard errors by at most "
          f"{np.max(np.abs(np.array(fit.stderr) / lsq.stderr - 1)):.2e}, interval ends by at most "
          f"{np.max(np.abs(np.ravel(fit.interval) - np.ravel(lsq.interval))) / min(lsq.stderr):.2e} standard errors")
    return fit


def show(label, x):
    err = x / MEASURED - 1
    print(f"{label:<34}" + "".join(f"{v:7.2f}" for v in x) + f"   NRMSE {100 * np.sqrt(np.mean(err**2)):5.1f} %   "
          "V-ratios {:.2f} {:.2f}  row-ratios {:.2f} {:.2f}".format(*trends(x)))


# %% 1. The readings of eq. 7 and Table I
readings = eq7_readings()
force_ok = [r for r in readings if r.force_ok]
table_ok = [r for r in readings if r.table_ok and r.starts_at_zero and r.grows_with_V]
both = [r for r in force_ok if r.table_ok]
print(f"readings of eq. 7 and Table I: {len(readings)}; starting at 0 and tensile: "
      f"{sum(r.starts_at_zero for r in readings)}; also growing with V and Fig. 4's range in [0.052, 0.98] N: "
      f"{len(force_ok)}; rising from 0, growing with V and Table II's voltage ratio in [1.8, 2.5]: {len(table_ok)}; "
      f"all of them: {len(both)}")
for r in force_ok:
    print(f"  force statements hold: {r.describe()}: 15 s force ratio 3.6/1.8 V {r.ratio:.2f}")
for r in table_ok:
    print(f"  voltage ratio holds:   {r.describe()}: 15 s force ratio {r.ratio:.2f}, range at 1.08 V "
          f"{r.fig4_range:.4g} N")
fixed = next(r for r in readings if r.describe() == AS_FIXED)
print(f"the element's reading ({AS_FIXED}): 15 s force ratio 3.6/1.8 V {fixed.ratio:.3f}")

# %% 2. Table I as read, the paper's lever arm: the eight cases
t0 = time.perf_counter()
sim_i = simulator(hydrogel_arm(per_segment=M), rtol=1e-7)
print(f"arm with all 16 SVAs, {8 * M} rod elements: built in {time.perf_counter() - t0:.0f} s")
print(f"{'case':<34}" + "".join(f"{c:7d}" for c, *_ in TABLE_II))
show("Table II, measured |X| [mm]", MEASURED)
x_i = case_ranges(sim_i, (LEVER, LEVER))
show(f"Table I, r = {1e3 * LEVER} mm", x_i)
fit_i = both_routes("Table I", None, sim_i, (LEVER, LEVER))
show("Table I, levers fitted", fit_i.ranges)

# %% 3. eq. 8's time coefficients at 1.08 V for every amplitude: the lever arms fitted
t0 = time.perf_counter()
sim_t = simulator(hydrogel_arm(per_segment=M, V_t=V_T), rtol=1e-7)
fit_t = both_routes(f"V_t = {V_T} V", V_T, sim_t, (4e-5, 6e-5))
show(f"b1, b2 at {V_T} V, levers fitted", fit_t.ranges)
print("  relative errors per case [%]: " + " ".join(f"{100 * e:+.1f}" for e in fit_t.relative_errors))

# %% 4. The water drag of eq. 5 (C = 0.0262 kg/m**2, on by default): the cases without it
sim_0 = simulator(hydrogel_arm(per_segment=M, V_t=V_T, drag=0.0), rtol=1e-7)
x_0 = case_ranges(sim_0, fit_t.levers)
print(f"water drag: largest change of a case's range {np.max(np.abs(fit_t.ranges - x_0)):.2e} mm")

# %% 5. The buoyant weight of eq. 5, scaled to the measured 0.29 mm sag: does it tell the rows apart?
arm_g = hydrogel_arm(per_segment=M, V_t=V_T, gravity=True)
sim_g = simulator(arm_g, rtol=1e-9)
rho = arm_g.param("rod.rho").value
t = np.linspace(0.0, 70.0, 701)
settle = sim_g.run(t[:301], params={"rod.rho_w": rho - 1.0})["tip"]  # 1 kg/m**3 of excess density
delta = 0.29 / abs(settle[-1])  # linear in the load: the excess density that sags the tip 0.29 mm
common = float(np.sqrt(fit_t.levers[0] * fit_t.levers[1]))
ranges_g = []
for case in (0, 2):  # cases 1 and 3: the upper and the lower row at 1.8 V
    _, svas, V, _, _ = TABLE_II[case]
    p = {"rod.rho_w": rho - delta, **{f"sva{i}.V_a": V for i in range(1, 17)},
         **{f"sva{i}.r": common if i <= 8 else -common for i in range(1, 17)}}
    u = {f"V{i}": Piecewise([0.0, 30.0, 45.0], [0.0, V, 0.0]) if i in svas else 0.0 for i in range(1, 17)}
    tip = sim_g.run(t, u=u, params=p)["tip"]
    ranges_g.append(float(np.ptp(tip[t >= 30.0])))
    sag = tip[300]
print(f"buoyant weight (excess density {delta:.3f} kg/m**3, sag {sag:.3f} mm), both rows r = {1e3 * common:.4f} mm: "
      f"case 1 {ranges_g[0]:.4f} mm, case 3 {ranges_g[1]:.4f} mm, lower/upper {ranges_g[1] / ranges_g[0]:.5f} "
      f"(Table II: {MEASURED[2] / MEASURED[0]:.2f})")

# %% 6. Reduced against full discretisation (default run only)
if not args.quick:
    sim_r = simulator(hydrogel_arm(per_segment=1, V_t=V_T), rtol=1e-7)
    x_r = case_ranges(sim_r, fit_t.levers)
    print(f"8 against 16 rod elements at the fitted levers: largest relative difference "
          f"{np.max(np.abs(x_r / fit_t.ranges - 1)):.2e}")

# %% Figure
fig, ax = plt.subplots(figsize=(9, 4))
k = np.arange(1, 9)
ax.bar(k - 0.27, MEASURED, 0.27, label="Table II (measured)", color="0.3")
ax.bar(k, x_i, 0.27, label=f"Table I as read, r = {1e3 * LEVER} mm")
ax.bar(k + 0.27, fit_t.ranges, 0.27, label=f"b1, b2 at {V_T} V, levers fitted")
ax.set_xticks(k, [f"{c}\n{V} V" for c, _, V, _, _ in TABLE_II])
ax.set_ylabel("tip range |X| [mm]")
ax.set_title("hydrogel arm: Table II cases (15 s pulses)")
ax.legend()
fig.tight_layout()
path = os.path.join(args.out, "hydrogel_arm_cases.png")
fig.savefig(path, dpi=90)
plt.close(fig)
print(f"wrote {path}; {time.perf_counter() - wall:.0f} s wall")
