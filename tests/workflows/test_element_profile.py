"""The first-order profile an input element's first search runs on (``element_search.Profile``,
``element_search.nominal_profile``): the cost left after the model's free parameters re-adjust along their
finite-difference directions, against a least-squares solution computed apart, and against a refit."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from codegen import simulate
from phs.workflows.diagnose.element_search import PROFILE_RCOND, PROFILE_TRUST, Profile, nominal_profile, trial_cost
from phs.workflows.diagnose.hypotheses import Data
from phs.workflows.identify import identify
from phs.workflows.recording import Recording
from systems.examples import rc_circuit

FINITE = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
NORMAL = FINITE.filter(lambda v: v == 0.0 or abs(v) >= 1e-150)
"""Without magnitudes near the floating-point floor (a finite difference of a weighted residual never comes
near it), where numpy's least squares (the reference) overflows to NaN on subnormal numbers and the profile
keeps no direction of singular value below the smallest normal number: the step's test keeps them."""


NEAR_SINGULAR = np.full((12, 3), 3e-7)
NEAR_SINGULAR[0, 0] = 2.0  # r = ones lies along a direction of singular value 1.4e-6 against 2: below the cut


@settings(max_examples=60, deadline=None, derandomize=True)
@given(arrays(float, (12, 3), elements=NORMAL), arrays(float, 12, elements=NORMAL), st.booleans())
@example(NEAR_SINGULAR, np.ones(12), False)
def test_the_cost_left_is_the_least_squares_residual(D, r, alike):
    # ‖r‖² − ‖Uᵀr‖² against numpy's least squares min_δ ‖r + D δ‖² (two columns acting alike when `alike`),
    # both leaving out the directions whose singular value is below PROFILE_RCOND of the largest: the profile
    # does so by design (on NEAR_SINGULAR the direction it leaves out would remove the whole residual with a
    # step of 1.7e6 finite-difference steps, far outside where a first-order model holds)
    if alike:
        D = D.copy()
        D[:, 2] = 2.0 * D[:, 0]
    pr = Profile(D, {"a": 1.0, "b": 2.0, "c": 3.0}, {"a": 1.0, "b": 1.0, "c": 1.0}, {})
    left = pr.left(float(r @ r), pr.coefficients(r))
    delta = np.linalg.lstsq(D, -r, rcond=PROFILE_RCOND)[0]
    best = float(np.sum((r + D @ delta) ** 2))
    scale = 1.0 + float(r @ r)
    assert 0.0 <= left <= float(r @ r) + 1e-9 * scale
    assert abs(left - best) <= 1e-6 * scale  # two SVDs with the same cut: equal to rounding


@settings(max_examples=60, deadline=None, derandomize=True)
@given(arrays(float, (8, 2), elements=FINITE), arrays(float, 8, elements=FINITE),
       st.floats(0.1, 5.0), st.floats(0.1, 5.0))
@example(np.full((8, 2), 5e-324), np.zeros(8), 1.0, 1.0)  # subnormal directions: no step (it was NaN)
def test_the_step_stays_in_its_bounds_and_its_trust(D, r, a, b):
    values = {"a": a, "b": b}
    bounds = {"a": (0.5 * a, 10.0), "b": (0.0, 1.2 * b)}
    pr = Profile(D, values, {"a": 1e-3 * a, "b": 1e-3 * b}, bounds)
    step = pr.step(pr.coefficients(r))
    for k, v in step.items():
        assert bounds[k][0] <= v <= bounds[k][1]
        assert abs(v - values[k]) <= PROFILE_TRUST * values[k] * (1 + 1e-12)


def test_the_profile_of_a_mistuned_resistance_agrees_with_its_refit():
    # an RC circuit simulated at R = 2 kΩ, the model at 1.8 kΩ: the profile's step and the cost it leaves
    # against identify's refit of R (an independent computation: forward sensitivities, Gauss-Newton)
    t = np.linspace(0.0, 0.02, 801)
    u = 0.5 + 0.5 * np.sin(2 * np.pi * 125.0 * t) ** 3
    rng = np.random.default_rng(0)
    y = simulate(rc_circuit(R=2e3), t, u={"U": u})["v_C"] + 1e-3 * rng.standard_normal(len(t))
    rec = Recording.from_arrays(t, {"U": u, "v_C": y})
    data = Data(rec, rec, np.ones(len(t), bool), None, ["v_C"], ["R.R"], {}, [], None)
    model = rc_circuit(R=1.8e3)
    values = {"R.R": 1.8e3}
    pr = nominal_profile(model, [0.0], rec, data, values, {"R.R": (1.0, 1e6)}, 1e-9)
    held = trial_cost(model, [0.0], rec, None, "U", data, 1e-9)
    profiled = trial_cost(model, [0.0], rec, None, "U", data, 1e-9, pr)
    fit = identify(model, rec, ["R.R"], outputs=["v_C"], x0={model.state_names[0]: 0.0}, rtol=1e-9)
    refitted = trial_cost(rc_circuit(R=fit.values["R.R"]), [0.0], rec, None, "U", data, 1e-9)
    step = profiled.step([])["R.R"]
    # measured: held 7.70, profiled 0.0506, refitted 0.0301 (the noise's share about 0.03); the step 1987.8 Ω,
    # the refit 1999.5 Ω.  The profile removes all but 0.27 % of what the refit removes (its remainder is second
    # order in the 10 % mistuning); the step lands within 1 % of the refit
    assert abs(step / fit.values["R.R"] - 1) < 0.01 and abs(fit.values["R.R"] / 2e3 - 1) < 0.005
    assert held([]) > 100 * refitted([])
    assert (held([]) - profiled([])) / (held([]) - refitted([])) > 0.99
