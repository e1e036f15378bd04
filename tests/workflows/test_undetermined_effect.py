"""An effect whose parameters the data do not determine (it only trades off with a free nominal
parameter) is reported as such (``Scored.undetermined``); the same effect next to a fixed parameter is
determined and recovers the concealed value."""

import numpy as np
import pytest

from codegen import simulate
from components.candidates import LIBRARY, Scales
from phs.workflows.diagnose.hypotheses import Data, fit_augmented, train_result
from phs.workflows.diagnose.nominal import fit_nominal
from phs.workflows.diagnose.ranking import undetermined_effect
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper


@pytest.fixture(scope="module")
def recording():
    t = np.arange(2001) * 2e-3
    F = np.where((t % 1.0) < 0.5, 1.0, -1.0) * (t > 0.05)
    y = simulate(mass_spring_damper(m=1.3), t, u={"F": F})["position"]
    rng = np.random.default_rng(3)
    return Recording.from_arrays(t, {"F": F, "position": y + 1e-4 * rng.standard_normal(len(t))})


def _added_mass(recording, free):
    system = mass_spring_damper()
    data = Data(recording, recording, np.ones(len(recording), bool), None, ["position"], free, {}, [], None)
    nominal, data = fit_nominal(system, data)
    res = train_result(nominal, data)
    U = np.column_stack([np.asarray(res["F"])])
    scales = Scales.of(nominal.system.with_params(nominal.values), res.t, np.asarray(res.x), U, {"position": recording["position"]})
    cand = next(c for c in LIBRARY if c.effect == "added_mass")
    aug = cand.augment(nominal.system.with_params(nominal.values), "m.p", scales)
    return aug, fit_augmented(nominal, aug, data)


def test_added_mass_next_to_a_free_mass_is_undetermined(recording):
    aug, h = _added_mass(recording, ["m.m", "k.K", "b.b"])
    assert h.ok
    assert set(aug.free) <= set(h.undetermined)  # m (1 + mu) is all the data determine
    assert undetermined_effect(h)


def test_added_mass_next_to_a_fixed_mass_is_determined(recording):
    aug, h = _added_mass(recording, ["k.K", "b.b"])
    assert h.ok and h.undetermined == []
    assert not undetermined_effect(h)
    # it finds the concealed extra inertia: (1 + mu) m = 1.3 with m = 1
    mu = h.values[aug.free[0]]
    assert abs(mu - 0.3) < 0.01
