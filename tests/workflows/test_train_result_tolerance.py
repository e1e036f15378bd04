"""The training trajectory of a scored model (``hypotheses.train_result``: what the next round's location,
discovery and the ranking read) is simulated at the scores' tolerance; where that integration fails, it is
the one at the fit's own tolerance (``Data.rtol``), where the fit computed the training residuals.  On a
lab-protocol Coulomb friction + hysteresis (``esa:coulomb_friction+hysteresis@1kHz``) the accepted
hysteresis' state grew to 15 times its typical size and the integration at 1e-8 took its 20 000 steps
within one output interval: the whole diagnosis ended in that error.  Here the failure is forced at the
scores' tolerance on a mass-spring-damper (a real one needs a 10-minute diagnosis), and the trajectory
returned must be the fit tolerance's, bit for bit.  Where both tolerances fail, the location reads the recorded
inputs alone (with a warning) instead of ending the diagnosis."""

import numpy as np
import pytest

from codegen import Simulator, simulate
from phs.errors import PHSError, SimulationError
from phs.workflows.diagnose import hypotheses
from phs.workflows.diagnose.hypotheses import Data, train_result
from phs.workflows.diagnose.mismatch import _features, _locate, noise_level
from phs.workflows.diagnose.nominal import fit_nominal
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper


@pytest.fixture(scope="module")
def fitted():
    t = np.arange(1001) * 2e-3
    F = np.where((t % 0.5) < 0.25, 1.0, -1.0) * (t > 0.05)
    y = simulate(mass_spring_damper(m=1.3), t, u={"F": F})["position"]
    rec = Recording.from_arrays(t, {"F": F, "position": y + 1e-4 * np.random.default_rng(5).standard_normal(len(t))})
    data = Data(rec, rec, np.ones(len(rec), bool), None, ["position"], ["k.K", "b.b"], {}, [], None, rtol=1e-6)
    return fit_nominal(mass_spring_damper(), data)


def _failing_at_the_scores_tolerance(monkeypatch, also_at_the_fits=False):
    plain = hypotheses._simulate

    def simulate_(system, rec, x0, params=None, sim=None):
        if sim is None or also_at_the_fits:
            raise SimulationError("simulation of 'msd': the integrator failed (forced)")
        return plain(system, rec, x0, params=params, sim=sim)

    monkeypatch.setattr(hypotheses, "_simulate", simulate_)


def test_a_trajectory_that_fails_at_the_scores_tolerance_is_the_fits(fitted, monkeypatch):
    nominal, data = fitted
    nominal.simulated["train"] = None
    _failing_at_the_scores_tolerance(monkeypatch)
    res = train_result(nominal, data)
    u = {"F": data.recording.input_signal("F")}
    direct = Simulator(nominal.system, rtol=data.rtol, energy=False).run(data.recording.t, u=u, x0=nominal.x0)
    assert np.array_equal(np.asarray(res.x), np.asarray(direct.x))
    # it is the fit's trajectory: its position reproduces the fit's training residuals (to the integration's error)
    fit_residual = np.asarray(nominal.residuals["position"])
    replayed = np.asarray(data.recording["position"]) - np.asarray(res["position"])
    assert np.max(np.abs(replayed - fit_residual)) <= 1e-3 * np.std(data.recording["position"])
    # and the next round's location reads it
    noise = {"position": noise_level(data.recording["position"])}
    assert _locate(nominal, nominal.system, data, noise) is not None


def test_a_trajectory_that_fails_at_both_tolerances_raises_the_simulation_error(fitted, monkeypatch):
    nominal, data = fitted
    nominal.simulated["train"] = None
    _failing_at_the_scores_tolerance(monkeypatch, also_at_the_fits=True)
    with pytest.raises(PHSError, match="forced"):
        train_result(nominal, data)
    nominal.simulated["train"] = None


def test_a_location_whose_trajectory_fails_at_both_tolerances_reads_the_inputs_alone(fitted, monkeypatch):
    # the next round's location of a model that cannot be integrated at all: a warning, and the mismatch located
    # against the recorded inputs alone (the same findings of the residual's whiteness as with the model's signals)
    nominal, data = fitted
    noise = {"position": noise_level(data.recording["position"])}
    with_model = _locate(nominal, nominal.system, data, noise)
    nominal.simulated["train"] = None
    _failing_at_the_scores_tolerance(monkeypatch, also_at_the_fits=True)
    with pytest.warns(RuntimeWarning, match="located against the recorded inputs alone"):
        alone = _locate(nominal, nominal.system, data, noise)
    nominal.simulated["train"] = None
    assert not any(s in f.where for f in alone for s in nominal.system.state_names)  # no model signal read
    with pytest.warns(RuntimeWarning):
        feats, inputs = _features(nominal, nominal.system, data)
    nominal.simulated["train"] = None
    assert feats == {} and list(inputs) == ["F"] and np.array_equal(inputs["F"], data.recording["F"])
    white = [(f.kind, f.where, f.details.get("significant")) for f in with_model if f.kind == "whiteness"]
    assert white and white == [(f.kind, f.where, f.details.get("significant")) for f in alone if f.kind == "whiteness"]
