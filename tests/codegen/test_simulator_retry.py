"""A run whose integration fails is tried once more from the state with its vanishing components set to
zero (``codegen.simulator.NEGLIGIBLE``): the curling HASEL fitted without its drift branch, driven by a
0 / −4 kV square wave interpolated as a smooth sampled input (step windows, not restarts at its kinks),
decays at 0 V to charges near 1e-170 C, and CVODES restarted from that state at 6.2 s fails with
repeated right-hand-side errors, while it passes from zero charge."""

import importlib

import numpy as np
import pytest

from codegen import Simulator
from phs.errors import SimulationError
from phs.signals import Sampled, square
from systems.curling_hasel import curling_hasel

# the values a nominal fit of the curling HASEL ended with (docs/examples/diagnose_curling_hasel.py)
VALUES = {"K_b": 0.047091880128233995, "b": 0.002934015144887044, "gamma1": 2.0000071232302155,
          "gamma2": 7.847577277391551, "R2": 1409526.2220472675}
_interpolants = importlib.import_module("codegen._interpolants")
_grid = importlib.import_module("codegen._grid")
simulator_module = importlib.import_module("codegen.simulator")  # the module (codegen.simulator is also a function)
X0 = {"seg1.l_p": 0.015, "seg2.l_p": 0.015}


def _run():
    t = np.arange(6667) / 1000.0
    U = np.asarray(square(-2000.0, 0.1, offset=-2000.0)(t), dtype=float)
    sim = Simulator(curling_hasel(2, drift=False, network="printed").with_params(VALUES), energy=False)
    return sim.run(t, u={"U": Sampled(tuple(t), tuple(U))}, x0=X0)


@pytest.fixture(autouse=True)
def _as_smooth_samples(monkeypatch):
    # the square wave's kinks are not breakpoints: the run that failed (the step windows' path of inputs
    # with many kinks)
    monkeypatch.setattr(Sampled, "kinks", lambda self: None)
    monkeypatch.setattr(Sampled, "lines", lambda self: np.zeros((0, 2)))  # nor its holds straight stretches
    # through CasADi's own B-spline and in windows of 200 intervals, with which the run failed (the banded build of the same spline differs by
    # rounding, 1e-14 of the range, and the failure, a Newton divergence near a vanishing state, hinges on it)
    monkeypatch.setattr(_interpolants, "BSPLINE_BANDED_FROM", 10**9)
    monkeypatch.setattr(_interpolants, "_INTERPOLANTS", {})
    monkeypatch.setattr(_grid, "JOINED_MAX", 1)  # and integrator calls of one window each


def test_a_failed_run_passes_from_its_vanishing_state_set_to_zero():
    res = _run()
    Q = np.asarray(res["seg1.Q2"])
    assert np.all(np.isfinite(Q))
    assert abs(Q[-1]) < 1e-12  # discharged at 0 V (C2 holds ~1e-6 C at -4 kV)
    assert np.max(np.abs(Q)) > 1e-7


def test_without_the_retry_the_same_run_fails(monkeypatch):
    monkeypatch.setattr(simulator_module, "NEGLIGIBLE", 0.0)
    with pytest.raises(SimulationError, match="between t=6.2"):
        _run()
