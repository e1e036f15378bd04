"""Screening on the leading part of a long training recording (``screening_samples``), refits on all of it."""

from types import SimpleNamespace

import numpy as np
import pytest

from codegen import simulate
from phs.workflows.diagnose import diagnose
from phs.workflows.diagnose.hypotheses import Data
from phs.workflows.diagnose.screening import SCREEN_MIN_SAMPLES, SCREEN_SHARE, screening_samples
from phs.workflows.recording import Recording
from systems.examples import rc_circuit


def _data(n):
    t = np.arange(n) * 1e-3
    rec = Recording.from_arrays(t, {"y": np.sin(t)})
    return t, Data(rec, rec, np.ones(n, bool), None, ["y"], [], {}, [], None)


def test_window_is_the_share_or_the_minimum():
    t, data = _data(30000)
    even = SimpleNamespace(residuals={"y": 0.1 * np.sin(40 * t)})
    assert screening_samples(even, data) == int(np.ceil(SCREEN_SHARE * 30000))
    for n in (SCREEN_MIN_SAMPLES + 10, 2 * SCREEN_MIN_SAMPLES - 1):  # a window would save less than half
        t, short = _data(n)
        assert screening_samples(SimpleNamespace(residuals={"y": 0.1 * np.sin(40 * t)}), short) == n
    t, mid = _data(2 * SCREEN_MIN_SAMPLES)
    assert screening_samples(SimpleNamespace(residuals={"y": 0.1 * np.sin(40 * t)}), mid) == SCREEN_MIN_SAMPLES


def test_window_extends_to_a_late_mismatch_and_not_to_late_noise():
    t, data = _data(30000)
    m0 = int(np.ceil(SCREEN_SHARE * 30000))
    late = np.where(t > 24.0, 0.1, 0.0)
    m = screening_samples(SimpleNamespace(residuals={"y": late}), data)
    # the window holds half its share in time of the mismatch: (m - 24000) / 6000 >= m / 60000
    assert m > 24000 and (m - 24001) / 6000 >= 0.5 * m / 30000 - 1e-3
    # the same late residual is noise of that level: nothing above the noise, the plain share
    assert screening_samples(SimpleNamespace(residuals={"y": late}), data, noise={"y": 0.1}) == m0
    # no residual known: the plain share
    assert screening_samples(SimpleNamespace(residuals={}), data) == m0


@pytest.fixture(scope="module")
def long_offset():
    t = np.arange(9000) * 2e-5  # 9000 samples: screened on the first 3000
    u = np.where((t % 0.02) > 0.01, 1.0, 0.0)
    y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
    rng = np.random.default_rng(0)
    rec = Recording.from_arrays(t, {"U": u, "v_C": y + 1e-3 * rng.standard_normal(len(t))})
    return diagnose(rc_circuit(R=1.3e3), rec, free=["R.R"], n_jobs=1)


def test_long_recording_screens_on_its_window_and_refits_on_all(long_offset):
    d = long_offset
    assert d.effect == "offset"
    n_train = len(d.nominal.residuals["v_C"])
    screened = [h for h in d.hypotheses if h.ok and h.stage == "screening"]
    full = [h for h in d.hypotheses if h.ok and h.stage == "full"]
    assert screened and full
    assert {len(h.residuals["v_C"]) for h in screened} == {SCREEN_MIN_SAMPLES}
    # the refits ran on the whole training part (hypotheses left at the nominal model carry no residual)
    assert {len(h.residuals["v_C"]) for h in full if h.residuals} == {n_train}
    assert len(d.accepted[0].residuals["v_C"]) == n_train
    # the accepted offset is refitted on the whole training part: its value is the concealed 0.05 V
    off = [v for k, v in d.final.values.items() if "offset" in k]
    assert off and abs(off[0] - 0.05) < 2e-3


def test_separate_validation_is_scored_whole_while_screening_fits_on_the_window():
    # with a validation recording of its own, screening fits on the training recording's leading third and
    # scores on all of the validation (one simulation each: the ranking sees every part of the program);
    # refits fit and score on all of both
    t = np.arange(9000) * 2e-5
    u = np.where((t % 0.02) > 0.01, 1.0, 0.0)
    rng = np.random.default_rng(1)

    y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05

    def rec():  # the same truth, noise of its own
        return Recording.from_arrays(t, {"U": u, "v_C": y + 1e-3 * rng.standard_normal(len(t))})

    d = diagnose(rc_circuit(R=1.3e3), rec(), validation=rec(), free=["R.R"], n_jobs=1)
    assert d.effect == "offset"
    screened = [h for h in d.hypotheses if h.ok and h.stage == "screening" and not h.no_improvement]
    full = [h for h in d.hypotheses if h.ok and h.stage == "full" and not h.no_improvement]
    assert screened and full
    assert {len(h.residuals["v_C"]) for h in screened} == {SCREEN_MIN_SAMPLES}
    assert {len(h.simulated["validation"]["v_C"]) for h in screened} == {len(t)}
    assert {len(h.simulated["validation"]["v_C"]) for h in full} == {len(t)}
    assert len(d.final.simulated["validation"]["v_C"]) == len(t)


def test_resemblance_compares_a_screened_hypothesis_on_its_samples():
    # a hypothesis scored on the first half of the validation samples is compared over that half
    from types import SimpleNamespace as NS

    from phs.workflows.diagnose.discover.naming import resemblance

    y = np.arange(8.0)
    data = NS(outputs=["y"], validation={"y": y}, val_mask=np.ones(8, bool))

    def run(v):
        return NS(simulated={"validation": {"y": np.asarray(v, float)}}, ok=True, no_improvement=False)

    lib, other = run([0, 2, 0, 2]), run([0, -1, 0, -1])
    lib.augmentation, other.augmentation = NS(effect="offset"), NS(effect="cubic_stiffness")
    found = run([0, 1, 0, 1, 5, 5, 5, 5])
    sim = dict(resemblance(found, run(np.zeros(8)), run(np.zeros(8)), [lib, other], data))
    assert sim["offset"] == pytest.approx(1.0) and sim["cubic_stiffness"] == pytest.approx(-1.0)


def test_a_window_the_model_does_not_simulate_on_is_screened_whole(monkeypatch):
    # the model the hypotheses extend fails to simulate on the leading windows (as the curling HASEL did
    # once at 0 V): screening falls back to the whole recordings instead of stopping the diagnosis
    import phs.workflows.diagnose.hypotheses as hyp
    from phs.errors import SimulationError

    t = np.arange(9000) * 2e-5
    u = np.where((t % 0.02) > 0.01, 1.0, 0.0)
    y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
    rng = np.random.default_rng(2)

    def rec():
        return Recording.from_arrays(t, {"U": u, "v_C": y + 1e-3 * rng.standard_normal(len(t))})

    real = hyp.score
    windows = []

    def score(label, system, values, x0, n_params, data, **kw):
        if label == "nominal" and len(data.recording) < len(t):
            windows.append(len(data.recording))
            raise SimulationError("simulation of 'rc': the integrator failed between t=0.05 and t=0.05002")
        return real(label, system, values, x0, n_params, data, **kw)

    monkeypatch.setattr(hyp, "score", score)
    d = diagnose(rc_circuit(R=1.3e3), rec(), validation=rec(), free=["R.R"], n_jobs=1)
    assert windows == [SCREEN_MIN_SAMPLES]  # the window was tried
    assert d.effect == "offset"
    screened = [h for h in d.hypotheses if h.ok and h.stage == "screening" and not h.no_improvement]
    assert screened and {len(h.simulated["validation"]["v_C"]) for h in screened} == {len(t)}
