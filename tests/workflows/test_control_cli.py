"""``phs control``: IDA-PBC design from the command line (phs.workflows.control_cli)."""

from __future__ import annotations

import json

import pytest

from phs.workflows.cli import main

MSD = "systems.examples:mass_spring_damper"
REST = [arg for i in range(1, 5) for arg in ("--x0", f"seg{i}.l_p=0.015")]


def test_mass_spring_design_writes_report_json_and_c(tmp_path, capsys):
    rc = main(["control", MSD, "--target", "position=0.5", "--stiffness", "k.l=6", "--damping", "2", "--t-end", "10",
               "--rays", "8", "--simulations", "2", "--json", str(tmp_path / "c.json"), "--report", str(tmp_path / "rep"),
               "--export-c", str(tmp_path / "c")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "target: position = 0.5 m; equilibrium input F = 2 N" in out
    assert "all passed" in out and "position: final 0.5" in out
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["controller"]["u_star"] == {"F": pytest.approx(2.0)}
    assert doc["controller"]["structure"]["coefficients"]["(k.l - *)^2/2"] == pytest.approx(6.0)
    assert doc["certificates"]["passed"] is True
    assert doc["closed_loop"]["final"]["position"] == pytest.approx(0.5, abs=1e-4)
    assert sorted(p.name for p in (tmp_path / "rep").iterdir()) == ["certificates.json", "closed_loop.csv",
                                                                      "closed_loop.png", "controller.txt"]
    assert (tmp_path / "rep" / "closed_loop.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["msd_controller.c", "msd_controller.h"]


def test_curling_hasel_tip_with_integral_action_and_mismatch(tmp_path, capsys):
    rc = main(["control", "systems.curling_hasel:curling_hasel", "--target", "tip=0.03", *REST, "--neglect", "seg*.Q1",
               "--integral", "output", "--t-end", "60", "--plant-param", "K_b=0.044", "--rays", "8", "--simulations", "2",
               "--json", str(tmp_path / "h.json")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "without seg1.Q1, seg2.Q1, seg3.Q1, seg4.Q1" in out
    doc = json.loads((tmp_path / "h.json").read_text())
    assert doc["closed_loop"]["plant_params"] == {"K_b": 0.044}
    # the integral of the tip error holds 30 mm on the plant with the drift branch and a stiffer film (1e-3 relative)
    assert doc["closed_loop"]["final"]["tip"] == pytest.approx(0.03, rel=1e-3)
    assert doc["closed_loop"]["settling_time_1pct"]["tip"] < 2.0


def test_failed_certificate_exits_1(capsys):
    rc = main(["control", MSD, "--target", "position=0.5", "--stiffness", "k.l=-6", "--rays", "4", "--simulations", "1"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "NOT positive definite" in out and "NOT ALL PASSED" in out


def test_target_not_reached_in_the_simulated_time_is_said_and_exits_1(tmp_path, capsys):
    rc = main(["control", MSD, "--target", "k.l=0.05", "--t-end", "2", "--rays", "4", "--simulations", "1",
               "--json", str(tmp_path / "c.json")])
    out = capsys.readouterr().out
    assert rc == 1
    assert "all passed" in out and "inf s" not in out
    assert "k.l: final" in out and "NOT REACHED" in out and "2 s" in out
    assert json.loads((tmp_path / "c.json").read_text())["closed_loop"]["reached"] == {"k.l": False}


@pytest.mark.parametrize(("argv", "match"), [
    (["control", "systems.electrostatic_actuator:electrostatic_actuator", "--target", "position=2e-4"],
     "not reachable"),
    (["control", MSD, "--target", "position"], "--target 'position': expected NAME=VALUE"),
    (["control", MSD, "--target", "nowhere=1"], "no state or measured output"),
    (["control", MSD, "--target", "position=0.5", "--damping", "-1"], "--damping '-1'"),
    (["control", MSD, "--target", "position=0.5", "--plant-param", "zz=1"], "no parameter 'zz'"),
    (["control", MSD, "--target", "position=0.5", "--dt", "0.1"], "--dt needs --t-end"),
])
def test_errors_exit_2_and_write_nothing(argv, match, tmp_path, capsys):
    rc = main([*argv, "--json", str(tmp_path / "x.json"), "--report", str(tmp_path / "rep")])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("phs: error: ") and match in err, err
    assert list(tmp_path.iterdir()) == []


def test_report_path_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "rep").write_text("x")
    rc = main(["control", MSD, "--target", "position=0.5", "--report", str(tmp_path / "rep")])
    assert rc == 2 and "is not a directory" in capsys.readouterr().err
