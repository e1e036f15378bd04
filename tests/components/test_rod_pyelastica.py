"""Dynamics of the Cosserat rod against pyelastica: an undamped cantilever under a step tip load and under gravity
switched on at t = 0, 1.5 periods of the first mode, tip trajectories compared over the whole run.

The setup of ours is written here again, independently of the bench; pyelastica's trajectories are stored in
``tests/data/rod_cantilever_pyelastica.npz`` (written by ``python bench/rod_cantilever.py``: runs at n = 160 and
320 and their first-order Richardson extrapolation), so the default test needs neither pyelastica nor its numba
compilation (over a minute with a cold cache).  The ``slow`` test reruns pyelastica live and checks the stored file.
Errors are the largest tip distance over the run in units of the largest tip deflection (0.59 L and 0.47 L).
"""

import importlib.util
import math
import os

import numpy as np
import pytest

from codegen import simulator
from components import ForceSource, TorqueSource
from components.rod import CosseratRod
from phs import interconnect, series

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
DATA = os.path.join(ROOT, "tests", "data", "rod_cantilever_pyelastica.npz")
L, RADIUS, RHO, E = 1.0, 0.02, 1000.0, 50e6
G, KS = E / 3, 27 / 28  # pyelastica's shear stiffness is alpha_c G A with alpha_c = 27/28 fixed
A, I = math.pi * RADIUS**2, math.pi * RADIUS**4 / 4  # noqa: E741
FY, GRAVITY = -E * I / L**2, 9.81
T_END = 1.5 * 2 * math.pi / (1.875104069**2 * math.sqrt(E * I / (RHO * A * L**4)))


def cantilever(n, case):
    if case == "gravity":
        return interconnect("hanging", [CosseratRod("rod", n=n, L=L, E=E, G=G, k_s=KS, I=I, A=A, rho=RHO,
                                                    gravity=True, g=GRAVITY)])
    rod = CosseratRod("rod", n=n, L=L, E=E, G=G, k_s=KS, I=I, A=A, rho=RHO, tip="force")
    return interconnect("cantilever", [rod, ForceSource("Fx"), ForceSource("Fy"), TorqueSource("M")],
                        [series("Fx", "rod.tip_x"), series("Fy", "rod.tip_y"), series("M", "rod.tip_m")])


def tip_trajectory(n, case, t, rtol=1e-7):
    res = simulator(cantilever(n, case), rtol=rtol, energy=False).run(t, u={"Fy": FY} if case == "tip" else None)
    return np.c_[L + res[f"rod.ux{n}"], res[f"rod.uy{n}"]]


def deviation(a, b):
    """Largest distance between tip trajectories a and b over the run, in units of b's largest tip deflection."""
    return np.max(np.hypot(*(a - b).T)) / np.max(np.hypot(b[:, 0] - L, b[:, 1]))


@pytest.fixture(scope="module")
def stored():
    with np.load(DATA) as f:
        data = {k: f[k] for k in f.files}
    # the stored runs are of this very cantilever
    np.testing.assert_allclose(data["params"], [L, RADIUS, RHO, E, G, KS, FY, GRAVITY, T_END], rtol=1e-12)
    return data


@pytest.mark.parametrize("case", ["tip", "gravity"])
def test_tip_trajectory_matches_pyelastica(stored, case):
    t = stored["t"]
    reference = stored[f"{case}_reference"]
    coarse, fine = tip_trajectory(5, case, t), tip_trajectory(10, case, t)
    # ours converges at second order: (4 x10 - x5)/3 removes the leading error.  Observed against pyelastica's
    # extrapolated trajectory: 0.38 % (tip), 0.11 % (gravity); pyelastica's own extrapolation is uncertain by
    # about 0.1 % (it moves by 0.09 % from n = 80/160 to 160/320 and 320/640) - the spec's 1 % holds with margin.
    assert deviation((4 * fine - coarse) / 3, reference) < 0.01
    # the plain n = 10 run: its own discretisation error (1.4 % and 1.1 % against ours at n = 20/40 extrapolated)
    # plus the 1 % allowance
    assert deviation(fine, reference) < 0.025
    # and the extrapolation is needed: pyelastica at n = 320 is still 1.1 % off its own limit (first order)
    assert 0.005 < deviation(stored[f"{case}_n320"], reference) < 0.02


@pytest.mark.slow
@pytest.mark.parametrize("case", ["tip", "gravity"])
def test_tip_trajectory_matches_live_pyelastica_at_full_size(stored, case):
    pytest.importorskip("elastica")
    spec = importlib.util.spec_from_file_location("rod_cantilever", os.path.join(ROOT, "bench", "rod_cantilever.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    t = stored["t"]
    live = {n: bench.elastica(n, case)[1] for n in (160, 320)}
    # the stored file is what pyelastica gives (1e-6: numba/numpy versions may change the last bits of 1e5 steps)
    assert deviation(live[320], stored[f"{case}_n320"]) < 1e-6
    theirs = bench.richardson(live[160], live[320], 1)
    ours20, ours40 = tip_trajectory(20, case, t, rtol=1e-9), tip_trajectory(40, case, t, rtol=1e-9)
    ours_limit = (4 * ours40 - ours20) / 3
    # both converged (extrapolated): observed 0.12 % (tip) and 0.08 % (gravity)
    assert deviation(ours_limit, theirs) < 0.01
    # without extrapolation ours at n = 40 is within 0.1 % of its limit, so the whole difference to pyelastica's
    # n = 320 run (1.2 %) is pyelastica's first-order error: check that it is what its halving predicts
    assert deviation(ours40, ours_limit) < 0.0015
    assert abs(deviation(live[320], ours_limit) - deviation(live[160], live[320])) < 0.003
