"""Every output of a command is written, or none: destinations are checked (writable, no two options naming
one file) before any work, and the prepared files are staged beside their destinations and renamed together
(:func:`phs.io.write_all_atomic`, :func:`phs.workflows.cli_options._write_outputs`).

An unwritable directory is a read-only one, or, when the tests run as root (who writes anywhere), a path
under a regular file (its "directory" cannot exist).
"""

from __future__ import annotations

import os
import shutil
import stat

import numpy as np
import pytest

from phs.errors import InputDataError
from phs.io import write_all_atomic
from phs.workflows.cli import main

RC = "systems.examples:rc_circuit"
SIMULATE = ["simulate", RC, "--t-end", "1e-3", "--dt", "1e-4", "--input", "step(1, 1e-4)"]
SWEEP = ["sweep", RC, "--t-end", "1e-3", "--dt", "1e-4", "--range", "R.R=1e3:2e3:3", "--metric", "final:v_C", "--quiet"]


@pytest.fixture
def unwritable(tmp_path):
    """A directory no file can be written into (see the module docstring)."""
    if os.geteuid() == 0:
        blocker = tmp_path / "blocked"
        blocker.write_text("a file where a directory is expected\n")
        yield blocker
        return
    d = tmp_path / "read_only"
    d.mkdir()
    d.chmod(stat.S_IRUSR | stat.S_IXUSR)
    yield d
    d.chmod(stat.S_IRWXU)


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("phs: error: ") and "\n" not in err and "Traceback" not in err, err
    return err


def _files(d) -> list[str]:
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file() and p.name != "blocked")


@pytest.fixture
def recording(tmp_path_factory):
    """A simulated RC recording (1 ms, 101 samples) for ``phs fit``."""
    d = tmp_path_factory.mktemp("data")
    assert main(SIMULATE + ["--dt", "1e-5", "--out", str(d / "rec.csv")]) == 0
    return str(d / "rec.csv")


# -- an unwritable destination: refused before any work, nothing written ----------------------------------
@pytest.mark.parametrize("option", ["--plot", "--json"])
def test_simulate_with_one_unwritable_output_writes_none(tmp_path, unwritable, capsys, option):
    bad = str(unwritable / ("s.png" if option == "--plot" else "s.json"))
    assert main(SIMULATE + ["--out", str(tmp_path / "ok.csv"), option, bad]) == 2
    assert f"cannot write {bad!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []


@pytest.mark.parametrize("option", ["--plot", "--json", "--out"])
def test_sweep_with_one_unwritable_output_writes_none(tmp_path, unwritable, capsys, option):
    outs = {"--out": str(tmp_path / "r.csv"), "--plot": str(tmp_path / "r.png"), "--json": str(tmp_path / "r.json")}
    outs[option] = str(unwritable / os.path.basename(outs[option]))
    assert main(SWEEP + [a for kv in outs.items() for a in kv]) == 2
    assert f"cannot write {outs[option]!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []


def test_fit_with_an_unwritable_json_writes_no_report(tmp_path, unwritable, recording, capsys):
    bad = str(unwritable / "fit.json")
    argv = ["fit", RC, recording, "--free", "R.R", "--quiet", "--report", str(tmp_path / "rep"), "--json", bad]
    assert main(argv) == 2
    assert f"cannot write {bad!r}" in _one_line_error(capsys)
    assert not (tmp_path / "rep").exists() and _files(tmp_path) == []


def test_fit_with_an_unwritable_report_writes_no_json(tmp_path, unwritable, recording, capsys):
    report = str(unwritable / "rep")
    argv = ["fit", RC, recording, "--free", "R.R", "--quiet", "--report", report, "--json", str(tmp_path / "f.json")]
    assert main(argv) == 2
    assert "cannot write" in _one_line_error(capsys)
    assert _files(tmp_path) == []


def test_diagnose_with_an_unwritable_json_is_refused_before_the_work(tmp_path, unwritable, recording, capsys):
    bad = str(unwritable / "d.json")
    assert main(["diagnose", RC, recording, "--free", "R.R", "--quiet", "--json", bad]) == 2
    assert f"cannot write {bad!r}" in _one_line_error(capsys)


# -- outputs that coincide: refused naming both options ------------------------------------------------
def test_simulate_refuses_out_and_plot_on_one_file(tmp_path, capsys):
    x = str(tmp_path / "x.csv")
    assert main(SIMULATE + ["--out", x, "--plot", x]) == 2
    assert f"--out and --plot both name {x!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []
    y = os.path.join(str(tmp_path), ".", "x.csv")  # the same file by another spelling
    assert main(SIMULATE + ["--out", x, "--json", y]) == 2
    assert "--out and --json both name" in _one_line_error(capsys)


@pytest.mark.parametrize(("option", "name"), [("--plot", "r.csv"), ("--json", "r.csv"), ("--json", "r.csv.study.json")])
def test_sweep_refuses_outputs_on_one_file(tmp_path, capsys, option, name):
    out = str(tmp_path / "r.csv")
    assert main(SWEEP + ["--out", out, option, str(tmp_path / name)]) == 2
    assert f"--out and {option} both name" in _one_line_error(capsys)
    assert _files(tmp_path) == []


def test_fit_refuses_a_json_inside_its_report(tmp_path, recording, capsys):
    report = tmp_path / "rep"
    argv = ["fit", RC, recording, "--free", "R.R", "--quiet", "--report", str(report), "--json", str(report / "summary.txt")]
    assert main(argv) == 2
    assert "--json and --report both name" in _one_line_error(capsys)
    assert not report.exists()


# -- a destination that fails during the writing: nothing is renamed into place ----------------------------
def test_simulate_writes_nothing_when_a_destination_vanishes_during_the_work(tmp_path, monkeypatch, capsys):
    import phs.workflows.simulate_cli as simulate_cli

    figures = tmp_path / "figures"
    figures.mkdir()
    rendered = simulate_cli._figure_png

    def render_then_lose_the_directory(res):
        shutil.rmtree(figures)  # after the checks, before the writing
        return rendered(res)

    monkeypatch.setattr(simulate_cli, "_figure_png", render_then_lose_the_directory)
    assert main(SIMULATE + ["--out", str(tmp_path / "ok.csv"), "--plot", str(figures / "p.png")]) == 2
    assert "cannot write" in _one_line_error(capsys)
    assert _files(tmp_path) == []  # ok.csv was staged, then removed: no file, no temporary


def test_write_all_atomic_stages_everything_before_renaming(tmp_path):
    keep = tmp_path / "a.txt"
    keep.write_text("old")
    with pytest.raises(InputDataError, match="b.txt"):
        write_all_atomic({keep: "new", tmp_path / "missing" / "b.txt": b"B"})
    assert keep.read_text() == "old" and _files(tmp_path) == ["a.txt"]
    write_all_atomic({keep: "new", tmp_path / "c.bin": np.arange(3, dtype=np.uint8).tobytes()})
    assert keep.read_text() == "new" and (tmp_path / "c.bin").read_bytes() == b"\x00\x01\x02"


# -- diagnose, passivity and control: their reports with the JSON, all or nothing -----------------------
DIAGNOSE = ["--free", "R.R", "--quiet", "--no-discover", "--effects", "leakage", "--jobs", "1"]  # the smallest diagnosis
PASSIVITY = ["passivity", RC, "--box-samples", "16", "--starts", "0", "--input", "step(1, 1e-4)", "--t-end", "1e-3",
             "--dt", "1e-4"]  # with a trajectory: the report holds a figure


def test_diagnose_with_an_unwritable_report_is_refused_before_the_work(tmp_path, unwritable, recording, capsys):
    report = str(unwritable / "rep")
    assert main(["diagnose", RC, recording, *DIAGNOSE, "--report", report, "--json", str(tmp_path / "d.json")]) == 2
    assert f"cannot write {report!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []


@pytest.mark.parametrize("inside", ["index.html", "", "diagnosis.json"])
def test_diagnose_refuses_a_json_on_its_report(tmp_path, recording, capsys, inside):
    report = tmp_path / "rep"
    json_path = str(report / inside) if inside else str(report)
    assert main(["diagnose", RC, recording, *DIAGNOSE, "--report", str(report), "--json", json_path]) == 2
    assert "--json and --report both name" in _one_line_error(capsys)
    assert not report.exists() and _files(tmp_path) == []


def test_diagnose_writes_nothing_when_a_destination_vanishes_during_the_work(tmp_path, recording, monkeypatch, capsys):
    import phs.workflows.diagnose.report as diagnose_report

    elsewhere = tmp_path / "json"
    elsewhere.mkdir()
    rendered = diagnose_report._report_files

    def render_then_lose_the_directory(d):
        shutil.rmtree(elsewhere)  # after the checks, before the writing
        return rendered(d)

    monkeypatch.setattr(diagnose_report, "_report_files", render_then_lose_the_directory)
    report = tmp_path / "rep"
    assert main(["diagnose", RC, recording, *DIAGNOSE, "--report", str(report), "--json", str(elsewhere / "d.json")]) == 2
    assert "cannot write" in _one_line_error(capsys)
    assert not report.exists() and _files(tmp_path) == []  # the report's directory made for it is removed again


@pytest.mark.parametrize("which", ["--report", "--json"])
def test_passivity_with_one_unwritable_output_writes_none(tmp_path, unwritable, capsys, which):
    outs = {"--report": str(tmp_path / "rep"), "--json": str(tmp_path / "p.json")}
    outs[which] = str(unwritable / os.path.basename(outs[which]))
    assert main(PASSIVITY + [a for kv in outs.items() for a in kv]) == 2
    assert f"cannot write {outs[which]!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []


@pytest.mark.parametrize("inside", ["report.json", "", "trajectory.png"])
def test_passivity_refuses_a_json_on_its_report(tmp_path, capsys, inside):
    report = tmp_path / "rep"
    report.mkdir()  # so that a JSON inside it is writable, and only the clash refuses it
    assert main(PASSIVITY + ["--report", str(report), "--json", str(report / inside) if inside else str(report)]) == 2
    assert "--json and --report both name" in _one_line_error(capsys)  # a figure's name: found once it is drawn
    assert _files(tmp_path) == []


def test_passivity_writes_nothing_when_a_destination_vanishes_during_the_work(tmp_path, monkeypatch, capsys):
    from codegen.passivity.report import PassivityReport

    elsewhere = tmp_path / "json"
    elsewhere.mkdir()
    rendered = PassivityReport.report_files

    def render_then_lose_the_directory(self):
        shutil.rmtree(elsewhere)
        return rendered(self)

    monkeypatch.setattr(PassivityReport, "report_files", render_then_lose_the_directory)
    report = tmp_path / "rep"
    assert main(PASSIVITY + ["--report", str(report), "--json", str(elsewhere / "p.json")]) == 2
    assert "cannot write" in _one_line_error(capsys)
    assert not report.exists() and _files(tmp_path) == []
    monkeypatch.undo()
    assert main(PASSIVITY + ["--report", str(report), "--json", str(tmp_path / "p.json")]) == 0
    assert {"report.html", "report.json", "report.txt", "trajectory.png"} <= set(os.listdir(report))


@pytest.mark.parametrize("option", ["--report", "--export-c"])
def test_control_refuses_a_json_on_its_directories(tmp_path, capsys, option):
    d = str(tmp_path / "out")
    argv = ["control", "systems.examples:mass_spring_damper", "--target", "position=0.5", "--rays", "4",
            "--simulations", "1", option, d, "--json", d]
    assert main(argv) == 2
    assert f"--json and {option} both name {d!r}" in _one_line_error(capsys)
    assert _files(tmp_path) == []


def test_write_all_atomic_refuses_a_directory_before_any_rename(tmp_path):
    report = tmp_path / "rep"
    with pytest.raises(InputDataError, match="it is a directory"):
        write_all_atomic({report / "a.txt": "A", report: "a file where the report's directory is"}, create=[report])
    assert not report.exists() and _files(tmp_path) == []


def test_export_writes_both_sources_or_neither(tmp_path, capsys):
    out = tmp_path / "c"
    out.mkdir()
    (out / "rc_model.h").mkdir()  # the header's destination is a directory: refused before any rename
    assert main(["export", RC, "--c", str(out)]) == 2
    assert "it is a directory" in _one_line_error(capsys)
    assert _files(tmp_path) == []  # no rc_model.c beside it, no temporary
    assert main(["export", RC, "--c", str(tmp_path / "new")]) == 0
    assert sorted(os.listdir(tmp_path / "new")) == ["rc_model.c", "rc_model.h"]
