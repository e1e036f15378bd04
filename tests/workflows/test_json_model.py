"""Every subcommand that takes a MODEL also takes a model saved as JSON (``PHSystem.save``), read
by the safe reader only: the same answers as from ``module:function``, and a file that is not a
saved model is refused in one line, running nothing."""

from __future__ import annotations

import json

import pytest

from phs.workflows.bundled import recording_path
from phs.workflows.cli import main
from phs.workflows.loader import load_model

MSD = "systems.examples:mass_spring_damper"


@pytest.fixture
def saved(tmp_path):
    path = tmp_path / "msd.json"
    load_model(MSD, {"k.K": 4.5}).save(path)
    return str(path)


def _out(capsys, argv):
    code = main(argv)
    return code, capsys.readouterr().out


def test_simulate_from_json_equals_simulate_from_module(saved, tmp_path, capsys):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", saved, "--t-end", "1", "--dt", "0.1", "--input", "0.1", "--out", str(a)]) == 0
    assert main(["simulate", MSD, "--param", "k.K=4.5", "--t-end", "1", "--dt", "0.1", "--input", "0.1",
                 "--out", str(b)]) == 0
    assert a.read_text() == b.read_text()


def test_param_overrides_apply_to_a_json_model(saved, tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", saved, "--param", "k.K=6", "--t-end", "1", "--input", "0.1", "--out", str(a)]) == 0
    assert main(["simulate", MSD, "--param", "k.K=6", "--t-end", "1", "--input", "0.1", "--out", str(b)]) == 0
    assert a.read_text() == b.read_text()


def test_fit_from_json(saved, capsys):
    args = [recording_path("msd_two_tone"), "--free", "k.K,b.b", "--quiet", "--max-iter", "20"]
    code_a, a = _out(capsys, ["fit", saved, *args])
    code_b, b = _out(capsys, ["fit", MSD, "--param", "k.K=4.5", *args])
    assert code_a == code_b == 0
    assert a.splitlines()[3:] == b.splitlines()[3:]  # the first lines name the MODEL and the time taken


def test_diagnose_from_json(saved, capsys):
    code, out = _out(capsys, ["diagnose", saved, recording_path("msd_two_tone"), "--free", "k.K,b.b", "--effects",
                              "coulomb_friction", "--jobs", "1", "--quiet"])
    assert code == 0 and "Diagnosis of 'msd'" in out


def test_passivity_from_json(saved, capsys):
    opts = ["--box-samples", "32", "--starts", "1"]
    code_a, a = _out(capsys, ["passivity", saved, *opts])
    code_b, b = _out(capsys, ["passivity", MSD, "--param", "k.K=4.5", *opts])
    assert code_a == code_b == 0
    assert a == b


def test_control_from_json(saved, capsys):
    opts = ["--target", "position=0.5", "--stiffness", "k.l=6", "--damping", "2", "--rays", "8", "--simulations", "2"]
    code, out = _out(capsys, ["control", saved, *opts])
    assert code == 0 and "IDA-PBC controller for 'msd'" in out


def test_sweep_from_json(saved, tmp_path, capsys):
    out = tmp_path / "s.csv"
    code = main(["sweep", saved, "--range", "b.b=0.2:0.4:2", "--metric", "final:position", "--t-end", "0.5",
                 "--input", "0.1", "--out", str(out), "--quiet", "--threads", "1"])
    assert code == 0 and len(out.read_text().splitlines()) == 3


def test_a_json_model_is_data_never_code(saved, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    doc = json.loads(open(saved).read())
    doc["energy"][0]["expr"] = "__import__('os').system('touch pwned')"
    evil = tmp_path / "evil.json"
    evil.write_text(json.dumps(doc))
    assert main(["simulate", str(evil), "--t-end", "1", "--out", "r.csv"]) == 2
    err = capsys.readouterr().err
    assert "evil.json" in err and err.count("\n") == 1
    assert not (tmp_path / "pwned").exists() and not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("content, words", [
    (None, ["does not exist"]),
    ("not json", ["not a readable saved model"]),
    ('{"format": "something else"}', ["not a readable saved model"]),
])
def test_unreadable_json_models_exit_2_naming_the_file(tmp_path, capsys, content, words):
    path = tmp_path / "m.json"
    if content is not None:
        path.write_text(content)
    assert main(["passivity", str(path)]) == 2
    err = capsys.readouterr().err
    assert "m.json" in err
    for w in words:
        assert w in err, err
