"""What ``phs`` shows while it works: progress bars only on a terminal or with --progress, the size of a
large CSV said before the run, ranges left said once per run (errors with --strict-ranges), solvers' own
warnings kept off stderr unless --verbose (phs.workflows.terminal, cli_output, ranges)."""

from __future__ import annotations

import io
import json
import os
import sys
import warnings

import numpy as np
import pytest

from phs.workflows import cli_output
from phs.workflows.cli import main
from phs.workflows.cli_output import csv_size_estimate, table_columns, write_csv
from phs.workflows.ranges import RangeWarning, check_ranges
from phs.workflows.terminal import solver_chatter

RC = "systems.examples:rc_circuit"
MSD = "systems.examples:mass_spring_damper"


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


# -- progress bars -------------------------------------------------------------------------------------------
def test_simulate_progress_only_when_asked_or_on_a_terminal(tmp_path, capsys, monkeypatch):
    args = ["simulate", RC, "--t-end", "0.01", "--dt", "1e-5", "--input", "square(1.0, 500)", "--out",
            str(tmp_path / "r.csv")]
    assert main(args) == 0
    assert capsys.readouterr().err == ""  # captured output (not a terminal): no bar
    assert main([*args, "--progress"]) == 0
    err = capsys.readouterr().err
    assert "simulate rc" in err and "100%" in err
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    assert main(args) == 0
    assert "simulate rc" in term.getvalue()  # a terminal gets the bar without asking
    term.truncate(0)
    assert main([*args, "--quiet"]) == 0
    assert "simulate rc" not in term.getvalue()


def test_passivity_progress_names_its_stages(capsys):
    args = ["passivity", RC, "--box-samples", "32", "--starts", "1"]
    assert main(args) == 0
    assert "stages" not in capsys.readouterr().err
    assert main([*args, "--progress"]) == 0
    err = capsys.readouterr().err
    assert "passivity rc" in err and "dissipation" in err and "4/4 stages" in err


def test_control_progress_names_its_stages(capsys):
    args = ["control", MSD, "--target", "position=0.5", "--stiffness", "k.l=6", "--damping", "2", "--rays", "8",
            "--simulations", "2", "--t-end", "5", "--dt", "0.05"]
    assert main(args) == 0
    assert "stages" not in capsys.readouterr().err
    assert main([*args, "--progress"]) == 0
    err = capsys.readouterr().err
    assert "control msd" in err and "closed loop" in err and "3/3 stages" in err


def test_fit_progress_bar_instead_of_lines_in_piped_output(tmp_path, capsys):
    data = tmp_path / "r.csv"
    assert main(["simulate", MSD, "--t-end", "5", "--dt", "0.05", "--input", "square(1.0, 0.5)", "--out", str(data)]) == 0
    capsys.readouterr()
    args = ["fit", MSD, str(data), "--free", "b.b", "--param", "b.b=0.3", "--max-iter", "20"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "evaluation" not in err and "fit msd" not in err  # piped: nothing on stderr by default
    assert main([*args, "--progress"]) == 0
    err = capsys.readouterr().err
    assert "fit msd" in err and "eval" in err


# -- size of a large CSV ---------------------------------------------------------------------------------
@pytest.mark.parametrize("model, spec", [(RC, "square(1.0, 500)"), (MSD, "chirp(1.0, 0.5, 20, 2)")])
def test_size_estimate_within_a_factor_1_5_of_the_file(tmp_path, capsys, model, spec):
    out = tmp_path / "r.csv"
    assert main(["simulate", model, "--t-end", "2", "--dt", "1e-4", "--input", spec, "--out", str(out)]) == 0
    rows = 20001
    from phs.workflows.loader import load_model

    columns = table_columns(load_model(model))
    with open(out) as fh:
        header = fh.readline()
        assert len(fh.readline().split(",")) == columns
    ratio = csv_size_estimate(rows, columns) / (os.path.getsize(out) - len(header))
    # the stated accuracy of the estimate (BYTES_PER_CELL): a factor 1.5 either way on general numbers
    assert 1 / 1.5 < ratio < 1.5, ratio


def test_large_output_warned_before_the_run(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli_output, "LARGE_OUTPUT", 1e5)
    out = tmp_path / "r.csv"
    assert main(["simulate", RC, "--t-end", "1", "--dt", "1e-3", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("phs: warning:") == 1
    assert f"--out {out} will hold 1001 rows x 8 columns, about 160 kB" in err
    assert main(["simulate", RC, "--t-end", "1", "--dt", "1e-2", "--out", str(out)]) == 0  # 0.016 MB: no warning
    assert "warning" not in capsys.readouterr().err


def test_written_bytes_are_those_of_to_csv(tmp_path):
    from codegen import simulate
    from systems.examples import rc_circuit

    res = simulate(rc_circuit(), np.linspace(0.0, 5e-3, 45_001), u={"U": 1.0})
    res.to_csv(tmp_path / "a.csv", between={"U": "1.0"})
    header, data = res.table()
    cells = [f"{n} [{res.unit(n)}]" + (" {1.0}" if n == "U" else "") for n in header]
    write_csv(tmp_path / "b.csv", cells, data)  # three blocks of rows: the block edges leave no trace
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


# -- ranges ----------------------------------------------------------------------------------------------
def test_state_leaving_its_range_said_once_or_refused(tmp_path, capsys):
    out = tmp_path / "r.csv"
    args = ["simulate", RC, "--t-end", "0.01", "--dt", "1e-4", "--input", "20", "--out", str(out)]  # Q = C U = 2e-5 C
    assert main(args) == 0
    err = capsys.readouterr().err
    assert err.count("phs: warning:") == 1 and err.count("C.Q") == 1
    assert "state 'C.Q' of 'rc' reaches 1.99991e-05 C, outside its declared range -1e-05 to 1e-05 C (first at t = " in err
    os.remove(out)
    assert main([*args, "--strict-ranges"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("phs: error: state 'C.Q' of 'rc' reaches") and err.count("\n") == 1
    assert not out.exists()  # nothing written


def test_input_outside_its_range_refused_before_the_run(tmp_path, capsys):
    out = tmp_path / "r.csv"
    args = ["simulate", "systems:msd_hasel", "--t-end", "0.002", "--dt", "1e-4", "--input", "V=7000", "--out", str(out)]
    assert main([*args, "--strict-ranges"]) == 2
    err = capsys.readouterr().err
    assert "phs: error: input 'V' of 'msd_hasel' reaches 7000 V, outside its declared range 0 to 6000 V" in err
    assert not out.exists()
    assert main(args) == 0  # a warning, once, and the run
    err = capsys.readouterr().err
    assert err.count("input 'V'") == 1 and "--strict-ranges makes this an error" in err


def test_fit_refuses_a_recorded_input_outside_its_range_with_the_option(tmp_path, capsys):
    data = tmp_path / "rec.csv"
    t = np.arange(5) * 0.01
    np.savetxt(data, np.column_stack([t, np.linspace(0.0, 3e4, 5), np.zeros(5), np.zeros(5)]), delimiter=",",
               header="t,V,F_load,displacement", comments="")
    assert main(["fit", "systems:msd_hasel", str(data), "--free", "b", "--strict-ranges"]) == 2
    err = capsys.readouterr().err
    assert f"{data}: input 'V' of 'msd_hasel' reaches 30000 V, outside its declared range 0 to 6000 V" in err


def test_check_ranges_in_python_warns_once_or_raises():
    from codegen import simulate
    from phs.errors import DomainError
    from systems.examples import rc_circuit

    res = simulate(rc_circuit(), np.linspace(0.0, 0.01, 101), u={"U": 20.0})
    with pytest.warns(RangeWarning) as caught:
        found = check_ranges(res)
    assert len(caught) == 1 and len(found) == 1 and "C.Q" in found[0]
    with pytest.raises(DomainError, match=r"state 'C.Q' of 'rc' reaches 1.99991e-05 C, outside its declared range -1e-05 "
                                           r"to 1e-05 C \(first at t = 0.0007 s\)"):
        check_ranges(res, strict=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RangeWarning)
        with pytest.raises(RangeWarning):
            check_ranges(res)


# -- solver chatter --------------------------------------------------------------------------------------
def test_solver_warnings_kept_off_stderr_unless_verbose(capsys, monkeypatch):
    import phs.workflows.list_cli as list_cli

    def chatty(args):  # CasADi writes its warnings through Python's sys.stderr, as here
        print('CasADi - 2026-11-27 22:43:06 WARNING("Failed to calculate multipliers") [.../nlpsol.cpp:859]',
              file=sys.stderr)
        print("phs: warning: our own", file=sys.stderr)
        return 0

    monkeypatch.setattr(list_cli, "run_list", chatty)
    with solver_chatter():
        sys.stderr.write("\rbar  50%")  # a bar redrawn in place (tqdm of a library) shows at once, not at the next newline
        assert capsys.readouterr().err == "\rbar  50%"
    assert main(["list"]) == 0
    assert capsys.readouterr().err == "phs: warning: our own\n"
    with solver_chatter(verbose=True):
        chatty(None)
    assert "Failed to calculate multipliers" in capsys.readouterr().err


@pytest.mark.slow
def test_manta_ray_fin_certificate_without_casadi_chatter(capsys):
    assert main(["passivity", "systems:manta_ray_fin"]) == 0
    assert "Failed to calculate multipliers" not in capsys.readouterr().err
    assert main(["passivity", "systems:manta_ray_fin", "--verbose"]) == 0
    assert "Failed to calculate multipliers" in capsys.readouterr().err


# -- small defects ---------------------------------------------------------------------------------------
def test_fit_of_a_simulate_file_fits_the_measured_outputs_only(tmp_path, capsys):
    data = tmp_path / "r.csv"
    assert main(["simulate", MSD, "--t-end", "5", "--dt", "0.05", "--input", "square(1.0, 0.5)", "--out", str(data)]) == 0
    header = open(data).readline()
    assert "k.l [m]" in header and "F.v" in header and "position" in header  # states, port output, measured
    js = tmp_path / "fit.json"
    assert main(["fit", MSD, str(data), "--free", "b.b", "--param", "b.b=0.3", "--max-iter", "20", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    assert doc["outputs"] == ["position"]  # position once, not again as the spring's state k.l
    assert "outputs position\n" in out
    assert doc["values"]["b.b"] == pytest.approx(0.4, rel=1e-5)  # the file's own run, recovered


def test_fit_echoes_the_whole_command(tmp_path, capsys):
    data = tmp_path / "r.csv"
    assert main(["simulate", MSD, "--t-end", "5", "--dt", "0.05", "--input", "square(1.0, 0.5)", "--out", str(data)]) == 0
    capsys.readouterr()
    import phs

    args = ["fit", MSD, str(data), "--free", "b.b", "--param", "b.b=0.3", "--max-iter", "20", "--outputs", "position"]
    assert main(args) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first == f"phs {phs.__version__} " + " ".join(args)


def test_simulate_takes_the_input_files_time_grid(tmp_path, capsys):
    u = tmp_path / "u.csv"
    t = np.linspace(0.0, 0.004, 9)
    np.savetxt(u, np.column_stack([t, np.where(t < 0.002, 0.0, 1.0)]), delimiter=",", header="t,U", comments="")
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["simulate", RC, "--input", str(u), "--out", str(a)]) == 0
    assert main(["simulate", RC, "--input", str(u), "--t-end", "0.004", "--dt", "0.0005", "--out", str(b)]) == 0
    A = np.loadtxt(a, delimiter=",", skiprows=1)
    B = np.loadtxt(b, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(A[:, 0], t)  # the file's own grid, not T/1000
    np.testing.assert_allclose(A, B, rtol=1e-12, atol=1e-20)  # the same run as with --t-end on that grid
    assert main(["simulate", RC, "--input", "U=1", "--out", str(a)]) == 2
    assert "--t-end is needed unless an --input CSV file gives the time grid" in capsys.readouterr().err


def test_closed_loop_starts_at_the_loaded_rest_state():
    from codegen.idapbc import design
    from phs import equilibrium
    from phs.workflows.control_cli import _plant_x0
    from systems.examples import mass_spring_damper
    from systems.msd_hasel import msd_hasel

    s = msd_hasel()  # carries its weight m g: at x = 0 it is not at rest
    ctrl = design(s, {"displacement": 0.5e-3}, inputs=["V"], stiffness={"x": 2000.0}, damping={"p": 20.0})
    start, loaded = _plant_x0(ctrl, s, {})
    rest = equilibrium(s, u={"V": 0.0, "F_load": 0.0}, x0={"x": 0.0})["x"]
    assert rest > 1e-6 and start[0] == pytest.approx(rest, rel=1e-9)  # not x = 0, but where the weight holds it
    assert loaded.startswith(f"x={rest:.4g}")
    assert _plant_x0(ctrl, s, {"x": 1e-4})[0][0] == 1e-4  # a given start is kept
    m = mass_spring_damper()  # no load: the declared rest is at rest
    c = design(m, {"position": 0.5}, stiffness={"k.l": 6.0}, damping=2.0)
    start, loaded = _plant_x0(c, m, {})
    assert loaded == "" and np.all(start == 0.0)
