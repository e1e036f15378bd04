"""Dimensional analysis of the whole structure (phs.structure_units): R, G, P, S, N, the ports and the measured
outputs against the states' and ports' units, each wrong entry named; check() fails on them."""

from __future__ import annotations

from dataclasses import replace

import pytest
import sympy as sp

from phs import InputInfo, Measured, Param, PHSystem, StateInfo
from phs.structure_units import structure_unit_problems
from systems.examples import mass_spring_damper, rc_circuit

q, p, F = sp.Symbol("q", real=True), sp.Symbol("p", real=True), sp.Symbol("F", real=True)
K, M, B = Param("k", 40.0, "N/m"), Param("m", 0.1, "kg"), Param("b", 0.5, "N*s/m")


def pushed_mass(G=None, output_unit="m/s", S=None, measured=(), extra=()) -> PHSystem:
    """Mass on a spring and a damper pushed by a force F [N] (output: its velocity [m/s])."""
    return PHSystem("pushed", [StateInfo("q", "m"), StateInfo("p", "kg*m/s", kind="I")],
                    H=K.symbol * q**2 / 2 + p**2 / (2 * M.symbol), J=[[0, 1], [-1, 0]], R=[[0, 0], [0, B.symbol]],
                    G=G if G is not None else [[0], [1]], S=S, inputs=[InputInfo("F", "N", "F.v", output_unit)],
                    params=[K, M, B, *extra], measured=measured)


def test_consistent_models_pass():
    assert structure_unit_problems(pushed_mass()) == ([], 0)
    assert structure_unit_problems(rc_circuit()) == ([], 0)


def test_damper_declared_in_newtons_is_named():
    """A damper's coefficient in N (instead of N*s/m): R[0,0] of the momentum is a force, not kg/s; check() fails
    naming the entry and the element, where it used to say the units pass."""
    msd = mass_spring_damper()
    bad = msd._replace(params=[replace(v, unit="N") if v.name == "b.b" else v for v in msd.params])
    item = bad.check()["units"]
    assert item.verdict == "fail"
    assert "R[0,0] (element 'b') is kg*m/s**2 (N), expected kg/s" in item.detail
    assert mass_spring_damper().check()["units"].verdict == "pass"


def test_input_map_with_a_wrong_dimension_is_named():
    """G[1,0] = c with c in 1/m: the force would enter the momentum's rate as N/m."""
    c = Param("c", 2.0, "1/m")
    problems, _ = structure_unit_problems(pushed_mass(G=[[0], [c.symbol]], extra=[c]))
    assert problems == ["G[1,0] (state 'p', input 'F') is 1/m, expected 1"]
    assert not pushed_mass(G=[[0], [c.symbol]], extra=[c]).check().ok


def test_port_that_is_not_power_conjugate_is_named():
    """A force whose output is declared in m (not m/s): y = G^T dH/dx is a velocity, and F*y is no power."""
    problems, _ = structure_unit_problems(pushed_mass(output_unit="m"))
    assert problems == ["port 'F': input unit 'N' times unit 'm' of its output 'F.v' is kg*m**2/s**2 (J), "
                        "not a power (W)"]


def test_feedthrough_and_measured_outputs_are_checked():
    """S[0,0] must be [y]/[u] = (m/s)/N = s/kg; a measured output must come out in its declared unit."""
    problems, _ = structure_unit_problems(pushed_mass(S=[[B.symbol]]))
    assert problems == ["S[0,0] is kg/s, expected s/kg"]
    good = Measured("v", p / M.symbol, "m/s")
    wrong = Measured("x", p / M.symbol, "m")
    via_port = Measured("v_port", sp.Symbol("F.v", real=True), "m/s")
    assert structure_unit_problems(pushed_mass(measured=[good, via_port])) == ([], 0)
    assert structure_unit_problems(pushed_mass(measured=[wrong]))[0] == ["measured output 'x' is m/s, expected m"]


def test_a_gain_baked_in_as_a_float_is_skipped_not_failed():
    """G[1,0] = 35.15 (a gain whose unit was never declared) may carry any unit: skipped and counted.
    An exact 2 is dimensionless and is still checked."""
    assert structure_unit_problems(pushed_mass(G=[[0], [35.15]])) == ([], 1)
    assert "skipped" in pushed_mass(G=[[0], [35.15]]).check()["units"].detail
    assert structure_unit_problems(pushed_mass(G=[[2], [0]]))[0] == ["G[0,0] (state 'q', input 'F') is 1, expected s/kg"]


@pytest.mark.parametrize("entry, words", [
    (B.symbol + K.symbol, "sum mixes dimensions"),
    (sp.exp(B.symbol), "argument of exp is not dimensionless"),
])
def test_entries_that_mix_dimensions_are_named(entry, words):
    problems, _ = structure_unit_problems(PHSystem(
        "pushed", [StateInfo("q", "m"), StateInfo("p", "kg*m/s", kind="I")], H=K.symbol * q**2 / 2 + p**2 / (2 * M.symbol),
        J=[[0, 1], [-1, 0]], R=[[0, 0], [0, entry]], params=[K, M, B]))
    assert len(problems) == 1 and problems[0].startswith("R[1,1]") and words in problems[0]
