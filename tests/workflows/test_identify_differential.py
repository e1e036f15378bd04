"""Identification's fast paths against plain ones, on lab-shaped recordings (:mod:`lab_inputs`).

* The exact Jacobian of a fit's residual (:meth:`_Problem.jac`: CVODES forward sensitivities through every kind
  of fit segment: straight lines between kinks, interpolated windows, held inputs restarted at their jumps,
  multiple-shooting windows, estimated initial states) against central differences of the residual itself
  (:meth:`_Problem.res`).
* A screening's ranking (loose fits on the leading part of the recording) against full fits of every hypothesis:
  on generated cases with a concealed effect, the screening's top candidate is among the full fits' best.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, reject, settings
from hypothesis import strategies as st
from lab_inputs import LabCase, lab_cases

import phs.workflows.identify.sensitivities as ident
from codegen import simulate
from phs.workflows.recording import Recording

pytestmark = [pytest.mark.filterwarnings("ignore::phs.errors.ParameterRangeWarning"),
              pytest.mark.filterwarnings("ignore::phs.errors.InputHoldWarning")]

EXAMPLES = [pytest.param(100, 80, id="default"), pytest.param(2000, 600, id="slow", marks=pytest.mark.slow)]
"""Examples per property and the most samples of a recording: 100 of up to 80 samples in the default suite, 2000
of up to 600 under ``-m slow``."""

FREE = {"rc": ["R.R", "C.C"], "rlc": ["R.R", "L.L", "C.C"], "msd": ["k.K", "b.b"], "msd2": ["k.K", "b.b", "m.m"],
        "duffing2": ["k", "k3", "b.b"]}
OUTPUTS = {"rc": ["v_C"], "rlc": ["C.Q", "U.i"], "msd": ["position"], "msd2": ["position", "F.v"],
           "duffing2": ["position"]}
RTOL = 1e-9
"""The fit's integration tolerance here (the truths of the screening cases are integrated to 1e-10 regardless)."""
FD_RTOL = 1e-11
"""The central differences' integration tolerance (and their absolute tolerance a hundredth of the fit's): they
divide the integration's error by their step, so at the fit's own :data:`RTOL` a column the recording hardly sees
carries that error times 1e4.  Measured on a generated RC fit (50 PRBS samples, the resistance's column 0.09 of the
capacitance's): the exact Jacobian at rtol 1e-9 against differences at 1e-9 disagreed by 0.038 in that column (0.055
at a step of 1e-5, 4.6e-3 at 1e-3: the differences' noise, falling with their step); against differences at 1e-11,
by 5.6e-5."""
FD_STEP = 1e-4
"""Central-difference step in the fit coordinates: of the parameters (ratios to their start or their logarithms), and
of the start states' excursion in the recording: truncation ~ FD_STEP² ~ 1e-8 of the curvature, integration noise
~ RTOL / FD_STEP ~ 1e-6."""
AGREE = 1e-2
"""Agreement asked of each column of the Jacobian with its central differences, relative to the larger of the column's
norm and 1e-3 of the Jacobian's largest column (a direction the recording hardly sees is compared on the scale of
those it sees).  The two are independent computations of one derivative; measured on 300 generated fits: up to
4.3e-3 with the differences at rtol 1e-9 where the integration's own error over the step dominates them (it falls to 6e-5
at rtol 1e-12 and a step of 1e-5, i.e. it is the differences' error; hence :data:`FD_RTOL`).  A seed of the wrong size,
a lost chain-rule term, a segment restarted from the wrong state or a window's start state seeded into the wrong columns are off by O(1)."""


def _truth(case: LabCase):
    return simulate(case.system, case.t, u=case.u, x0=case.x0, params=case.params, rtol=1e-10, atol=1e-16)


def _recording(case: LabCase, truth) -> Recording:
    """The case's truth on its grid (the outputs a lab would record), its inputs declared as delivered: an array's
    reading left to the recording (undeclared), the others declared ``linear`` or ``zoh``."""
    s = case.system
    signals = {n: case.inputs[n].values for n in s.input_names}
    signals.update({ch: np.asarray(truth[ch], dtype=float) for ch in OUTPUTS[case.model]})
    holds = {n: v.hold for n, v in case.inputs.items() if v.delivery != "grid"}
    return Recording.from_arrays(case.t, signals, holds=holds)


def _atol(case: LabCase, truth) -> float:
    """An absolute tolerance on the scaled states ``x / s`` of ``RTOL / 1000`` of the smallest state's excursion (in
    units of its scale ``s``): the generated time scales move some states by far less than their declared scale, and
    the default (``RTOL / 100``) would leave their integration error above what the central differences resolve."""
    scale = np.array([st.typical for st in case.system.states])
    size = np.max(np.abs(np.asarray(truth.x)), axis=0) / scale
    return float(max(RTOL * 1e-3 * np.min(np.maximum(size, 1e-9)), 1e-22))


@st.composite
def fit_problems(draw, max_samples: int = 200):
    """A generated recording and a fit of it: free parameters (some log-scaled), estimated initial states,
    multiple-shooting windows and the point ``z`` the Jacobian is taken at (away from the truth)."""
    case = draw(lab_cases(max_samples=max_samples, on_grid=True))
    free = FREE[case.model]
    log_scaled = [k for k in free if draw(st.booleans())]
    states = case.system.state_names
    estimate = [n for n in states if draw(st.booleans())]
    shooting = draw(st.integers(1, 3))
    offsets = [draw(st.floats(-0.2, 0.2)) for _ in range(len(free) + len(estimate) + len(states) * (shooting - 1))]
    return case, free, log_scaled, estimate, shooting, np.array(offsets)


def check_jacobian(case: LabCase, free, log_scaled, estimate, shooting, offsets) -> float:
    s = case.system
    truth = _truth(case)
    rec = _recording(case, truth)
    y = {ch: rec[ch] for ch in OUTPUTS[case.model]}
    weights = {ch: 1.0 / max(float(np.std(v)), 1e-300) for ch, v in y.items()}
    p_true = s.param_vector(case.params)
    x0 = np.array([case.x0.get(n, 0.0) for n in s.state_names])
    prob = ident._Problem(s, rec, free, log_scaled, OUTPUTS[case.model], weights, x0, estimate, RTOL, _atol(case, truth),
                          shooting=shooting, params=p_true)
    # z: each parameter 20 % off at most, the estimated states and the windows' start states off by up to 0.2 of
    # the states' excursion in the recording, from the truth
    X = np.column_stack([np.asarray(truth[n]) for n in s.state_names])
    excursion = np.max(np.abs(X), axis=0) / prob.scale
    th = np.where(prob.is_log, 0.0, 1.0) + offsets[: prob.n_theta]
    xi = (x0 / prob.scale)[prob.ixi] + offsets[prob.n_theta: prob.n_theta + prob.n_xi] * excursion[prob.ixi]
    starts = [X[e] / prob.scale + offsets[prob.n_theta + prob.n_xi + k * prob.nx:][:prob.nx] * excursion
              for k, e in enumerate(prob.ms_edges[1:-1])]
    z = np.concatenate([th, xi] + starts)
    try:
        r0 = prob.res(z)
    except RuntimeError:  # the plain path fails too (a stiff model driven off its course): nothing to compare
        reject()
    r, J = prob.jac(z)
    assert np.array_equal(r, r0)
    ref = ident._Problem(s, rec, free, log_scaled, OUTPUTS[case.model], weights, x0, estimate, FD_RTOL,
                         _atol(case, truth) * 1e-2, shooting=shooting, params=p_true)
    # steps of FD_STEP in the parameters' coordinates, and of FD_STEP of their excursion in the states'
    steps = FD_STEP * np.concatenate([np.ones(prob.n_theta), excursion[prob.ixi]] + [excursion] * (prob.K - 1))
    Jfd = np.column_stack([(ref.res(z + h * e) - ref.res(z - h * e)) / (2 * h) for h, e in zip(steps, np.eye(len(z)))])
    norms = np.linalg.norm(Jfd, axis=0)
    err = np.linalg.norm(J - Jfd, axis=0) / np.maximum(norms, 1e-3 * norms.max(initial=0.0) + 1e-300)
    assert np.all(err <= AGREE), (err, [sg.layout.size for sg in prob.segments])
    return float(err.max(initial=0.0))


JACOBIAN_EXAMPLES = [pytest.param(50, 80, id="default"), EXAMPLES[1]]
"""Half of :data:`EXAMPLES` in the default suite for the Jacobian's property: each example costs its central
differences (0.9 s, 90 s for a hundred); 2000 under ``-m slow`` as for the others."""


@pytest.mark.parametrize("n_examples, max_samples", JACOBIAN_EXAMPLES)
def test_exact_jacobian_agrees_with_central_differences(n_examples, max_samples):
    @settings(max_examples=n_examples)
    @given(fit_problems(max_samples))
    def agree(problem):
        check_jacobian(*problem)

    agree()


# -- screening against full fits ---------------------------------------------------------------------------------------
SCREEN_MARGIN = 0.05
"""A screening's top candidate counts among the full fits' best when its full fit is one of the two best, or leaves a
validation residual within this share of the best's (hypotheses that explain nothing tie with each other)."""


def _candidates():
    from components.candidates import AddedMass, CoulombFriction, CubicStiffness, Offset, QuadraticDrag

    return [CubicStiffness(), QuadraticDrag(), CoulombFriction(), Offset(), AddedMass()]


@st.composite
def concealed_cases(draw, max_samples: int = 800):
    """A recording of the two-force mass-spring-damper with a concealed effect: a cubic stiffness (the truth is the
    Duffing oscillator, its cubic term ``ratio`` times the linear one at the recording's largest deflection) or an
    offset of the measured position (``ratio`` of its range); 0.1 % noise."""
    case = draw(lab_cases(models=("msd2",), min_samples=400, max_samples=max_samples, on_grid=True))
    effect = draw(st.sampled_from(("cubic_stiffness", "offset")))
    ratio = draw(st.floats(0.05, 0.3))
    seed = draw(st.integers(0, 2**31))
    return case, effect, ratio, seed


def check_screening(case: LabCase, effect: str, ratio: float, seed: int):
    from lab_inputs import model

    from phs.workflows.diagnose import diagnose

    linear = _truth(case)
    y = np.asarray(linear["position"], dtype=float)
    if effect == "cubic_stiffness":
        K = case.params["k.K"]
        k3 = ratio * K / max(float(np.max(np.abs(y))), 1e-300) ** 2
        truth = simulate(model("duffing2"), case.t, u=case.u, x0={"m.p": case.x0["m.p"], "s.q": case.x0["k.l"]},
                         params={"k": K, "k3": k3, "b.b": case.params["b.b"]}, rtol=1e-10)
        y = np.asarray(truth["position"], dtype=float)
    else:
        y = y + ratio * np.ptp(y)
    y = y + 1e-3 * np.ptp(y) * np.random.default_rng(seed).standard_normal(len(y))
    signals = {n: case.inputs[n].values for n in ("F", "G")}
    holds = {n: v.hold for n, v in case.inputs.items() if v.delivery != "grid"}
    rec = Recording.from_arrays(case.t, {**signals, "position": y}, holds=holds)
    system = model("msd2").with_params(case.params)
    bounds = {k: (v / 10, v * 10) for k, v in case.params.items()}  # the drawn time scale, not the declared ranges
    runs = {}
    for top in (1, 0):  # the screening's pick refitted alone, and every hypothesis fitted to convergence
        d = diagnose(system, rec, free=["k.K", "b.b"], candidates=_candidates(), x0=case.x0, n_jobs=1, refit_top=top,
                     max_effects=1, discover=False, bounds=bounds)
        if d.effect == "model_cannot_describe":  # the concealed effect is too large for the model to start from
            reject()
        runs[top] = [h for h in d.hypotheses if h.ok]
    picked = [h.augmentation.effect for h in runs[1] if h.stage == "full"]
    full = sorted(runs[0], key=lambda h: h.validation_rss)
    assert picked and full
    best = full[0].validation_rss
    good = {h.augmentation.effect for h in full[:2]} | {h.augmentation.effect for h in full
                                                        if h.validation_rss <= best + SCREEN_MARGIN * abs(best)}
    assert picked[0] in good, (picked, [(h.augmentation.effect, h.validation_rss) for h in full])
    return picked[0], full[0].augmentation.effect


@pytest.mark.parametrize("n_examples", [pytest.param(1, id="default"), pytest.param(12, id="slow", marks=pytest.mark.slow)])
def test_screening_picks_one_of_the_full_fits_best(n_examples):
    @settings(max_examples=n_examples)
    @given(concealed_cases(max_samples=450 if n_examples == 1 else 2000))
    def among_best(drawn):
        check_screening(*drawn)

    among_best()
