"""Parameter values entering from outside go through one check: finite, of the declared sign (refused
otherwise, naming the parameter), inside the declared range (warned otherwise)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from codegen import simulate
from phs import ModelError, Param, ParameterError
from phs.errors import ParameterRangeWarning
from phs.workflows.cli import main
from systems.examples import mass_spring_damper, rc_circuit

RC = "systems.examples:rc_circuit"
MSD = "systems.examples:mass_spring_damper"


@pytest.mark.parametrize("make, name, value", [
    (rc_circuit, "C.C", -1e-6), (rc_circuit, "C.C", 0.0), (rc_circuit, "R.R", 0.0), (rc_circuit, "R.R", -1e3),
    (mass_spring_damper, "m.m", -1.0), (mass_spring_damper, "k.K", -1.0), (mass_spring_damper, "b.b", -0.1),
])
def test_a_value_of_the_wrong_sign_is_refused_at_every_door(make, name, value):
    system = make()
    for door in (lambda: system.with_params({name: value}), lambda: system.param_vector({name: value}),
                 lambda: simulate(system, np.linspace(0, 1e-3, 5), params={name: value})):
        with pytest.raises(ParameterError, match=f"'{name}'.*declared positive"):
            door()


@pytest.mark.parametrize("model, assignment", [(RC, "C.C=-1e-6"), (RC, "R.R=0"), (MSD, "m.m=-1"), (MSD, "k.K=-1")])
def test_the_command_line_refuses_it_in_one_line(tmp_path, capsys, model, assignment):
    out = tmp_path / "sim.csv"
    code = main(["simulate", model, "--t-end", "0.001", "--dt", "0.0001", "--param", assignment, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code != 0 and not out.exists()
    assert len(err.splitlines()) == 1 and assignment.split("=")[0] in err and "declared positive" in err, err


def test_construction_refuses_it_too():
    with pytest.raises(ModelError, match="'R'.*declared positive"):
        Param("R", -1.0, "Ohm", positive=True)
    with pytest.raises((ModelError, ValueError)):
        rc_circuit(C=-1e-6)


def test_a_value_outside_the_declared_range_warns_and_is_kept():
    with pytest.warns(ParameterRangeWarning, match=r"'R.R' = 1e\+09 is outside its declared range"):
        s = rc_circuit().with_params({"R.R": 1e9})
    assert s.param("R.R").value == 1e9
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc_circuit().with_params({"R.R": 2e3})                 # inside: silent


def test_the_passivity_what_if_still_reports_a_negative_resistance():
    """The certificate is the one place a wrong sign is let through on purpose, to show what it breaks."""
    from codegen.passivity import certify

    report = certify(rc_circuit(), params={"R.R": -1e3}, samples=16, starts=1)
    assert report["dissipation"].verdict == "fail" and not report.passive
