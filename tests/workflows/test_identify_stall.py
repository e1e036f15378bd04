"""A fit whose cost no longer falls at the resolution of its integration stops at its best point
(``phs.workflows.identify.solve.STALL``, and ``RESOLVED`` where a step's predicted and actual decreases are
both within the cost's resolution) instead of shrinking its trust region to scipy's step tolerance.

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
    monkeypatch.setattr(solve, "RESOLVED", 0.0)  # the resolution rule off: the stall rule alone
    fit, truth = _fit()
    assert fit.message.startswith("stalled")
    assert fit.values["R.R"] == pytest.approx(truth.param("R.R").value, rel=1e-2)  # the noisy recording's optimum
    monkeypatch.setattr(solve, "STALL", 10**9)  # the rule off: scipy's step tolerance ends it
    slow, _ = _fit()
    assert not slow.message.startswith("stalled")
    assert fit.iterations < slow.iterations
    assert fit.cost <= slow.cost * (1 + 1e-6)  # and it ended no worse (to the perturbation's size)


def test_a_fit_ends_where_its_steps_are_below_the_cost_resolution(noisy_cost, monkeypatch):
    # the perturbation is read as the cost's resolution (the Jacobian's integration does not carry it), and
    # the fit ends as soon as a step's predicted and actual decreases fall within it: before the stall rule
    fit, truth = _fit()
    assert fit.message.startswith("resolved")
    assert fit.values["R.R"] == pytest.approx(truth.param("R.R").value, rel=1e-2)
    monkeypatch.setattr(solve, "RESOLVED", 0.0)
    stalled, _ = _fit()
    assert fit.iterations < stalled.iterations
    assert fit.cost <= stalled.cost * (1 + 1e-6)


def _stiff_fit(rtol):
    """A stiff mass-spring-damper (k = 400, fitted from 380 with the damping) on 4 s of a square and a sine at
    1 kHz, integrated at ``rtol``: at 1e-5 the integration's error in the cost (about 0.1 at the optimum)
    is far above the decreases the last steps still find."""
    from systems.examples import mass_spring_damper as msd

    t = np.linspace(0.0, 4.0, 4001)
    u = np.where((t % 1.0) < 0.5, 1.0, -0.5) + 0.3 * np.sin(7 * t)
    y = simulate(msd(k=400.0, b=0.5), t, u={"F": u})["position"]
    rec = Recording.from_arrays(t, {"F": u, "position": y + 1e-4 * np.random.default_rng(1).standard_normal(len(t))})
    return identify(msd(k=380.0, b=0.7), rec, ["k.K", "b.b"], rtol=rtol, ftol=1e-12)


def test_the_resolution_ends_a_loosely_integrated_fit_early_and_in_the_same_place(monkeypatch):
    fit = _stiff_fit(1e-5)
    monkeypatch.setattr(solve, "RESOLVED", 0.0)
    monkeypatch.setattr(solve, "STALL", 10**9)
    slow = _stiff_fit(1e-5)
    assert fit.message.startswith("resolved") and not slow.message.startswith(("resolved", "stalled"))
    assert fit.iterations < slow.iterations
    # the same optimum within half a standard error (two fits that each end within the integration's error
    # of the cost), and the truth within three
    for k, true in (("k.K", 400.0), ("b.b", 0.5)):
        assert abs(fit.values[k] - slow.values[k]) < 0.5 * fit.std_errors[k]
        assert abs(fit.values[k] - true) < 3 * fit.std_errors[k]


def test_the_attainable_decrease_bounds_every_steps_prediction():
    # the Gauss-Newton model at a Jacobian's point: no step predicts more than the full step, which predicts
    # exactly the attainable decrease (two parameters, one far off: the full step is far larger than a small one)
    from systems.examples import mass_spring_damper as msd

    t = np.linspace(0.0, 2.0, 801)
    u = np.where((t % 0.5) < 0.25, 1.0, -0.5)
    y = simulate(msd(k=9.0, b=1.2), t, u={"F": u})["position"]
    rec = Recording.from_arrays(t, {"F": u, "position": y})
    system = msd(k=4.0, b=0.4)
    p = np.array(system.param_vector(), float)
    prob = sensitivities._Problem(system, rec, ["k.K", "b.b"], [], ["position"], {"position": 1.0}, np.zeros(2), [],
                                  1e-9, None, params=p)
    assert prob.attainable_decrease() == float("inf")  # before a first Jacobian
    at = np.array([1.0, 1.0])
    r, J = prob.jac(at)
    full = at + np.linalg.lstsq(J, -r, rcond=None)[0]
    best = prob.attainable_decrease()
    assert 0 < best <= 0.5 * float(r @ r)
    assert prob.predicted_decrease(full) == pytest.approx(best, rel=1e-9)
    for dz in np.random.default_rng(0).standard_normal((50, 2)) * np.array([0.5, 0.5]):
        assert prob.predicted_decrease(at + dz) <= best * (1 + 1e-12)
    assert prob.predicted_decrease(at + 0.01 * (full - at)) < 0.05 * best  # a short step along it predicts little

