"""Integrator failures said in words (codegen._solver_errors): every SUNDIALS flag CasADi reports, and
CasADi's own failure words, become a message that says what happened, where (the interval, a state) and
what to try, with the flag only at the end in parentheses; real failures of the simulator, through the API
and the ``phs`` command, name the state that ran away or the parameter that made the model stiff."""

import re
import warnings

import numpy as np
import pytest
import sympy as sp

from codegen import Simulator, simulate
from codegen._solver_errors import CODES, describe, failure_code, in_words
from components import Damper, ForceSource, Mass, NonlinearSpring
from phs import Param, interconnect, series
from phs.errors import SimulationError
from phs.workflows.cli import main
from systems.examples import mass_spring_damper, rc_circuit


def _raw(code):
    """The text CasADi raises for a SUNDIALS flag (its C++ source lines included), or its own words."""
    if code[:3] == "CV_":
        return ("Error in Function::call for 'rc_rhs_cvodes1' [CvodesInterface] at .../casadi/core/function.cpp:1655:\n"
                f'.../casadi/interfaces/sundials/cvodes_interface.cpp:403: CVode returned "{code}". Consult CVODES documentation.')
    if code[:4] == "IDA_":
        return ("Error in Function::call for 'rc_rhs_idas1' [IdasInterface] at .../casadi/core/function.cpp:1655:\n"
                f'.../casadi/interfaces/sundials/idas_interface.cpp:592: IDASolve returned "{code}". Consult IDAS documentation.')
    return {"psetup": "Error in Function::call for 'F' [CvodesInterface] at .../casadi/core/function.cpp:1655:\n"
                      ".../casadi/interfaces/sundials/cvodes_interface.cpp:820: psetup failed: singular Jacobian",
            "max_num_steps": ".../casadi/interfaces/sundials/sundials_interface.cpp:377: the integrator exceeded "
                             "max_num_steps",
            "nan": "Error in Function::call for 'F' [CvodesInterface] at .../casadi/core/function.cpp:1655:\n"
                   ".../casadi/core/function_internal.hpp:1260: NaN detected in the integrator's right-hand side"}[code]


REQUESTED = [f"CV_{c}" for c in ("TOO_MUCH_WORK", "TOO_MUCH_ACC", "ERR_FAILURE", "CONV_FAILURE", "LINIT_FAIL", "LSETUP_FAIL",
                                 "LSOLVE_FAIL", "RHSFUNC_FAIL", "REPTD_RHSFUNC_ERR", "UNREC_RHSFUNC_ERR", "TOO_CLOSE", "ILL_INPUT")]
REQUESTED += [f"IDA_{c}" for c in ("TOO_MUCH_WORK", "TOO_MUCH_ACC", "ERR_FAIL", "CONV_FAIL", "LINIT_FAIL", "LSETUP_FAIL",
                                   "LSOLVE_FAIL", "RES_FAIL", "REP_RES_ERR", "ILL_INPUT", "CONSTR_FAIL", "FIRST_RES_FAIL")]
REQUESTED += ["psetup", "max_num_steps", "nan"]
#: what each kind of failure tells the user to change
ADVICE = {"work": "--dt", "accuracy": "--rtol", "error_test": "--rtol", "convergence": "--rtol", "linear": "ranges",
          "nonfinite": "ranges", "too_close": "--dt", "ill_input": "--rtol"}


def _clean(msg):
    assert "\n" not in msg
    for raw in ("cvodes_interface", "idas_interface", ".cpp", "Consult", "Function::call"):
        assert raw not in msg, msg


@pytest.mark.parametrize("code", REQUESTED)
def test_each_flag_is_said_in_words_with_the_time_a_state_and_what_to_try(code):
    assert failure_code(_raw(code)) == code and code in CODES
    rc = rc_circuit()
    msg = describe(RuntimeError(_raw(code)), rc, t0=0.5, t1=0.75, x=[2e-6], u=[1.0], p=rc.param_vector(), max_steps=500)
    _clean(msg)
    assert msg.startswith("simulation of 'rc': the integrator failed between t=0.5 and t=0.75: ")
    assert "at t=0.5: " in msg and "C.Q" in msg  # the state at the failure, by name
    assert ADVICE[CODES[code]] in msg
    label = code if code[:3] in ("CV_", "IDA") else f"CasADi: {'NaN or Inf in evaluation' if code == 'nan' else code}"
    assert msg.endswith(f"; {label + (' failed' if code == 'psetup' else '')})")  # the flag only at the end
    words = in_words(_raw(code))  # without the context (a fit's sensitivity run): still words
    _clean(words)
    assert "the integrator failed: " in words and words.endswith(f"{label + (' failed' if code == 'psetup' else '')})")


def test_text_without_a_raw_failure_is_left_alone():
    for text in ("parameter 'R.R' = -1 refused", "simulation of 'rc' left the validity domain at t=1"):
        assert in_words(text) == text and failure_code(text) is None


def test_too_much_work_over_a_billion_seconds_suggests_an_output_step_that_passes():
    t = np.linspace(0.0, 1e9, 1001)
    with pytest.raises(SimulationError) as err:
        simulate(rc_circuit(), t, u={"U": "sin(2*pi*50*t)"})
    msg = str(err.value)
    _clean(msg)
    assert "between t=0 and t=1e+06" in msg and "maximum number of internal steps (20000)" in msg and "C.Q" in msg
    # the fastest time constant is R C = 1 ms, printed as it is
    assert "fastest time constant there is 0.001 s against an output step of 1e+06 s" in msg
    dt = float(re.search(r"output interval\) of ([0-9.e+-]+) s or less", msg).group(1))
    # the step suggested is what the integrator managed from the failing state (here the start), so a run on
    # that grid passes: a wrong (too large) suggestion would fail here again
    res = simulate(rc_circuit(), np.arange(0.0, 4 * dt, dt), u={"U": "sin(2*pi*50*t)"})
    assert np.all(np.isfinite(res["C.Q"]))
    with pytest.raises(SimulationError, match="CV_TOO_MUCH_WORK"):  # and it is within a factor 4 of the limit
        simulate(rc_circuit(), np.array([0.0, 4 * dt]), u={"U": "sin(2*pi*50*t)"})


def test_the_command_says_it_in_one_line(tmp_path, capsys):
    out = tmp_path / "x.csv"
    code = main(["simulate", "systems.examples:rc_circuit", "--t-end", "1e9", "--input", "sin(2*pi*50*t)", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and not out.exists()
    assert len(err.splitlines()) == 1 and err.startswith("phs: error: simulation of 'rc': the integrator failed between t=0 ")
    _clean(err)
    assert "--dt" in err and "C.Q" in err and err.endswith("CV_TOO_MUCH_WORK)")


def _softening(k3=1.0):
    """A mass on a softening cubic spring (F = q - k3 q**3) with a damper: driven beyond the spring's
    barrier (F > 2 / (3 sqrt(3)) = 0.385 N) the mass escapes and the state blows up in finite time."""
    q = sp.Symbol("q", real=True)
    k3p = Param("k3", k3, "N/m**3", "cubic softening")
    return interconnect("soft", [ForceSource("F"), Mass("m", m=1.0), NonlinearSpring("s", force=q - k3p.symbol * q**3,
                                                                                      variable=q, params=[k3p]),
                                 Damper("b", b=0.1)], [series("F", "m", "s", "b")])


def test_a_blow_up_names_the_state_that_ran_away_and_when():
    s, t = _softening(), np.linspace(0.0, 10.0, 101)
    assert np.all(np.isfinite(simulate(s, t, u={"F": 0.1})["s.q"]))  # below the barrier it stays bounded
    with pytest.raises(SimulationError) as err:
        simulate(s, t, u={"F": 5.0})
    msg = str(err.value)
    _clean(msg)
    m = re.search(r"between t=([0-9.]+) and t=([0-9.]+) \(reached t=([0-9.]+)\)", msg)
    t0, t1, reached = map(float, m.groups())
    assert t1 - t0 == pytest.approx(0.1) and t0 <= reached < t1
    assert "s.q = " in msg and "is outside its range [-0.1, 0.1] m" in msg and "runs away" in msg
    assert "a finer --dt or another --rtol will not cure" in msg
    # the state named is the state of the run at the time named: integrated up to just before it, the
    # position is already more than 100 times its range, and within 1e-3 of it (rtol 1e-8, away from the pole)
    q_msg = float(re.search(r"s\.q = ([0-9.e+-]+) is outside", msg).group(1))
    q_run = simulate(s, np.array([0.0, t0, reached]), u={"F": 5.0})["s.q"][-1]
    assert q_msg > 10 and q_run == pytest.approx(q_msg, rel=1e-3)


def test_an_absurd_stiffness_is_named_with_the_time_constant_it_makes():
    msd = mass_spring_damper()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # k.K outside its declared range is warned of; that is the point
        with pytest.raises(SimulationError) as err:
            Simulator(msd).run(np.linspace(0.0, 100.0, 2001), u={"F": 1.0}, params={"k.K": 1e12})
    msg = str(err.value)
    _clean(msg)
    assert "between t=0 and t=0.05" in msg and "m.p" in msg
    assert "parameter k.K = 1e+12 is outside its range [0.4, 40]" in msg
    # sqrt(m / K) = 1e-6 s: the period the integrator must follow
    assert "fastest time constant there is 1e-06 s" in msg and "parameters outside their range brought back in" in msg
