"""The ``phs`` command line (phs.workflows.cli, loader, inputs)."""

from __future__ import annotations

import csv
import json
import os
import textwrap

import numpy as np
import pytest

from phs import InputDataError, ParameterError, PHSystem
from phs.workflows.cli import main
from phs.workflows.inputs import parse_assignments, read_input_csv
from phs.workflows.loader import load_model
from systems.examples import mass_spring_damper

RC = "systems.examples:rc_circuit"
RC_COLUMNS = ["t [s]", "C.Q [C]", "U [V]", "U.i [A]", "v_C [V]", "H [J]", "dissipated [W]", "supplied [W]"]


def rc_columns(law: str) -> list[str]:
    """The header of ``phs simulate --out`` for the RC circuit driven by ``law`` (written after the input's unit)."""
    return [f"U [V] {{{law}}}" if c == "U [V]" else c for c in RC_COLUMNS]


def csv_header(path) -> list[str]:
    with open(path, newline="") as fh:
        return next(csv.reader(fh))


def read_csv(path) -> tuple[list[str], np.ndarray]:
    """Column names (without their `` [unit]``) and the data."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return [c.split(" [")[0] for c in rows[0]], np.array(rows[1:], dtype=float)


def simulate(tmp_path, *extra, model=RC, t_end="5e-3", dt="1e-4"):
    argv = ["simulate", model, "--t-end", t_end, "--dt", dt, "--out", str(tmp_path / "res.csv"), *extra]
    return main(argv)


# -- successful runs ---------------------------------------------------------------------------
def test_version(capsys):
    import phs

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"phs {phs.__version__}"


def test_step_response_matches_analytic_rc(tmp_path):
    assert simulate(tmp_path, "--input", "step(1.0)", "--rtol", "1e-10", "--atol", "1e-10") == 0
    header, data = read_csv(tmp_path / "res.csv")
    assert csv_header(tmp_path / "res.csv") == rc_columns("step(1.0)")
    t, q = data[:, 0], data[:, header.index("C.Q")]
    np.testing.assert_allclose(t, np.arange(0, 5e-3 + 0.5e-4, 1e-4), rtol=0, atol=1e-15)
    assert len(t) == 51
    R, C, U = 1e3, 1e-6, 1.0
    analytic = C * U * (1 - np.exp(-t / (R * C)))
    assert q[0] == 0.0
    np.testing.assert_allclose(q[1:], analytic[1:], rtol=1e-6)
    np.testing.assert_allclose(data[:, header.index("v_C")], q / C, rtol=1e-12)


def test_square_input_with_plot_and_json(tmp_path):
    rc = simulate(tmp_path, "--input", "square(1.0, 50)", "--plot", str(tmp_path / "fig.png"),
                  "--json", str(tmp_path / "summary.json"), t_end="0.04", dt="1e-3")
    assert rc == 0
    header, data = read_csv(tmp_path / "res.csv")
    assert csv_header(tmp_path / "res.csv") == rc_columns("square(1.0, 50)")
    u = data[:, header.index("U")]
    assert set(np.round(u, 12)) == {1.0, -1.0}
    assert (tmp_path / "fig.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary["final_state"]) == {"C.Q"}
    assert summary["final_state"]["C.Q"] == pytest.approx(data[-1, 1], rel=1e-12)
    assert summary["energy_balance_error"] < 1e-2
    assert summary["runtime_seconds"] > 0
    assert sorted(os.listdir(tmp_path)) == ["fig.png", "res.csv", "summary.json"]


def test_param_and_x0_overrides(tmp_path):
    rc = simulate(tmp_path, "--param", "R.R=2000", "--x0", "C.Q=1e-6", "--rtol", "1e-10", "--atol", "1e-10")
    assert rc == 0
    header, data = read_csv(tmp_path / "res.csv")
    t, q = data[:, 0], data[:, header.index("C.Q")]
    np.testing.assert_allclose(q, 1e-6 * np.exp(-t / 2e-3), rtol=1e-6)  # discharge, inputs default to 0
    assert np.all(data[:, header.index("U")] == 0)


def test_input_from_csv_with_map_and_time_column(tmp_path):
    src = tmp_path / "drive.csv"
    src.write_text("time,volts\n0,2\n0.0025,2\n0.005,2\n")
    rc = simulate(tmp_path, "--input", str(src), "--time", "time", "--map", "volts=U",
                  "--rtol", "1e-10", "--atol", "1e-10")
    assert rc == 0
    header, data = read_csv(tmp_path / "res.csv")
    t = data[:, 0]
    np.testing.assert_allclose(data[1:, 1], 2e-6 * (1 - np.exp(-t[1:] / 1e-3)), rtol=1e-6)


def test_model_from_file(tmp_path):
    model = tmp_path / "my_model.py"
    model.write_text("from systems.examples import mass_spring_damper\n\ndef build():\n"
                     "    return mass_spring_damper(k=9.0)\n")
    rc = simulate(tmp_path, "--input", "F=sine(1.0, 2.0)", model=f"{model}:build", t_end="1", dt="0.01")
    assert rc == 0
    header, _ = read_csv(tmp_path / "res.csv")
    assert header[:5] == ["t", "m.p", "k.l", "F", "F.v"]
    assert "position" in header
    assert load_model(f"{model}:build").param("k.K").value == 9.0


# -- invalid input: error type, culprit named, nothing written ---------------------------------
BROKEN_MODELS = textwrap.dedent("""
    def not_a_system():
        return 42

    def broken():
        raise ValueError("bad resistance")

    NOT_CALLABLE = 3
""")


def _csv(tmp_path, text: str) -> str:
    path = tmp_path / "u.csv"
    path.write_text(text)
    return str(path)


CASES = {
    # id: (MODEL, extra args or callable(tmp_path) -> extra args, culprits in the message)
    "no colon": ("systems.examples", [], ["systems.examples", "module:function"]),
    "missing module": ("no_such_module_xyz:build", [], ["no_such_module_xyz", "not found"]),
    "missing function": ("systems.examples:no_such_function", [], ["no_such_function", "rc_circuit"]),
    "missing file": ("missing_dir/model.py:build", [], ["missing_dir/model.py", "does not exist"]),
    "not a PHSystem": ("{models}:not_a_system", [], ["not_a_system", "int", "not a PHSystem"]),
    "function raises": ("{models}:broken", [], ["broken", "ValueError", "bad resistance"]),
    "not callable": ("{models}:NOT_CALLABLE", [], ["NOT_CALLABLE", "not a function"]),
    "unknown param": (RC, ["--param", "X.Y=1"], ["'X.Y'", "R.R"]),
    "param not a number": (RC, ["--param", "R.R=abc"], ["--param", "R.R", "'abc'"]),
    "param without value": (RC, ["--param", "R.R"], ["--param", "'R.R'", "NAME=VALUE"]),
    "unknown state in x0": (RC, ["--x0", "Z=1"], ["x0", "'Z'"]),
    "unknown input": (RC, ["--input", "V=1"], ["'V'", "U"]),
    "bad expression": (RC, ["--input", "sin(2*pi*t"], ["sin(2*pi*t"]),
    "unknown name in expression": (RC, ["--input", "square(1, 50) + foo"], ["'foo'"]),
    "csv NaN": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.001,1\n0.002,nan\n0.005,1\n")],
                ["u.csv", "row 4", "'U'", "not finite"]),
    "csv inf": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.001,inf\n0.005,1\n")], ["u.csv", "row 3", "'U'"]),
    "csv non-monotone time": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.002,1\n0.001,1\n0.005,1\n")],
                              ["u.csv", "row 4", "'t'", "not strictly increasing"]),
    "csv duplicated time": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.002,1\n0.002,1\n0.005,1\n")],
                            ["u.csv", "row 4", "duplicated"]),
    "csv missing input column": (RC, lambda p: ["--input", _csv(p, "t,V\n0,1\n0.005,1\n")],
                                 ["u.csv", "'U'", "columns: t, V"]),
    "csv missing time column": (RC, lambda p: ["--input", _csv(p, "time,U\n0,1\n0.005,1\n")], ["u.csv", "'t'"]),
    "csv non-numeric cell": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.001,abc\n0.005,1\n")],
                             ["u.csv", "row 3", "'U'", "'abc'"]),
    "csv empty cell": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.001,\n0.005,1\n")], ["row 3", "'U'", "empty"]),
    "csv one row": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n")], ["u.csv", "at least 2"]),
    "csv too short": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.001,1\n")], ["u.csv", "'t'", "0.001"]),
    "csv unit not the model's": (RC, lambda p: ["--input", _csv(p, "t [s],U [m]\n0,1\n0.005,1\n")],
                                 ["u.csv", "'U'", "'m'", "'V'", "different dimensions"]),
    "csv time not a time": (RC, lambda p: ["--input", _csv(p, "t [V],U [V]\n0,1\n5,1\n")], ["u.csv", "'t'", "'V'", "'s'"]),
    "csv missing file": (RC, ["--input", "absent.csv"], ["absent.csv", "does not exist"]),
    "map unknown signal": (RC, lambda p: ["--input", _csv(p, "t,U\n0,1\n0.005,1\n"), "--map", "U=W"], ["'W'"]),
    "out directory missing": (RC, ["--out", "no/such/dir/res.csv"], ["no/such/dir"]),
}


@pytest.mark.parametrize("model, extra, culprits", list(CASES.values()), ids=list(CASES))
def test_invalid_input_is_reported_and_nothing_written(tmp_path, capsys, model, extra, culprits):
    models = tmp_path / "models.py"
    models.write_text(BROKEN_MODELS)
    model = model.format(models=models)
    extra = extra(tmp_path) if callable(extra) else extra
    before = set(os.listdir(tmp_path))
    out = tmp_path / "res.csv"
    argv = ["simulate", model, "--t-end", "5e-3", "--dt", "1e-3", "--out", str(out),
            "--plot", str(tmp_path / "fig.png"), "--json", str(tmp_path / "s.json"), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("phs: error: ")
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    for culprit in culprits:
        assert culprit in err, (culprit, err)
    assert set(os.listdir(tmp_path)) == before


def test_success_says_what_was_written(tmp_path, capsys):
    assert simulate(tmp_path, "--input", "step(1.0)", "--json", str(tmp_path / "s.json")) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1, out
    for part in ["'rc'", "51 samples", "t = 0.005 s", str(tmp_path / "res.csv"), str(tmp_path / "s.json")]:
        assert part in out, (part, out)


def test_plot_alone_needs_no_csv_and_one_of_them_is_required(tmp_path, capsys):
    argv = ["simulate", RC, "--t-end", "1e-3", "--dt", "1e-4", "--input", "step(1.0)"]
    assert main([*argv, "--plot", str(tmp_path / "fig.png")]) == 0
    assert os.listdir(tmp_path) == ["fig.png"]
    assert "fig.png" in capsys.readouterr().out
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "--plot" in err and err.startswith("phs: error: ")


def test_result_csv_reads_back_as_a_recording(tmp_path):
    from phs.workflows.recording import Recording

    assert simulate(tmp_path, "--input", "step(1.0)") == 0
    rec = Recording.from_csv(tmp_path / "res.csv")
    _, data = read_csv(tmp_path / "res.csv")
    np.testing.assert_array_equal(rec["C.Q"], data[:, 1])
    assert rec.units["C.Q"] == "C" and rec.units["dissipated"] == "W"


def test_result_csv_feeds_back_as_input(tmp_path):
    """A CSV written by ``phs simulate --out`` (headers ``name [unit]``) is a valid ``--input``."""
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    assert simulate(first, "--input", "sine(1.0, 100)", "--rtol", "1e-10", "--atol", "1e-10") == 0
    assert simulate(second, "--input", str(first / "res.csv"), "--rtol", "1e-10", "--atol", "1e-10") == 0
    assert csv_header(second / "res.csv") == RC_COLUMNS
    header, a = read_csv(first / "res.csv")
    _, b = read_csv(second / "res.csv")
    u, q = header.index("U"), header.index("C.Q")
    np.testing.assert_allclose(b[:, u], a[:, u], rtol=0, atol=1e-12)
    np.testing.assert_allclose(b[:, q], a[:, q], rtol=0, atol=1e-3 * np.abs(a[:, q]).max())


@pytest.mark.parametrize("args", [["--dt", "-1"], ["--t-end", "nan"], ["--rtol", "0"]], ids=str)
def test_bad_numbers_are_usage_errors(tmp_path, capsys, args):
    argv = ["simulate", RC, "--t-end", "1e-3", "--dt", "1e-4", "--out", str(tmp_path / "res.csv"), *args]
    assert main(argv) == 2
    assert args[0] in capsys.readouterr().err
    assert os.listdir(tmp_path) == []


def test_bare_expression_needs_a_single_input():
    import sympy as sp

    from phs.workflows.inputs import input_signals

    q = sp.Symbol("q", real=True)
    two = PHSystem("two", ["q"], q**2 / 2, [[0]], [[1]], [[1, 1]], inputs=["U1", "U2"])
    with pytest.raises(InputDataError, match="NAME=EXPR") as info:
        input_signals(two, ["1.0"])
    assert "U1, U2" in str(info.value)
    assert set(input_signals(two, ["U2=sine(1, 2)"])) == {"U2"}


# -- the helpers directly ---------------------------------------------------------------------------
def test_load_model_applies_params_and_names_unknown_ones():
    assert load_model(RC, {"C.C": 2e-6}).param("C.C").value == 2e-6
    with pytest.raises(ParameterError, match="'nope'"):
        load_model(RC, {"nope": 1.0})


def test_parse_assignments_errors():
    assert parse_assignments(["a=1", "b.c = x"]) == {"a": "1", "b.c": "x"}
    with pytest.raises(InputDataError, match="given twice"):
        parse_assignments(["a=1", "a=2"], "--x0")
    with pytest.raises(InputDataError, match="--map 'a=': the value"):
        parse_assignments(["a="], "--map")
    with pytest.raises(InputDataError, match="not finite"):
        parse_assignments(["a=inf"], numeric=True)


def test_read_input_csv_rows_and_signals(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("t,F,position\n0,0,0\n\n1,2,0.1\n2,4,0.2\n")  # a blank line is skipped
    t, u = read_input_csv(path, mass_spring_damper(), mapping={"position": "position"})
    assert t.tolist() == [0.0, 1.0, 2.0]
    assert list(u) == ["F"] and float(u["F"](1.5)) == 3.0
    path.write_text("t,F\n0,0\n\n1,x\n")
    with pytest.raises(InputDataError, match=r"row 4, column 'F'"):  # spreadsheet rows count the blank line
        read_input_csv(path, mass_spring_damper())



@pytest.mark.parametrize(("text", "culprit"), [
    ("9**9**9", "exponent"), ("step(9**9**9)", "exponent"), ("1/0", "division by zero"), ("sin", "'sin' is a function"),
    ("log(0)", "not finite"), ("1e400", "not a finite"), ("__import__('os').system('true')", "'__import__'"),
])
def test_unsafe_or_undefined_input_expressions_are_one_error_line(tmp_path, capsys, text, culprit):
    assert simulate(tmp_path, "--input", f"U={text}") == 2
    err = capsys.readouterr().err
    assert err.startswith("phs: error: --input U: ") and err.count("\n") == 1 and culprit in err, err
    assert os.listdir(tmp_path) == []
