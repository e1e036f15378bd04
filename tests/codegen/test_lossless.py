"""A model without any dissipating element simulates (its dissipated power is a structural zero) and keeps its energy."""

import numpy as np
import pytest

from codegen import simulate
from systems.examples import duffing_oscillator


def test_undamped_duffing_runs_and_conserves_its_energy():
    res = simulate(duffing_oscillator(), np.linspace(0.0, 2.0, 201), x0={"s.q": 0.05}, rtol=1e-10)
    H = res.H
    # no input, no dissipation: H constant to the integration tolerance (rtol 1e-10 over a few periods)
    assert np.ptp(H) <= 1e-7 * H[0]
    assert res.quadratures["E_dissipated"][-1] == pytest.approx(0.0, abs=1e-15)
