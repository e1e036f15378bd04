"""The diagnosis prints every change of a validation residual with its sign as it is: a rival whose residual
rose is printed with "+" and said to have risen, one whose residual fell with "−" and said to have fallen
(the explanation, the summary, the HTML table, the pre-sliding note); and a hypothesis whose fit failed in
the integrator is reported in words, in the summary and in the JSON, not with CasADi's C++ source."""

import json
import math
from types import SimpleNamespace

import numpy as np

from phs.workflows.diagnose.hypotheses import Scored
from phs.workflows.diagnose.report import explanation, residual_change
from phs.workflows.diagnose.result import Diagnosis, _verdict
from phs.workflows.diagnose.retry import FitFailed, fit_with_retries, reason

RAW = ("Error in Function::call for 'msd_rhs_cvodes1' [CvodesInterface] at .../casadi/core/function.cpp:1655:\n"
       '.../casadi/interfaces/sundials/cvodes_interface.cpp:403: CVode returned "CV_REPTD_RHSFUNC_ERR". '
       "Consult CVODES documentation.")


def _scored(label, validation_rss, bic, effect="cubic_stiffness", place="k.l", error=""):
    aug = SimpleNamespace(effect=effect, attached_to=place, component="CubicSpring", summary="", free=[], element=None)
    return Scored(label, None, {}, np.zeros(2), 1, {"position": 90.0}, {"position": 80.0}, 1.0, validation_rss, bic,
                  {}, {}, 0.1, aug, error=error)


NOMINAL = Scored("nominal", None, {}, np.zeros(2), 3, {"position": 90.0}, {"position": 80.0}, 1.0, 1.0, 100.0, {}, {}, 0.1)
ROSE = _scored("cubic_stiffness@k.l", 1.02, 105.0)                              # validation residual 2 % higher
FELL = _scored("quadratic_drag@m.p", 0.847, 99.0, effect="quadratic_drag", place="m.p")  # 15.3 % lower


def test_the_change_is_printed_with_its_own_sign():
    assert residual_change(-0.02) == "+2.0 % (rose)"
    assert residual_change(0.153) == "−15.3 % (fell)"
    assert residual_change(0.0) == residual_change(1e-5) == "0.0 % (unchanged)"


def test_a_rival_that_rose_and_one_that_fell_in_the_explanation():
    text = explanation(NOMINAL, [], [], ROSE, ["position"])  # nothing accepted: the best is reported
    assert "validation residual +2.0 % (rose)" in text and "-2.0" not in text and "−2.0" not in text
    text = explanation(NOMINAL, [], [], FELL, ["position"])
    assert "validation residual −15.3 % (fell)" in text and "+15.3" not in text
    accepted = _scored("coulomb_friction@m.p", 0.5, 50.0, effect="coulomb_friction", place="m.p")
    text = explanation(NOMINAL, [accepted], [], ROSE, ["position"])
    assert "Next best explanation: cubic_stiffness at k.l; its validation residual +2.0 % (rose)." in text


def _diagnosis(hyps, accepted=(), failed=()):
    v = _verdict(NOMINAL, list(accepted), hyps, [], ["position"], failed=list(failed))
    system = SimpleNamespace(name="msd", model_hash=lambda: "0" * 8)
    final = SimpleNamespace(fit_percent={"position": 90.0}, validation_fit_percent={"position": 80.0}, values={},
                            element_values={}, system=SimpleNamespace(check=lambda: SimpleNamespace(ok=True)))
    return Diagnosis(system, ["position"], NOMINAL, [], hyps, list(accepted), final, v, {}, 1.0)


def test_the_summary_and_the_html_table_carry_the_sign():
    d = _diagnosis([FELL, ROSE])
    lines = {ln.split()[0]: ln for ln in d.summary().splitlines() if "@" in ln}
    assert "validation residual −15.3 % (fell)" in lines["quadratic_drag@m.p"]
    assert "validation residual +2.0 % (rose)" in lines["cubic_stiffness@k.l"]
    page = d._repr_html_()
    assert "+2.0 % (rose)" in page and "−15.3 % (fell)" in page and "gain %" not in page


def test_a_fit_failing_in_the_integrator_is_reported_in_words():
    def fit_one(start, bounds):
        raise RuntimeError(RAW)

    try:
        fit_with_retries(fit_one, [{}], neutral={"a": 1e-3}, target={"a": 1.0}, bounds={"a": (1e-3, 1e3)})
    except FitFailed as exc:
        error = str(exc)
    assert error == reason(RuntimeError(RAW)) + " (and 3 retries failed)"
    failed = _scored("cubic_stiffness@k.l", math.inf, math.inf, error=error)
    d = _diagnosis([FELL, failed], failed=[failed])
    record = json.dumps(d.verdict, ensure_ascii=False)  # the verdict as the JSON holds it
    for text in (d.summary(), record, d.verdict["explanation"]):
        assert "cvodes_interface" not in text and "Consult" not in text and ".cpp" not in text
        assert "the model's equations gave NaN or Inf at the states it tried, at parameter values the fit tried" in text
    assert d.verdict["failed"][0]["error"].endswith("(CV_REPTD_RHSFUNC_ERR) (and 3 retries failed)")
