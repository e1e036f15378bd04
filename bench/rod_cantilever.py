"""The undamped cantilever compared with pyelastica: the problem, a runner for each code, and the stored reference.

    python bench/rod_cantilever.py      # writes tests/data/rod_cantilever_pyelastica.npz (about 1 min)

The problem (the same in both codes): a rod of length 1 m, circular cross-section of radius 0.02 m, density
1000 kg/m**3, E = 50 MPa, G = E/3 (Poisson ratio 0.5), shear factor 27/28 (pyelastica's fixed Timoshenko factor
``alpha_c``: its shear stiffness is ``alpha_c G A``, ours ``k_s G A``), clamped at the base along +x, straight and at
rest at t = 0, undamped, moving in the x-y plane.  Two cases, switched on at t = 0:

* ``tip``: a dead tip force ``F_y = -EI/L**2`` (perpendicular to the undeformed rod, fixed direction);
* ``gravity``: gravity ``g = 9.81 m/s**2`` along -y (weight ``rho A g`` per unit length).

Simulated for 1.5 periods of the linear first mode, ``T = 3 pi/omega_1`` (1.2 s), tip sampled at 301 times.

Conventions matched.  pyelastica: ``CosseratRod.straight_rod`` with ``n`` elements, ``youngs_modulus=E``,
``shear_modulus=G``; nodal masses lumped (half an element at each end, like ours); clamp by ``OneEndFixedBC``
(node 0 and the director of element 1 fixed); tip force by ``EndpointForces`` with a vanishing ramp (a step);
gravity by ``GravityForces``; ``PositionVerlet`` with a step ``frac * 2/omega_max``, ``omega_max**2 =
alpha_c G A/(rho I) + 4 E/(rho h**2)`` (the shear-rotation and axial-bending limits of its explicit scheme: with
``dt = T/(300*20)`` it diverges).  Ours: :class:`components.CosseratRod` with ``k_s = alpha_c``, CVODES.
What differs by construction and vanishes with n: pyelastica's rotary inertia lives on elements, ours on nodes;
its clamp fixes the first element's director, ours the cross-section at the clamp (so its tip converges at
first order in n, ours at second); its constitutive law divides stresses by the dilatation (differences of the
order of the axial strain, 1e-4 here).

Reference of each code: Richardson extrapolation of two runs ``n`` and ``2n`` with the observed order (1 for
pyelastica, 2 for ours); the stored file holds pyelastica's runs at n = 160 and 320 (``frac = 0.45``) and their
extrapolation.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

from codegen import simulator  # noqa: E402
from components import CosseratRod, ForceSource, TorqueSource  # noqa: E402
from phs import interconnect, series  # noqa: E402

L, RADIUS, RHO, E = 1.0, 0.02, 1000.0, 50e6
G, ALPHA_C = E / 3, 27 / 28
A, I = math.pi * RADIUS**2, math.pi * RADIUS**4 / 4  # noqa: E741
EI = E * I
FY, GRAVITY = -EI / L**2, 9.81
OMEGA1 = 1.875104069**2 * math.sqrt(EI / (RHO * A * L**4))
T_END = 1.5 * 2 * math.pi / OMEGA1
N_OUT = 300
TIMES = np.linspace(0.0, T_END, N_OUT + 1)
CASES = ("tip", "gravity")
REFERENCE = os.path.join(ROOT, "tests", "data", "rod_cantilever_pyelastica.npz")


def deviation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between two tip trajectories ``(k, 2)``, in units of the largest tip deflection of ``b``."""
    deflection = np.max(np.hypot(b[:, 0] - L, b[:, 1]))
    return float(np.max(np.hypot(*(a - b).T)) / deflection)


def richardson(coarse: np.ndarray, fine: np.ndarray, order: int) -> np.ndarray:
    """Extrapolation of runs at ``n`` and ``2n`` whose error falls as ``n**-order``."""
    return (2**order * fine - coarse) / (2**order - 1)


# -- ours ----------------------------------------------------------------------------------------------------------------
def ours_system(n: int, case: str):
    """The cantilever as a port-Hamiltonian system (tip-load ports driven by sources, or gravity)."""
    if case == "tip":
        rod = CosseratRod("rod", n=n, L=L, E=E, G=G, k_s=ALPHA_C, I=I, A=A, rho=RHO, tip="force")
        return interconnect("cantilever", [rod, ForceSource("Fx"), ForceSource("Fy"), TorqueSource("M")],
                            [series("Fx", "rod.tip_x"), series("Fy", "rod.tip_y"), series("M", "rod.tip_m")])
    rod = CosseratRod("rod", n=n, L=L, E=E, G=G, k_s=ALPHA_C, I=I, A=A, rho=RHO, gravity=True, g=GRAVITY)
    return interconnect("cantilever", [rod])


def ours_run(sim, n: int, case: str) -> tuple[float, np.ndarray]:
    """Wall time of one run of a built simulator and the tip trajectory ``(301, 2)``."""
    t0 = time.perf_counter()
    res = sim.run(TIMES, u={"Fx": 0.0, "Fy": FY, "M": 0.0} if case == "tip" else None)
    seconds = time.perf_counter() - t0
    return seconds, np.c_[L + res[f"rod.ux{n}"], res[f"rod.uy{n}"]]


def ours(n: int, case: str, rtol: float = 1e-9, compile: bool = False) -> np.ndarray:
    """Tip trajectory of ours at ``n`` elements and tolerance ``rtol``."""
    return ours_run(simulator(ours_system(n, case), rtol=rtol, energy=False, compile=compile), n, case)[1]


# -- pyelastica ------------------------------------------------------------------------------------------------------------
def elastica_steps(n: int, frac: float) -> int:
    """Steps per output interval for a time step ``frac`` times PositionVerlet's stability bound at ``n``."""
    h = L / n
    omega_max = math.sqrt(ALPHA_C * G * A / (RHO * I) + 4 * E / (RHO * h * h))
    return math.ceil(T_END / N_OUT / (frac * 2 / omega_max))


def elastica(n: int, case: str, frac: float = 0.45) -> tuple[float, np.ndarray]:
    """Wall time (stepping only) and tip trajectory ``(301, 2)`` of pyelastica at ``n`` elements."""
    import elastica as ea

    class Tip(ea.CallBackBaseClass):
        def __init__(self, every, out):
            self.every, self.out = every, out

        def make_callback(self, system, time, current_step):
            if current_step % self.every == 0:
                self.out.append(system.position_collection[:2, -1].copy())

    class Cantilever(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.CallBacks):
        pass

    sim = Cantilever()
    rod = ea.CosseratRod.straight_rod(n, np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), L, RADIUS,
                                      RHO, youngs_modulus=E, shear_modulus=G)
    sim.append(rod)
    sim.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
    if case == "tip":  # the ramp is over before the first force evaluation (at dt/2): a step
        sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), np.array([0.0, FY, 0.0]), ramp_up_time=1e-300)
    else:
        sim.add_forcing_to(rod).using(ea.GravityForces, acc_gravity=np.array([0.0, -GRAVITY, 0.0]))
    every = elastica_steps(n, frac)
    out: list = []
    sim.collect_diagnostics(rod).using(Tip, every=every, out=out)
    sim.finalize()
    stepper, dt, t = ea.PositionVerlet(), T_END / (N_OUT * every), np.float64(0.0)
    t0 = time.perf_counter()
    for _ in range(N_OUT * every):
        t = stepper.step(sim, t, dt)
    seconds = time.perf_counter() - t0
    return seconds, np.array(out)


def main() -> None:
    from importlib.metadata import version

    elastica_version = version("pyelastica")
    elastica(4, "tip")  # numba compilation
    data = {"t": TIMES, "params": np.array([L, RADIUS, RHO, E, G, ALPHA_C, FY, GRAVITY, T_END]),
            "pyelastica_version": np.array(elastica_version)}
    for case in CASES:
        runs = {}
        for n in (160, 320):
            seconds, runs[n] = elastica(n, case)
            data[f"{case}_n{n}"] = runs[n]
            print(f"{case}: pyelastica n={n} {seconds:.1f} s", flush=True)
        data[f"{case}_reference"] = richardson(runs[160], runs[320], 1)
    np.savez_compressed(REFERENCE, **data)
    print(f"wrote {REFERENCE}")


if __name__ == "__main__":
    main()
