"""Structural checks that always finish and never read a NaN as a pass (phs.checks, phs.storage_bound)."""

from __future__ import annotations

import json
import time

import pytest
import sympy as sp

import phs
from phs import PHSystem, StateInfo
from phs.errors import InputDataError, ModelError
from phs.workflows.cli import main
from systems.examples import rc_circuit

Q = "Symbol('C.Q', real=True)"
RR = "Symbol('R.R', positive=True)"


def _power_difference(first: int, second: int) -> str:
    """srepr of (C.Q + R.R + first)**120 - (C.Q + R.R + second)**120: inf - inf = nan in floating point."""
    return (f"Add(Pow(Add({Q}, {RR}, Integer({first})), Integer(120)), "
            f"Mul(Integer(-1), Pow(Add({Q}, {RR}, Integer({second})), Integer(120))))")


def _saved_rc(tmp_path, entry: str):
    """The RC circuit saved to JSON with its dissipation entry R[0,0] (and the resistor's form) replaced.  The
    charge's unit is left undeclared ("1"): the entry adds a charge to a resistance, which the constructor's unit
    check would refuse before the dissipation checks these tests are about."""
    path = tmp_path / "rc.json"
    rc_circuit().save(path)
    data = json.loads(path.read_text())
    data["states"][0]["unit"] = "1"
    data["matrices"]["R"] = f"ImmutableDenseMatrix([[{entry}]])"
    data["dissipators"][0]["entries"]["0,0"] = entry
    path.write_text(json.dumps(data))
    return path


def test_hostile_negative_dissipation_is_refused_fast(tmp_path, capsys):
    """R = (Q+R+1)**120 - (Q+R+2)**120 < 0 everywhere, NaN at every float sample: once taken for no evidence, then
    a hang in the symbolic minors.  Now refused by the loader and by ``phs passivity`` naming R[0,0] and the
    resistor (measured 0.1 s to load, 0.5 s for the command run in-process; 20 s leaves room for a loaded machine)."""
    path = _saved_rc(tmp_path, _power_difference(1, 2))
    t = time.perf_counter()
    with pytest.raises(InputDataError, match=r"R\[0,0\] \('R'\) is negative there \(evaluated with mpmath"):
        phs.load(path)
    assert time.perf_counter() - t < 20.0
    t = time.perf_counter()
    assert main(["passivity", str(path), "--box-samples", "64", "--starts", "1"]) == 2
    assert time.perf_counter() - t < 20.0
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "R[0,0] ('R') is negative" in err


def test_hostile_positive_dissipation_is_decided_by_sampling_and_says_so(tmp_path):
    """The same entry with the sign reversed (positive everywhere): the constructor accepts it, check() refuses the
    symbolic minors as over the budget and samples instead, with mpmath where floats overflow
    (measured 1.6 s for load + check; bound 20 s)."""
    t = time.perf_counter()
    system = phs.load(_saved_rc(tmp_path, _power_difference(2, 1)))
    item = system.check()["R positive semidefinite"]
    assert time.perf_counter() - t < 20.0
    assert item.verdict == "pass"
    assert "symbolic decision refused" in item.method and "over the symbolic budget" in item.method


def _rc_with_R(entry) -> PHSystem:
    rc = rc_circuit()
    return rc._replace(R=sp.Matrix([[entry]]), dissipators=())


def test_entry_undefined_at_some_points_is_undecided_not_pass():
    """R = 1/R.R where C.Q > 0, NaN elsewhere: about half of the sampled points say nothing, so the check is
    undecided and names the entry and how many points (a skipped NaN once made this a pass)."""
    rc = rc_circuit()
    q, r = rc.x[0], rc.param("R.R").symbol
    item = _rc_with_R(sp.Piecewise((1 / r, q > 0), (sp.nan, True))).check()["R positive semidefinite"]
    assert item.verdict == "undecided"
    assert "R[0,0] is not finite (even with mpmath)" in item.detail and "no evidence" in item.detail


def test_entry_undefined_everywhere_is_refused():
    rc = rc_circuit()
    q, r = rc.x[0], rc.param("R.R").symbol
    with pytest.raises(ModelError, match=r"dissipation entry R\[0,0\] is not finite at any of the 8 sampled points"):
        _rc_with_R(sp.Piecewise((1 / r, q > 1), (sp.nan, True)))


def test_skew_symmetry_over_budget_is_sampled_and_said():
    """J[0,1] = (q²+5q+6)**100, J[1,0] = -((q+2)(q+3))**100: skew, but the check would expand 5151 terms; the
    constructor compares them at sampled points and check() says so.  A J that is not skew is still refused."""
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    big = (q**2 + 5 * q + 6) ** 100
    osc = PHSystem("osc", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")], H=q**2 / 2 + p**2 / 2,
                   J=[[0, big], [-((q + 2) * (q + 3)) ** 100, 0]], R=[[0, 0], [0, 0]])
    item = osc.check()["J skew-symmetric"]
    assert item.method.startswith("sampled") and "over the symbolic budget" in item.detail
    with pytest.raises(ModelError, match="J is not skew-symmetric"):
        PHSystem("osc", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")], H=q**2 / 2 + p**2 / 2,
                 J=[[0, big], [big, 0]], R=[[0, 0], [0, 0]])


def test_energy_over_budget_is_minimised_over_the_box_and_said():
    """H = (q²+q+1)**60 - (q²+q)**60 + p²/2 (degree 118, bounded below): not expanded (1891-term price), minimised
    over the box instead and followed outward (measured 0.3 s; bound 20 s)."""
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    osc = PHSystem("osc", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")],
                   H=(q**2 + q + 1) ** 60 - (q**2 + q) ** 60 + p**2 / 2, J=[[0, 1], [-1, 0]], R=[[0, 0], [0, 0]])
    t = time.perf_counter()
    item = osc.check()["H bounded below"]
    assert time.perf_counter() - t < 20.0
    assert item.verdict == "pass" and "symbolic decision refused" in item.method


def test_skew_symmetry_undefined_at_every_sample_is_undecided_not_pass():
    """J[0,1] over the budget and undefined (NaN) wherever sampled: its skew symmetry is not decided, and check()
    says so instead of passing it."""
    q, p = sp.Symbol("q", real=True), sp.Symbol("p", real=True)
    big = sp.Piecewise(((q**2 + 5 * q + 6) ** 100, q > 5), (sp.nan, True))
    osc = PHSystem("osc", [StateInfo("q", range=(-1, 1)), StateInfo("p", kind="I")], H=q**2 / 2 + p**2 / 2,
                   J=[[0, big], [-sp.Piecewise((((q + 2) * (q + 3)) ** 100, q > 5), (sp.nan, True)), 0]],
                   R=[[0, 0], [0, 0]])
    item = osc.check()["J skew-symmetric"]
    assert item.verdict == "undecided" and "undefined at all 8 sampled points" in item.detail
