"""``phs fit``: end-to-end fit from a CSV recording, and invalid inputs (phs.workflows.cli)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from phs.workflows.cli import main
from phs.workflows.cli_recordings import parse_scales
from phs.workflows.identify import sensitivity_markdown

RC = "systems.examples:rc_circuit"
R_TRUE = 1500.0


def _rc_recording(path, t_end=0.02, n=401, seed=0, noise=0.002, columns=("time", "volts", "vc_mV")):
    """Square-wave response of the RC circuit with R = 1.5 kOhm; the capacitor voltage written in mV."""
    from codegen import simulate
    from systems.examples import rc_circuit

    t = np.linspace(0.0, t_end, n)
    u = np.where((t % 0.008) < 0.004, 1.0, -0.5)
    y = simulate(rc_circuit().with_params({"R.R": R_TRUE}), t, u={"U": u}, rtol=1e-10)["v_C"]
    y = y + noise * np.random.default_rng(seed).standard_normal(n)
    rows = [",".join(columns)] + [f"{a:.17g},{b:.17g},{c * 1e3:.17g}" for a, b, c in zip(t, u, y, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return str(path)


FIT_ARGS = ["--free", "R.R", "--time", "time", "--map", "volts=U", "--map", "vc_mV=v_C", "--scale", "vc_mV=mV:V"]


# -- end to end ----------------------------------------------------------------------------------
def test_fit_recovers_resistance_with_validation_report_and_json(tmp_path, capsys):
    train = _rc_recording(tmp_path / "train.csv", seed=1)
    check = _rc_recording(tmp_path / "check.csv", seed=2)
    out, report = tmp_path / "fit.json", tmp_path / "report"
    rc = main(["fit", RC, train, *FIT_ARGS, "--validate", check, "--json", str(out), "--report", str(report)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "evaluation" not in captured.err  # captured, not a terminal: no progress (phs.workflows.terminal)
    assert "R.R" in captured.out and "validation" in captured.out

    doc = json.loads(out.read_text())
    assert doc["values"]["R.R"] == pytest.approx(R_TRUE, rel=0.01)
    lo, hi = doc["intervals"]["R.R"]
    assert lo < doc["values"]["R.R"] < hi
    assert doc["free"] == ["R.R"] and doc["outputs"] == ["v_C"]
    assert doc["fit_percent"]["v_C"] > 95
    assert doc["validation"]["data"] == check
    assert doc["validation"]["fit_percent"]["v_C"] > 95
    assert doc["validation_fit_percent"] == doc["validation"]["fit_percent"]
    assert set(doc["sensitivity_by_channel"]["v_C"]["R.R"]) == {"-0.1", "-0.05", "0.0", "0.05", "0.1", "std"}
    assert doc["command"] == "fit" and doc["model"] == RC

    assert sorted(os.listdir(report)) == ["fit.png", "sensitivity.md", "summary.txt"]
    assert (report / "fit.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (report / "sensitivity.md").read_text()
    assert "| parameter | fitted value | -10 % | -5 % | 0 % | +5 % | +10 % | SD |" in md
    row = next(line for line in md.splitlines() if line.startswith("| `R.R`"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    fits = [float(c) for c in cells[2:7]]
    assert fits[2] == max(fits)  # the fitted value is the best of the five
    assert float(cells[7]) == pytest.approx(np.std(fits, ddof=1), abs=1e-2)  # cells rounded to 0.01
    summary = (report / "summary.txt").read_text()
    assert "R.R" in summary and "validation" in summary and doc["model_hash"] in summary
    assert sorted(os.listdir(tmp_path)) == ["check.csv", "fit.json", "report", "train.csv"]  # no temporary files


def test_quiet_fit_without_outputs_writes_nothing_and_prints_summary(tmp_path, capsys):
    data = _rc_recording(tmp_path / "d.csv", noise=0.0, columns=("t", "U", "v_C"))
    rc = main(["fit", RC, data, "--free", "R.R", "--quiet", "--param", "C.C=1e-6", "--max-iter", "30"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert captured.err == ""
    assert "fit v_C" in captured.out
    assert os.listdir(tmp_path) == ["d.csv"]


def test_parse_scales_and_markdown_helpers():
    assert parse_scales(["pos=mm:m", "f=2"]) == {"pos": ("mm", "m"), "f": 2.0}
    md = sensitivity_markdown({"y": {"a": {-0.1: 1.0, 0.0: 2.0, 0.1: 1.0, "std": 0.5},
                                     "b": {-0.1: 2.0, 0.0: 2.0, 0.1: 2.0, "std": 0.0}}})
    lines = [line for line in md.splitlines() if line.startswith("| `")]
    assert [line.split("`")[1] for line in lines] == ["a", "b"]  # most sensitive first


# -- invalid input: exit code 2, the culprit named, nothing written --------------------------------
def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


GOOD = "t,U,v_C\n0,1,0\n0.001,1,0.5\n0.002,1,0.8\n0.003,1,0.9\n"

CASES = {
    # id: (extra args, CSV text or None for the good one, fragments the message must contain)
    "unknown free parameter": (["--free", "R.X"], None, ["'R.X'", "R.R", "C.C"]),
    "empty free list": (["--free", "R.R,"], None, ["--free", "'R.R,'"]),
    "csv missing input column": (["--free", "R.R"], "t,V,v_C\n0,1,0\n0.001,1,0.5\n0.002,1,0.8\n",
                                 ["data.csv", "'U'", "columns: t, V, v_C"]),
    "csv missing mapped column": (["--free", "R.R", "--map", "volts=U"], GOOD, ["data.csv", "'volts'"]),
    "csv NaN cell": (["--free", "R.R"], "t,U,v_C\n0,1,0\n0.001,1,nan\n0.002,1,0.8\n0.003,1,0.9\n",
                     ["data.csv", "row 3", "'v_C'", "not finite"]),
    "csv empty cell": (["--free", "R.R"], "t,U,v_C\n0,1,0\n0.001,,0.5\n0.002,1,0.8\n",
                       ["data.csv", "row 3", "'U'", "empty"]),
    "csv non-monotone time": (["--free", "R.R"], "t,U,v_C\n0,1,0\n0.002,1,0.5\n0.001,1,0.8\n0.003,1,0.9\n",
                              ["data.csv", "row 4", "not strictly increasing"]),
    "csv duplicated time": (["--free", "R.R"], "t,U,v_C\n0,1,0\n0.001,1,0.5\n0.001,1,0.8\n0.003,1,0.9\n",
                            ["data.csv", "row 4", "duplicated"]),
    "csv irregular sampling": (["--free", "R.R"], "t,U,v_C\n0,1,0\n0.001,1,0.5\n0.005,1,0.8\n0.006,1,0.9\n",
                               ["data.csv", "irregular sampling", "--resample"]),
    "csv no output": (["--free", "R.R"], "t,U\n0,1\n0.001,1\n0.002,1\n", ["data.csv", "v_C"]),
    "scale incompatible units": (["--free", "R.R", "--scale", "v_C=mm:V"], GOOD,
                                 ["--scale", "v_C=mm:V", "'mm'", "'V'", "different dimensions"]),
    "scale unknown unit": (["--free", "R.R", "--scale", "v_C=furlong:m"], GOOD, ["--scale", "'furlong'"]),
    "scale of a missing column": (["--free", "R.R", "--scale", "pos=mm:m"], GOOD, ["data.csv", "pos"]),
    "unknown output": (["--free", "R.R", "--outputs", "tip"], GOOD, ["--outputs", "'tip'", "v_C"]),
    "map to unknown signal": (["--free", "R.R", "--map", "v_C=volts"], GOOD, ["--map", "'volts'", "v_C"]),
    "map twice to one signal": (["--free", "R.R", "--map", "U=U", "--map", "v_C=U"], GOOD,
                                ["--map", "'U'", "'v_C'", "two columns"]),
    "unknown state in x0": (["--free", "R.R", "--x0", "Z=1"], GOOD, ["--x0", "'Z'", "C.Q"]),
    "missing data file": (["--free", "R.R"], "missing", ["missing.csv", "does not exist"]),
    "missing validation file": (["--free", "R.R", "--validate", "nowhere.csv"], GOOD, ["nowhere.csv"]),
    "bad resample": (["--free", "R.R", "--resample", "-1"], GOOD, ["--resample"]),
    "unknown model": (["--free", "R.R"], GOOD, ["no_such_function"]),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_invalid_input_is_one_error_line_and_writes_nothing(tmp_path, capsys, case):
    extra, text, fragments = CASES[case]
    if text == "missing":
        data = str(tmp_path / "missing.csv")
    else:
        data = _write(tmp_path, "data.csv", GOOD if text is None else text)
    model = "systems.examples:no_such_function" if case == "unknown model" else RC
    before = sorted(os.listdir(tmp_path))
    out, report = tmp_path / "out.json", tmp_path / "report"
    rc = main(["fit", model, data, *extra, "--json", str(out), "--report", str(report)])
    err = capsys.readouterr().err
    assert rc == 2
    lines = [line for line in err.splitlines() if line.startswith("phs: error:") or "error:" in line]
    assert lines, err
    message = lines[-1]
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    assert sorted(os.listdir(tmp_path)) == before  # no JSON, no report directory, no temporary file


def test_report_directory_that_is_a_file_is_an_error(tmp_path, capsys):
    data = _write(tmp_path, "data.csv", GOOD)
    blocker = _write(tmp_path, "report", "not a directory")
    rc = main(["fit", RC, data, "--free", "R.R", "--report", blocker, "--json", str(tmp_path / "o.json")])
    assert rc == 2
    assert "report" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["data.csv", "report"]


def test_json_into_missing_directory_is_an_error_before_fitting(tmp_path, capsys):
    data = _write(tmp_path, "data.csv", GOOD)
    rc = main(["fit", RC, data, "--free", "R.R", "--json", str(tmp_path / "nope" / "o.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "nope" in err and "evaluation" not in err
