"""``phs passivity``: end-to-end certificates from the command line, and invalid options (phs.workflows.passivity_cli).

Exit status 0 means certified passive, 1 not certified passive, 2 an error naming the bad option; on an
error nothing is written.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from phs.workflows.cli import main

MSD = "systems.examples:mass_spring_damper"
RC = "systems.examples:rc_circuit"
SMALL = ["--samples", "64", "--starts", "2"]


def test_passive_model_with_every_test_json_and_report(tmp_path, capsys):
    out, report = tmp_path / "p.json", tmp_path / "report"
    code = main(["passivity", MSD, *SMALL, "--equilibrium", "F=2", "--input", "F=square(1.0, 2)", "--t-end", "1",
                 "--dt", "0.01", "--json", str(out), "--report", str(report)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "PASSIVE" in captured.out and "local" in captured.out
    doc = json.loads(out.read_text())
    assert doc["passive"] is True and doc["command"] == "passivity" and doc["model"] == MSD
    assert {k: v["verdict"] for k, v in doc["tests"].items()} == {
        "interconnection": "pass", "dissipation": "pass", "feedthrough": "pass", "storage": "pass",
        "trajectory": "pass", "local": "pass"}
    assert doc["tests"]["local"]["numbers"]["output_index"] == pytest.approx(0.4, rel=1e-6)
    assert doc["tests"]["local"]["worst"]["k.l"] == pytest.approx(0.5, rel=1e-9)
    assert doc["tests"]["trajectory"]["numbers"]["dissipated_by"]["b"] > 0
    names = set(os.listdir(report))
    assert {"report.html", "report.json", "report.txt", "dissipation.png", "storage.png", "trajectory.png",
            "local.png"} <= names
    assert (report / "trajectory.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_negative_resistance_exits_1_and_names_the_element(tmp_path, capsys):
    out = tmp_path / "p.json"
    code = main(["passivity", RC, *SMALL, "--param", "R.R=-1000", "--json", str(out)])
    captured = capsys.readouterr()
    assert code == 1, captured.err
    assert "NOT CERTIFIED PASSIVE" in captured.out and "element responsible: R" in captured.out
    doc = json.loads(out.read_text())
    assert doc["passive"] is False and doc["tests"]["dissipation"]["verdict"] == "fail"
    assert doc["params"]["R.R"] == -1000.0


def test_parameter_box_and_declared_range(tmp_path, capsys):
    out = tmp_path / "p.json"
    code = main(["passivity", MSD, *SMALL, "--box", "b.b=-0.1:1", "--box", "k.l=-0.2:0.2", "--json", str(out)])
    assert code == 1
    doc = json.loads(out.read_text())
    assert doc["box"]["b.b"] == [-0.1, 1.0] and doc["box"]["k.l"] == [-0.2, 0.2]
    assert doc["tests"]["dissipation"]["worst"]["b.b"] == pytest.approx(-0.1)
    capsys.readouterr()
    assert main(["passivity", MSD, *SMALL, "--box", "b.b"]) == 0  # the declared range of b.b is positive
    assert "parameters b.b" in capsys.readouterr().out


def test_recording_input_gives_the_time_grid(tmp_path, capsys):
    t = np.linspace(0.0, 0.5, 51)
    rows = ["time,force"] + [f"{a:.6g},{np.sin(20 * a):.6g}" for a in t]
    csv = tmp_path / "rec.csv"
    csv.write_text("\n".join(rows) + "\n")
    out = tmp_path / "p.json"
    code = main(["passivity", MSD, *SMALL, "--input", str(csv), "--time", "time", "--map", "force=F", "--json", str(out)])
    assert code == 0, capsys.readouterr().err
    traj = json.loads(out.read_text())["tests"]["trajectory"]
    assert traj["verdict"] == "pass" and traj["numbers"]["T"] == pytest.approx(0.5)


@pytest.mark.parametrize(("args", "words"), [
    (["--box", "k.l=1:0"], ["--box k.l=1:0", "lower bound 1 > upper bound 0"]),
    (["--box", "nope=0:1"], ["'nope'"]),
    (["--box", "k.l=0;1"], ["--box k.l=0;1", "LO:HI"]),
    (["--box", "k.l"], ["state 'k.l'", "LO:HI"]),
    (["--box", "k.l=0:inf"], ["finite"]),
    (["--box", "k.l=0:1", "--box", "k.l=0:2"], ["'k.l' is given twice"]),
    (["--equilibrium", "k.l=0.3", "--equilibrium", "F=2"], ["k.l=0.3", "not an equilibrium", "m.p"]),
    (["--equilibrium", "nope=1"], ["--equilibrium nope=1", "'nope'"]),
    (["--equilibrium", "F=abc"], ["--equilibrium F", "'abc'"]),
    (["--param", "nope=1"], ["'nope'"]),
    (["--x0", "nope=1"], ["--x0", "'nope'"]),
    (["--t-end", "1", "--dt", "2"], ["--dt 2 is larger than --t-end 1"]),
    (["--dt", "0.1"], ["--dt needs --t-end"]),
    (["--input", "F=1"], ["needs --t-end"]),
    (["--input", "F=sin(x)", "--t-end", "1", "--dt", "0.1"], ["--input F", "'x'"]),
    (["--samples", "0"], ["--samples"]),
])
def test_invalid_options_exit_2_naming_them_and_write_nothing(tmp_path, capsys, args, words):
    out, report = tmp_path / "p.json", tmp_path / "report"
    code = main(["passivity", MSD, *SMALL, *args, "--json", str(out), "--report", str(report)])
    err = capsys.readouterr().err
    assert code == 2
    for w in words:
        assert w in err, err
    assert not out.exists() and not report.exists()


def test_missing_output_directory_is_refused_before_any_work(tmp_path, capsys):
    code = main(["passivity", MSD, *SMALL, "--json", str(tmp_path / "missing" / "p.json")])
    assert code == 2 and "does not exist" in capsys.readouterr().err
