"""Manta-ray fin: single electrical branch, power balance, periodic flapping under sine drive."""

import numpy as np
import pytest
import sympy as sp

from codegen import simulate
from systems.manta_ray_fin import manta_ray_fin

X0 = {f"shell{i}.l_p": 0.015 for i in range(1, 5)}


@pytest.fixture(scope="module")
def fin():
    return manta_ray_fin(4)


def test_single_electrical_branch_structurally(fin):
    electrical = [n for n in fin.state_names if n.endswith(("Q1", "Q2"))]
    assert electrical == ["fin.Q1", "fin.Q2"]
    idx = [fin.state_names.index(n) for n in electrical]
    R0, R1, R2 = (sp.Symbol(n, positive=True) for n in ("R0", "R1", "R2"))
    expected = sp.Matrix([[1 / R0 + 1 / R1, 1 / R0], [1 / R0, 1 / R0 + 1 / R2]])
    assert sp.simplify(fin.R.extract(idx, idx) - expected) == sp.zeros(2, 2)
    # every shell angle acts on the one electrode capacitor: dH/dtheta_i depends on Q2
    q2 = sp.Symbol("fin.Q2", real=True)
    for i in range(1, 5):
        assert fin.grad_H[fin.state_names.index(f"shell{i}.theta")].has(q2)
    assert fin.check(samples=50).ok


def test_power_balance_over_10s(fin):
    t = np.linspace(0, 10, 5001)
    res = simulate(fin, t, u={"U": "5000*sin(2*pi*t)"}, x0=X0, rtol=1e-9)
    assert res.energy_balance_error() <= 1e-6


@pytest.mark.parametrize("freq", [1.0, 0.5])
def test_sine_drive_gives_periodic_flapping(fin, freq):
    # the force goes with V**2: the fin flaps at twice the drive frequency; after ~10 drift time
    # constants (C1 (R1 || (R0 + R2)) ~ 2.3 s) consecutive flapping periods coincide
    period = 1 / (2 * freq)
    t_end = 30.0
    dt = 1e-3
    t = np.arange(0, t_end + dt / 2, dt)
    res = simulate(fin, t, u={"U": f"5000*sin(2*pi*{freq}*t)"}, x0=X0)
    n = int(round(period / dt))
    last, prev = res["tip"][-n:], res["tip"][-2 * n: -n]
    amplitude = last.max() - last.min()
    assert amplitude > 5e-3  # millimetres of flapping, not a tremor
    assert np.max(np.abs(last - prev)) <= 1e-3 * amplitude
    # and the motion is not periodic at the drive period's half-shift by accident: one peak per flap
    assert np.argmax(last) not in (0, n - 1)
