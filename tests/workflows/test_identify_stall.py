"""A fit whose cost no longer falls at the resolution of its integration stops at its best point
(``phs.workflows.identify.solve.STALL``) instead of shrinking its trust region to scipy's step tolerance.

The residual gets a deterministic perturbation of 3e-4 of its RMS at every trial point (seeded by the
point: a stand-in for the integration's error, which moves with the parameters): near the optimum no
step lowers the cost reliably.  The fit stops ``stalled`` at the lowest cost it saw, at the same point
as with the rule off (scipy's step tolerance then ends it, after more evaluations: measured 9 against
14), and near the truth (1 %: the recording's noise).  Which trial points a fit visits moves with the integration's
own segments, and with them whether a smaller perturbation happens to stall it (1e-4 stalled before the fit read
its inputs through the simulator's plan, not after): 3e-4 is well above the integration error of rtol 1e-9."""

import zlib

import numpy as np
import pytest

from codegen import simulate
from phs.workflows.identify import identify, sensitivities, solve
from phs.workflows.recording import Recording
from systems.examples import rc_circuit


@pytest.fixture
def noisy_cost(monkeypatch):
    res = sensitivities._Problem.res

    def perturbed(self, z):
        r = np.asarray(res(self, z), dtype=float)
        seed = zlib.crc32(np.asarray(z, dtype=float).tobytes())
        return r + 3e-4 * np.linalg.norm(r) / np.sqrt(r.size) * np.random.default_rng(seed).standard_normal(r.size)

    monkeypatch.setattr(sensitivities._Problem, "res", perturbed)


def _fit():
    t = np.linspace(0.0, 0.01, 401)
    u = np.where((t % 0.004) < 0.002, 1.0, -0.5)
    truth = rc_circuit()
    y = simulate(truth, t, u={"U": u})["v_C"]
    rec = Recording.from_arrays(t, {"U": u, "v_C": y + 1e-3 * np.random.default_rng(1).standard_normal(len(t))})
    return identify(rc_circuit(R=1.6e3), rec, ["R.R"], rtol=1e-9, ftol=1e-15), truth


def test_a_stalled_fit_stops_at_its_best_point(noisy_cost, monkeypatch):
    fit, truth = _fit()
    assert fit.message.startswith("stalled")
    assert fit.values["R.R"] == pytest.approx(truth.param("R.R").value, rel=1e-2)  # the noisy recording's optimum
    monkeypatch.setattr(solve, "STALL", 10**9)  # the rule off: scipy's step tolerance ends it
    slow, _ = _fit()
    assert not slow.message.startswith("stalled")
    assert fit.iterations < slow.iterations
    assert fit.cost <= slow.cost * (1 + 1e-6)  # and it ended no worse (to the perturbation's size)
