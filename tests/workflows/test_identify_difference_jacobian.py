"""Where the integration with sensitivities fails but the state's alone passes, a fit takes its Jacobian by
differences of the residual (``phs.workflows.identify.solve._jacobian``) instead of failing.

Differential: on a recording of an RC circuit's square-wave response the differenced Jacobian agrees with the
sensitivities' to ``√rtol``-sized error (tolerance 1e-3 of the largest entry: forward differences with a step of
``√rtol`` (1e-5 at the rtol 1e-10 used) err by far less); and a fit whose sensitivity integrations all fail reaches the same
values as the fit with them (to 1e-4: both stop at the noisy recording's optimum within the cost's resolution).
"""

import numpy as np
import pytest

from codegen import simulate
from phs.workflows.identify import identify, sensitivities, solve
from phs.workflows.recording import Recording
from systems.examples import rc_circuit


def _recording(seed=1):
    t = np.linspace(0.0, 0.01, 401)
    u = np.where((t % 0.004) < 0.0021, 1.0, -0.5)
    y = simulate(rc_circuit(), t, u={"U": u})["v_C"]
    return Recording.from_arrays(t, {"U": u, "v_C": y + 1e-3 * np.random.default_rng(seed).standard_normal(len(t))})


@pytest.fixture
def failing_sensitivities(monkeypatch):
    def fail(self, z):
        raise RuntimeError('CVode returned "CV_TOO_MUCH_WORK"')

    monkeypatch.setattr(sensitivities._Problem, "_jac", fail)


@pytest.mark.parametrize("z", [[0.3, -0.2], [1.5, 0.4], [-0.8, 1.0]])
def test_the_differenced_jacobian_agrees_with_the_sensitivities(z):
    rec = _recording()
    code = rc_circuit(R=1.6e3, C=1.3e-6)
    w = {"v_C": 1.0 / float(np.std(rec["v_C"]))}
    prob = sensitivities._Problem(code, rec, ["R.R", "C.C"], ["R.R", "C.C"], ["v_C"], w, np.zeros(1), [], 1e-10, None,
                                  compile=False)
    z = np.asarray(z)
    r, J = prob.jac(z)

    class Failing:
        def jac(self, z):
            raise RuntimeError("CV_TOO_MUCH_WORK")

        def res(self, z):
            return prob.res(z)

    r2, J2 = solve._jacobian(Failing(), z, [np.inf, np.inf], 1e-10)
    np.testing.assert_allclose(r2, r, rtol=0, atol=1e-9 * np.max(np.abs(r)))
    np.testing.assert_allclose(J2, J, rtol=0, atol=1e-3 * np.max(np.abs(J)))


def test_a_fit_whose_sensitivities_fail_reaches_the_same_values(failing_sensitivities):
    rec = _recording(2)
    fit = identify(rc_circuit(R=1.6e3, C=1.3e-6), rec, ["R.R", "C.C"], rtol=1e-9)
    assert np.isfinite(fit.cost)
    truth = rc_circuit()
    assert fit.values["R.R"] * fit.values["C.C"] == pytest.approx(truth.param("R.R").value * truth.param("C.C").value, rel=1e-2)


def test_a_fit_whose_sensitivities_fail_matches_the_one_with_them(monkeypatch):
    rec = _recording(3)
    with_sens = identify(rc_circuit(R=1.6e3), rec, ["R.R"], rtol=1e-9)

    def fail(self, z):
        raise RuntimeError('CVode returned "CV_TOO_MUCH_WORK"')

    monkeypatch.setattr(sensitivities._Problem, "_jac", fail)
    without = identify(rc_circuit(R=1.6e3), rec, ["R.R"], rtol=1e-9)
    assert without.values["R.R"] == pytest.approx(with_sens.values["R.R"], rel=1e-4)


@pytest.mark.slow  # two 17 s lab recordings integrated by scipy (about 2 min) and a diagnosis (about 2 min)
def test_the_lab_friction_and_hysteresis_are_both_named():
    """``esa:coulomb_friction+hysteresis@1kHz``: the friction alone lowers the current; the hysteresis that makes
    the pair whole failed its fit in the integration with sensitivities (``CV_TOO_MUCH_WORK``) before the
    differenced Jacobian, and the verdict was none."""
    import importlib

    from phs.workflows.diagnose import diagnose

    lp = importlib.import_module("examples.lab_protocols")
    case = "esa:coulomb_friction+hysteresis@1kHz"
    train, info = lp.generate(case, seed=1)
    val, _ = lp.generate(case, seed=2, validation=True)
    act = lp.ACTUATORS["esa"]
    d = diagnose(act.nominal(), train, validation=val, free=info["free"], x0=info["x0"], outputs=list(act.channels), n_jobs=2)
    assert set(d.verdict["effects"]) == {"coulomb_friction", "hysteresis"}, d.summary()
    for ch in act.channels:
        assert d.final.validation_fit_percent[ch] >= d.nominal.validation_fit_percent[ch]
