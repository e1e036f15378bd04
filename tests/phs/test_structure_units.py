"""Dimensional analysis of the whole structure (phs.structure_units): R, G, P, S, N, the ports and the measured
outputs against the states' and ports' units, each wrong entry named.  Where the declared units decide it, the
constructor refuses the model (ModelError, one line per entry: the entry, its unit, the expected one); what they
cannot decide (an undeclared unit, a float gain, an unreadable unit) builds and is left to check()."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
import sympy as sp

import phs
from phs import InputInfo, Measured, Param, PHSystem, StateInfo
from phs.errors import InputDataError, ModelError
from phs.structure_units import construction_problems, structure_unit_problems
from systems.examples import mass_spring_damper, rc_circuit

q, p, F = sp.Symbol("q", real=True), sp.Symbol("p", real=True), sp.Symbol("F", real=True)
K, M, B = Param("k", 40.0, "N/m"), Param("m", 0.1, "kg"), Param("b", 0.5, "N*s/m")


def pushed_mass(G=None, output_unit="m/s", S=None, measured=(), extra=(), R=None, damper=B) -> PHSystem:
    """Mass on a spring and a damper pushed by a force F [N] (output: its velocity [m/s])."""
    return PHSystem("pushed", [StateInfo("q", "m"), StateInfo("p", "kg*m/s", kind="I")],
                    H=K.symbol * q**2 / 2 + p**2 / (2 * M.symbol), J=[[0, 1], [-1, 0]],
                    R=R if R is not None else [[0, 0], [0, damper.symbol]], G=G if G is not None else [[0], [1]], S=S,
                    inputs=[InputInfo("F", "N", "F.v", output_unit)], params=[K, M, damper, *extra], measured=measured)


def refused(build) -> list[str]:
    """The problems of the ModelError that building raises (after checking it is the constructor's)."""
    with pytest.raises(ModelError) as info:
        build()
    assert str(info.value).startswith("invalid port-Hamiltonian system 'pushed'")
    return list(info.value.problems)


def test_consistent_models_pass():
    assert structure_unit_problems(pushed_mass()) == ([], 0)
    assert structure_unit_problems(rc_circuit()) == ([], 0)
    assert construction_problems(pushed_mass()) == []


def test_damper_declared_in_newtons_is_refused_when_built():
    """A damper's coefficient in N (instead of N*s/m): R[0,0] of the momentum is a force, not kg/s.  The
    constructor refuses it in one line naming the entry, the element, its unit and the expected one."""
    msd = mass_spring_damper()
    with pytest.raises(ModelError) as info:
        msd._replace(params=[replace(v, unit="N") if v.name == "b.b" else v for v in msd.params])
    assert info.value.problems == ("R[0,0] (element 'b') is kg*m/s**2 (N), expected kg/s",)
    assert mass_spring_damper().check()["units"].verdict == "pass"


def test_a_saved_model_with_a_wrong_unit_is_refused_by_load(tmp_path):
    """The same damper in a saved model's file: phs.load refuses it (bad input), naming the file and the entry."""
    path = tmp_path / "msd.json"
    mass_spring_damper().save(path)
    data = json.loads(path.read_text())
    for par in data["params"]:
        if par["name"] == "b.b":
            par["unit"] = "N"
    path.write_text(json.dumps(data))
    with pytest.raises(InputDataError) as info:
        phs.load(path)
    assert "msd.json" in str(info.value) and "R[0,0] (element 'b') is kg*m/s**2 (N), expected kg/s" in str(info.value)


def test_input_map_with_a_wrong_dimension_is_refused():
    """G[1,0] = c with c in 1/m: the force would enter the momentum's rate as N/m."""
    c = Param("c", 2.0, "1/m")
    assert refused(lambda: pushed_mass(G=[[0], [c.symbol]], extra=[c])) == [
        "G[1,0] (state 'p', input 'F') is 1/m, expected 1"]


def test_port_that_is_not_power_conjugate_is_refused():
    """A force whose output is declared in m (not m/s): y = G^T dH/dx is a velocity, and F*y is no power."""
    assert refused(lambda: pushed_mass(output_unit="m")) == [
        "port 'F': input unit 'N' times unit 'm' of its output 'F.v' is kg*m**2/s**2 (J), not a power (W)"]


def test_feedthrough_and_measured_outputs_are_checked():
    """S[0,0] must be [y]/[u] = (m/s)/N = s/kg; a measured output must come out in its declared unit."""
    assert refused(lambda: pushed_mass(S=[[B.symbol]])) == ["S[0,0] is kg/s, expected s/kg"]
    good = Measured("v", p / M.symbol, "m/s")
    wrong = Measured("x", p / M.symbol, "m")
    via_port = Measured("v_port", sp.Symbol("F.v", real=True), "m/s")
    assert structure_unit_problems(pushed_mass(measured=[good, via_port])) == ([], 0)
    assert refused(lambda: pushed_mass(measured=[wrong])) == ["measured output 'x' is m/s, expected m"]


def test_every_wrong_entry_is_named_in_one_error():
    """Two wrong entries (the damper in N, a measured output in m): one ModelError, a line each."""
    b_in_newtons = Param("b", 0.5, "N")
    assert refused(lambda: pushed_mass(damper=b_in_newtons, measured=[Measured("x", p / M.symbol, "m")])) == [
        "R[1,1] is kg*m/s**2 (N), expected kg/s", "measured output 'x' is m/s, expected m"]


def test_a_gain_baked_in_as_a_float_is_skipped_not_failed():
    """G[1,0] = 35.15 (a gain whose unit was never declared) may carry any unit: skipped and counted.
    An exact 2 is dimensionless and is still decided."""
    assert structure_unit_problems(pushed_mass(G=[[0], [35.15]])) == ([], 1)
    assert "skipped" in pushed_mass(G=[[0], [35.15]]).check()["units"].detail
    assert refused(lambda: pushed_mass(G=[[2], [0]])) == ["G[0,0] (state 'q', input 'F') is 1, expected s/kg"]


def test_what_the_declared_units_cannot_decide_builds_and_is_left_to_check():
    """A damper whose unit was left at the default "1" (dimensionless or undeclared: the constructor cannot
    tell) builds; check() takes it as dimensionless and fails it, as before.  A state left at "1" skips its
    entries in both; an unreadable unit builds and check() names it."""
    undeclared = Param("b", 0.5)
    system = pushed_mass(damper=undeclared)
    assert construction_problems(system) == []
    assert structure_unit_problems(system, declared_only=True) == ([], 1)
    assert structure_unit_problems(system)[0] == ["R[1,1] is 1, expected kg/s"]
    item = system.check()["units"]
    assert item.verdict == "fail" and "R[1,1] is 1, expected kg/s" in item.detail
    free_state = PHSystem("free", [StateInfo("q"), StateInfo("p", "kg*m/s", kind="I")], H=q**2 / 2 + p**2 / (2 * M.symbol),
                          J=[[0, 1], [-1, 0]], R=[[0, 0], [0, B.symbol]], params=[M, B])
    assert structure_unit_problems(free_state) == ([], 2)  # J[0,1], J[1,0] rest on the undeclared state
    unreadable = pushed_mass(damper=Param("b", 0.5, "furlong/fortnight"))
    assert construction_problems(unreadable) == []
    units = unreadable.check()["units"]
    assert units.verdict == "fail" and "parameter 'b'" in units.detail and "furlong" in units.detail


@pytest.mark.parametrize("entry, words", [
    (B.symbol + K.symbol, "sum mixes dimensions"),
    (sp.exp(B.symbol), "argument of exp is not dimensionless"),
])
def test_entries_that_mix_dimensions_are_refused(entry, words):
    (problem,) = refused(lambda: pushed_mass(R=[[0, 0], [0, entry]]))
    assert problem.startswith("R[1,1]") and words in problem


def test_a_structure_that_passed_is_not_analysed_again(monkeypatch):
    """with_params (other values, same structure and units: fits and diagnoses rebuild models so in their loops)
    is served by the remembered verdict; a changed unit is analysed, and refused."""
    import phs.structure_units as su

    calls = []
    analyse = su.structure_unit_problems
    monkeypatch.setattr(su, "structure_unit_problems", lambda *a, **k: calls.append(1) or analyse(*a, **k))
    system = pushed_mass()
    first = len(calls)  # 0 when an equal structure passed before (in another test), else 1
    system.with_params(b=0.7).with_params(k=12.0)
    assert len(calls) == first and first <= 1
    with pytest.raises(ModelError):
        system._replace(params=[K, M, Param("b", 0.5, "N")])
    assert len(calls) == first + 1


def test_a_zero_or_undefined_branch_takes_the_unit_of_the_other():
    """A damper acting only while q > 0 (Piecewise with a 0 branch), one clipped by Max(0, ...), one undefined
    (NaN) elsewhere: 0 and NaN carry no unit of their own, so these build; a branch in another unit does not."""
    for entry in (sp.Piecewise((B.symbol, q > 0), (0, True)), sp.Max(0, B.symbol * sp.sign(q)),
                  sp.Piecewise((B.symbol, q > 0), (sp.nan, True))):
        assert construction_problems(pushed_mass(R=[[0, 0], [0, entry]])) == []
    (problem,) = refused(lambda: pushed_mass(R=[[0, 0], [0, sp.Piecewise((B.symbol, q > 0), (K.symbol, True))]]))
    assert problem.startswith("R[1,1]") and "branches of a piecewise expression differ in dimension" in problem


def test_a_float_exponent_that_is_a_simple_fraction_is_that_fraction():
    """Friction laws written with floats leave powers such as (4.0 p**2 + v_s**2)**-0.5 (sympy keeps the float
    exponent): -0.5 is the square root's -1/2, not a power the constructor cannot read."""
    v_s = Param("v_s", 0.01, "m/s")
    entry = B.symbol * v_s.symbol * (4.0 * p**2 / M.symbol**2 + v_s.symbol**2) ** -0.5
    assert construction_problems(pushed_mass(R=[[0, 0], [0, entry]], extra=[v_s])) == []
