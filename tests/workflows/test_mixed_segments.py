"""A recording whose input has flat stretches beside curved ones: its fit is cut into segments of two kinds
(straight lines with the input's constants in the integrator's parameters, interpolated stretches without),
whose parameter vectors differ in size.  Each segment carries its own layout (codegen._layout.ParamLayout)."""

import numpy as np
import pytest

import phs.workflows.identify.sensitivities as ident
from codegen import simulate
from codegen._layout import ParamLayout
from phs.errors import SimulationError
from phs.workflows.identify import identify
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper


def _rest_then_sine():
    t = np.arange(0, 6, 1e-3)
    u = np.where(t < 2, 0.0, np.sin(6 * np.pi * t))
    y = simulate(mass_spring_damper().with_params({"k.K": 5.0, "b.b": 0.6}), t, u={"F": u})["position"]
    return Recording.from_arrays(t, {"F": u, "position": y})


def test_rest_then_sine_fits_to_the_truth():
    fit = identify(mass_spring_damper(), _rest_then_sine(), free=["k.K", "b.b"])
    # noise-free data from the same model at rtol 1e-8: the values agree far inside any reported interval
    assert fit.values["k.K"] == pytest.approx(5.0, rel=1e-6)
    assert fit.values["b.b"] == pytest.approx(0.6, rel=1e-6)


def test_both_segment_kinds_are_used_and_their_jacobian_matches_central_differences():
    rec = _rest_then_sine()
    s = mass_spring_damper()
    prob = ident._Problem(s, rec, ["k.K", "b.b"], ["b.b"], ["position"], {"position": 1.0 / np.std(rec["position"])},
                          np.zeros(2), ["m.p"], 1e-10, None)
    sizes = {sg.layout.size for sg in prob.segments}
    assert len(sizes) == 2, sizes  # lines (with the input's weight and constants) and interpolated stretches
    z = np.array([1.1, 0.1, 0.01])
    r, J = prob.jac(z)
    h = 1e-4
    Jfd = np.column_stack([(prob.res(z + h * e) - prob.res(z - h * e)) / (2 * h) for e in np.eye(len(z))])
    # central differences: truncation ~h^2 ~ 1e-8 and the integration error (rtol 1e-10) over h: 1e-6 relative;
    # a seed sized for the other segment kind or a lost chain-rule term is off by O(1)
    err = np.linalg.norm(J - Jfd, axis=0) / np.linalg.norm(Jfd, axis=0)
    assert np.all(err < 1e-4), err


def test_a_parameter_vector_of_the_wrong_layout_is_refused_by_name():
    lay = ParamLayout(2, (("slots", (2,)),))
    assert lay.size == 2 + 2 + 3
    lay.check(np.zeros(7), "here")
    with pytest.raises(SimulationError, match="segment 3: the integrator takes 7 parameters"):
        lay.check(np.zeros(4), "segment 3")


@pytest.mark.parametrize("t0", [1234.5, 1.7e9])
def test_a_recording_stamped_late_fits_like_one_from_zero(t0):
    """A logger's clock time (1.7e9 s is an epoch time, where a float resolves 2.4e-7 s of a 1 ms step): the runs
    count time from the grid's start, so the fit is that of the same recording from t = 0."""
    base = _rest_then_sine()
    late = Recording.from_arrays(t0 + base.t, base.signals)
    fits = [identify(mass_spring_damper(), rec, free=["k.K", "b.b"], shooting=3) for rec in (base, late)]
    # at 1234.5 s both are at the truth to the integration's tolerance (rtol 1e-8); at 1.7e9 s the stamps themselves
    # are rounded to 2.4e-7 s, 2.4e-4 of a step: the data were sampled at other instants than the floats say, which
    # moves the damping by 9e-6 of itself (1e-4 allowed); before the runs counted from the grid's start it failed
    rel = 1e-6 if t0 < 1e6 else 1e-4
    for k, v in (("k.K", 5.0), ("b.b", 0.6)):
        assert fits[0].values[k] == pytest.approx(v, rel=1e-6) and fits[1].values[k] == pytest.approx(v, rel=rel)
