"""Identification from summary statistics (``identify(system, [Summary, ...], free)``): the truth of a
mass-spring-damper recovered from a few statistics of three runs (one with its own mass), the same fit
computed independently (scipy's least squares over plain simulations, finite-difference Jacobian), and
bad summaries refused with one line naming the culprit."""

import numpy as np
import pytest
import scipy.optimize
import scipy.stats

from codegen import simulate
from phs import InputDataError, ParameterError, Summary
from phs.workflows.identify import SummaryFit, identify
from phs.workflows.identify.summaries import statistic, summary_statistics
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper

TRUTH = {"k.K": 5.0, "b.b": 0.8}
T = np.linspace(0.0, 10.0, 501)


def _run(F, name, measured, params=None):
    """A run whose force steps to ``F`` at 1 s (held between the samples)."""
    rec = Recording.from_arrays(T, {"F": np.where(T >= 1.0, F, 0.0)}, source=name, holds={"F": "zoh"})
    return Summary(rec, measured, dict(params or {}), name)


def _runs(values=None):
    """Three runs: a step of 1 N, one of 2 N, one of -1 N on twice the mass; their statistics of
    ``position`` are the truth's, or ``values`` in their order."""
    labels = [["max(position)", "final(position)"], ["mean(position)", "range(position)"], ["rms(position)", "min(position)"]]
    shells = [_run(1.0, "a", dict.fromkeys(labels[0], 1.0)), _run(2.0, "b", dict.fromkeys(labels[1], 1.0)),
              _run(-1.0, "c", dict.fromkeys(labels[2], 1.0), {"m.m": 2.0})]
    if values is None:
        values = summary_statistics(mass_spring_damper(**{"k": TRUTH["k.K"], "b": TRUTH["b.b"]}), shells, rtol=1e-10)
    out, k = [], 0
    for s, labs in zip(shells, labels, strict=True):
        out.append(Summary(s.recording, {lab: float(values[k + j]) for j, lab in enumerate(labs)}, s.params, s.name))
        k += len(labs)
    return out


def test_statistics_of_simulated_runs_give_back_the_truth():
    """Noise-free statistics (rtol 1e-10) fitted at rtol 1e-9 from 20-50 % off: the truth to 1e-6."""
    fit = identify(mass_spring_damper(), _runs(), ["k.K", "b.b"], rtol=1e-9)
    assert isinstance(fit, SummaryFit) and fit.dof == 4
    for k, v in TRUTH.items():
        assert fit.values[k] == pytest.approx(v, rel=1e-6)
    assert np.max(np.abs(fit.relative_errors)) < 1e-7
    # the third run's mass entered its simulation: at m = 1 its rms differs by 2.1 %, far above the tolerances
    other = summary_statistics(mass_spring_damper(k=5.0, b=0.8), [_runs()[2]], rtol=1e-10)
    plain = Summary(_runs()[2].recording, _runs()[2].measured, {}, "c1")
    assert abs(summary_statistics(mass_spring_damper(k=5.0, b=0.8), [plain], rtol=1e-10)[0] / other[0] - 1) > 0.02
    assert "Student's t, 4 degrees of freedom" in fit.summary()


def test_the_fit_agrees_with_least_squares_over_plain_simulations():
    """Statistics off by -3..+3 %: the same relative least squares solved by scipy over ``Simulator.run``
    with a finite-difference Jacobian (step 1e-6 on an integration at rtol 1e-10: Jacobian error about 1e-4)
    gives the same values to 1e-5 and standard errors to 0.1 %; the intervals are v ± t(0.975, 4) std."""
    truth_runs = _runs()
    measured = np.concatenate([list(s.measured.values()) for s in truth_runs])
    measured *= 1.0 + np.array([0.03, -0.02, 0.01, -0.03, 0.02, -0.01])
    runs = _runs(measured)
    fit = identify(mass_spring_damper(), runs, ["k.K", "b.b"], log_scale=(), rtol=1e-10)

    def rel(p):
        return summary_statistics(mass_spring_damper(k=p[0], b=p[1]), runs, rtol=1e-10) / measured - 1.0

    sol = scipy.optimize.least_squares(rel, [4.0, 0.4], diff_step=1e-6, xtol=1e-12, ftol=1e-12)
    s2 = float(sol.fun @ sol.fun) / (len(measured) - 2)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(sol.jac.T @ sol.jac)))
    q = scipy.stats.t.ppf(0.975, 4)
    for i, k in enumerate(("k.K", "b.b")):
        assert fit.values[k] == pytest.approx(sol.x[i], rel=1e-5)
        assert fit.std_errors[k] == pytest.approx(se[i], rel=1e-3)
        lo, hi = fit.intervals[k]
        assert (lo, hi) == pytest.approx((fit.values[k] - q * fit.std_errors[k], fit.values[k] + q * fit.std_errors[k]), rel=1e-12)
    np.testing.assert_allclose(fit.relative_errors, sol.fun, atol=1e-6)


def test_statistics_and_their_gradients():
    y = np.array([1.0, 4.0, -2.0, 3.0])
    assert [statistic(k, y)[0] for k in ("mean", "range", "max", "min", "final")] == [1.5, 6.0, 4.0, -2.0, 3.0]
    rms, g = statistic("rms", y)
    h = 1e-7
    fd = [(statistic("rms", y + h * np.eye(4)[i])[0] - rms) / h for i in range(4)]
    np.testing.assert_allclose(g, fd, atol=1e-6)  # forward difference: error of order h


@pytest.mark.parametrize(("make", "error", "words"), [
    (lambda r: Summary(r, {"average(position)": 1.0}), InputDataError, "'average(position)' is not a statistic"),
    (lambda r: Summary(r, {"max(position)": float("nan")}), InputDataError, "max(position) is nan"),
    (lambda r: Summary(r, {}), InputDataError, "non-empty"),
    (lambda r: Summary(r.t, {"max(position)": 1.0}), InputDataError, "recording must be a Recording"),
])
def test_bad_summaries_are_refused(make, error, words):
    rec = _run(1.0, "a", {"max(position)": 1.0}).recording
    with pytest.raises(error) as exc:
        make(rec)
    assert words in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize(("runs", "kw", "error", "words"), [
    (lambda: [_run(1.0, "a", {"max(speed)": 1.0})], {}, InputDataError, "'speed'"),
    (lambda: [_run(1.0, "a", {"mean(position)": 0.0})], {}, ParameterError, "mean(position) = 0"),
    (lambda: [_run(1.0, "a", {"max(position)": 0.2}, {"k.K": 3.0})], {}, ParameterError, "free parameter(s) ['k.K']"),
    (lambda: [_run(1.0, "a", {"max(position)": 0.2}), _run(2.0, "a", {"max(position)": 0.4})], {}, InputDataError,
     "distinct names"),
    (lambda: [_run(1.0, "a", {"max(position)": 0.2})], {"shooting": 3}, ParameterError, "shooting"),
    (lambda: [_run(1.0, "a", {"max(position)": 0.2})], {"weights": "ml"}, ParameterError, "weights='ml'"),
    (lambda: [_run(1.0, "a", {"max(position)": 0.2})], {"estimate_x0": ["m.p"]}, ParameterError, "estimate_x0"),
])
def test_bad_fits_to_summaries_are_refused(runs, kw, error, words):
    with pytest.raises(error) as exc:
        identify(mass_spring_damper(), runs(), ["k.K"], **kw)
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_a_zero_statistic_is_fitted_with_a_given_weight_and_the_recording_methods_say_why_not():
    """mean(position) of a run without force is 0 at any stiffness: given a weight it is fitted (the
    other run determines k), and the recording-only methods refuse in one line."""
    step = _run(1.0, "a", {"mean(position)": 1.0})
    y = simulate(mass_spring_damper(k=5.0), T, u={"F": step.recording.input_signal("F")}, rtol=1e-10)["position"]
    runs = [_run(1.0, "a", {"mean(position)": float(np.mean(y))}), _run(0.0, "rest", {"mean(position)": 0.0})]
    fit = identify(mass_spring_damper(), runs, ["k.K"], weights={"mean(position)": 10.0}, rtol=1e-9)
    assert fit.values["k.K"] == pytest.approx(5.0, rel=1e-6)
    assert fit.weights == {"a:mean(position)": 10.0, "rest:mean(position)": 10.0}
    for call in (lambda: fit.validate(None), lambda: fit.sensitivity_table()):
        with pytest.raises(ParameterError, match="summary statistics"):
            call()
    assert len(fit.plot().axes) == 1
