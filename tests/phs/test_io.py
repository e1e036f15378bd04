"""Saving and loading systems as JSON (phs.io)."""

from __future__ import annotations

import json
import os

import pytest
import sympy as sp

from phs import InputDataError, PHSystem
from phs import load as load_system
from phs.io import FORMAT_VERSION, parse_srepr, save_system
from systems.examples import duffing_oscillator, mass_spring_damper, rc_circuit, rlc_circuit

EXAMPLES = [rc_circuit, mass_spring_damper, duffing_oscillator, rlc_circuit]


@pytest.mark.parametrize("build", EXAMPLES, ids=lambda f: f.__name__)
def test_round_trip(build, tmp_path):
    s = build()
    path = tmp_path / f"{s.name}.json"
    s.save(path)
    r = PHSystem.load(path)
    assert isinstance(r, PHSystem)
    assert r.name == s.name and r.description == s.description
    assert sp.simplify(r.H - s.H) == 0 and r.H == s.H
    for k in ("J", "R", "G", "P", "S", "N"):
        assert getattr(r, k) == getattr(s, k), k
    assert r.param_values() == s.param_values()
    assert r.params == s.params
    assert r.states == s.states and r.inputs == s.inputs
    assert r.measured == s.measured
    assert r.conditions == s.conditions
    assert r.dissipators == s.dissipators
    assert r.structure == s.structure
    assert r.energy_terms == s.energy_terms
    assert r.model_hash() == s.model_hash()
    assert [str(e) for e in r.dynamics] == [str(e) for e in s.dynamics]


def test_symbol_assumptions_survive(tmp_path):
    s = rc_circuit()
    s.save(tmp_path / "rc.json")
    r = load_system(tmp_path / "rc.json")
    (C,) = [x for x in r.H.free_symbols if x.name == "C.C"]
    assert C.is_positive
    assert r.x[0].is_real


def test_with_params_values_survive(tmp_path):
    s = mass_spring_damper().with_params({"k.K": 7.5, "b.b": 0.125})
    save_system(s, tmp_path / "msd.json")
    r = load_system(tmp_path / "msd.json")
    assert r.param("k.K").value == 7.5 and r.param("b.b").value == 0.125
    assert r.param("k.K").unit == "N/m" and r.param("k.K").description == s.param("k.K").description
    assert r.param("k.K").range == s.param("k.K").range


def test_file_is_readable_json(tmp_path):
    path = tmp_path / "rc.json"
    rc_circuit().save(path)
    data = json.loads(path.read_text())
    assert data["version"] == FORMAT_VERSION
    assert data["params"][0] == {"name": "R.R", "value": 1000.0, "unit": "Ohm", "description": "resistance",
                                 "range": [100.0, 10000.0], "positive": True}
    assert data["dissipators"][0]["label"] == "R" and "0,1" in data["dissipators"][0]["entries"]


def test_save_is_atomic_and_leaves_nothing_behind(tmp_path):
    path = tmp_path / "rc.json"
    rc_circuit().save(path)
    duffing_oscillator().save(path)  # overwrite in place
    assert os.listdir(tmp_path) == ["rc.json"]
    assert load_system(path).name == "duffing"


def test_save_into_missing_directory(tmp_path):
    target = tmp_path / "nope" / "rc.json"
    with pytest.raises(InputDataError, match="does not exist"):
        rc_circuit().save(target)
    assert not (tmp_path / "nope").exists()


def test_save_failure_leaves_no_file(tmp_path, monkeypatch):
    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(RuntimeError):
        rc_circuit().save(tmp_path / "rc.json")
    assert os.listdir(tmp_path) == []


def _saved(tmp_path) -> dict:
    path = tmp_path / "rc.json"
    rc_circuit().save(path)
    return json.loads(path.read_text())


def _corrupt_version(d):
    d["version"] = 99


def _corrupt_format(d):
    d["format"] = "something else"


def _missing_states(d):
    del d["states"]


def _bad_expression(d):
    d["energy"][0]["expr"] = "__import__('os').system('true')"


def _unknown_name(d):
    d["energy"][0]["expr"] = "open('x')"


def _attribute_access(d):
    d["energy"][0]["expr"] = "Symbol.__class__"


def _not_a_matrix(d):
    d["matrices"]["J"] = "Integer(1)"


def _invalid_model(d):
    d["matrices"]["J"] = "MutableDenseMatrix([[Integer(1)]])"


def _bad_dissipator_key(d):
    d["dissipators"][0]["entries"] = {"zero": "Integer(0)"}


def _unknown_symbol(d):
    d["energy"][0]["expr"] = "Symbol('Z', real=True)"


@pytest.mark.parametrize(
    "corrupt, culprit",
    [
        (_corrupt_version, "version 99"),
        (_corrupt_format, "format"),
        (_missing_states, "states"),
        (_bad_expression, "energy 'C'"),
        (_unknown_name, "open"),
        (_attribute_access, "Attribute"),
        (_not_a_matrix, "matrix J"),
        (_invalid_model, "skew"),
        (_bad_dissipator_key, "'zero'"),
        (_unknown_symbol, "'Z'"),
    ],
    ids=lambda v: getattr(v, "__name__", v),
)
def test_corrupt_files_are_refused(tmp_path, corrupt, culprit):
    data = _saved(tmp_path)
    corrupt(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputDataError) as info:
        load_system(path)
    msg = str(info.value)
    assert str(path) in msg
    assert culprit in msg


def test_missing_file(tmp_path):
    with pytest.raises(InputDataError, match="does not exist") as info:
        load_system(tmp_path / "absent.json")
    assert "absent.json" in str(info.value)


@pytest.mark.parametrize("text, culprit", [("{not json", "not valid JSON"), ("[1, 2]", "JSON object"), ("", "JSON")])
def test_not_json(tmp_path, text, culprit):
    path = tmp_path / "broken.json"
    path.write_text(text)
    with pytest.raises(InputDataError, match=culprit) as info:
        load_system(path)
    assert "broken.json" in str(info.value)


def test_parse_srepr_rejects_code():
    with pytest.raises(InputDataError, match="unknown name"):
        parse_srepr("eval('1')")
    with pytest.raises(InputDataError, match="not allowed"):
        parse_srepr("Integer(1) + Integer(2)")
    x = sp.Symbol("seg1.theta", real=True)
    e = sp.Piecewise((sp.asin(x), x > 0), (0, True)) + sp.Float("1e-300") * sp.erf(x)
    assert parse_srepr(sp.srepr(e)) == e


def test_hand_built_system_with_structure_and_conditions(tmp_path):
    from phs import Condition, Param, StateInfo

    q = sp.Symbol("q", real=True)
    L = Param("L", 0.5, "m", "length")
    s = PHSystem("pend", [StateInfo("q", "rad", (-1.0, 1.0))], L.symbol * (1 - sp.cos(q)), [[0]], [[0]],
                 params=[L], conditions=[Condition("small angle", 1 - q**2, "|q| <= 1")],
                 structure={"note": "hand-built", "gain": 2 * L.symbol, "levels": [1, 2.5, None]})
    s.save(tmp_path / "pend.json")
    r = load_system(tmp_path / "pend.json")
    assert r.structure == s.structure
    assert r.conditions == s.conditions and r.H == s.H


def _every_system():
    import inspect

    import systems
    from systems import lab

    found = {name: getattr(systems, name) for name in systems.MODELS}
    found.update({name: f for name, f in vars(lab).items() if inspect.isfunction(f) and f.__module__ == lab.__name__
                  and not name.startswith("_")})
    return found


@pytest.mark.parametrize("build", list(_every_system().values()), ids=list(_every_system()))
def test_every_system_round_trips_through_the_safe_reader(build, tmp_path):
    """Each model of systems/ saved and loaded again: same hash, same expressions, same units and structure."""
    s = build()
    s.save(tmp_path / "m.json")
    r = PHSystem.load(tmp_path / "m.json")
    assert r.model_hash() == s.model_hash()
    assert r.energy_terms == s.energy_terms and all(getattr(r, k) == getattr(s, k) for k in ("J", "R", "G", "P", "S", "N"))
    assert r.measured == s.measured and r.conditions == s.conditions and r.definitions == s.definitions
    assert r.params == s.params and r.states == s.states and r.inputs == s.inputs and r.structure == s.structure


def test_field_paths_name_the_culprit(tmp_path):
    data = _saved(tmp_path)
    data["matrices"]["J"] = "MutableDenseMatrix([[sin('x')]])"
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputDataError, match=r"matrices\.J \(matrix J\): sin\(\) takes expressions"):
        load_system(path)
    data = _saved(tmp_path)
    data["params"][1]["unit"] = "furlong"
    path.write_text(json.dumps(data))
    with pytest.raises(InputDataError, match=r"params\[1\]\.unit: unknown unit 'furlong'"):
        load_system(path)
