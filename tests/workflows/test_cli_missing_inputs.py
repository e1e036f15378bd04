"""``phs fit`` and ``phs diagnose`` with ``--input NAME=EXPR``: an input a recording has no column for is filled
from a law (phs.workflows.cli_recordings.missing_input_laws, fill_inputs, model_and_recordings).

The model: a mass on a spring and damper driven by two forces, ``F`` (recorded in every run) and ``pulses_N``
(force pulses applied only in the validation run; the training CSV has no column for it)."""

from __future__ import annotations

import csv
import json
import os

import numpy as np
import pytest

from phs.workflows.cli import build_parser, main
from phs.workflows.cli_recordings import model_and_recordings

K_TRUE = 4.0
MODEL_SOURCE = '''
from components import Damper, ForceSource, LinearSpring, Mass
from phs import Measured, interconnect, series, symbol_of_state


def msd2():
    return interconnect(
        "msd2",
        [ForceSource("F"), ForceSource("pulses_N"), Mass("m", m=1.0), LinearSpring("k", K=4.0), Damper("b", b=0.4)],
        [series("F", "pulses_N", "m", "k", "b")],
        measured=[Measured("position", symbol_of_state("k.l"), "m", "spring elongation")],
    )
'''
PULSES = "square(2.0, 0.25, duty=0.2, bipolar=0, start=4.0)"  # 0.8 s pulses of 2 N every 4 s from t = 4 s


def _truth(model: str, t, pulses):
    """Position of the true model (K = 4) under F = sin(1.3 t) + 0.5 sin(3.1 t) and the force law ``pulses``."""
    from codegen import simulate
    from phs.signals import parse_expression
    from phs.workflows.loader import load_model

    force = np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t)
    law = parse_expression(pulses)
    y = simulate(load_model(model), t, u={"F": force, "pulses_N": law}, rtol=1e-10)["position"]
    return force, np.broadcast_to(np.asarray(law(t), float), t.shape), y


def _write(path, columns: dict) -> str:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(columns))
        w.writerows([[f"{v:.17g}" for v in row] for row in zip(*columns.values(), strict=True)])
    return str(path)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """The model, train.csv without a pulses_N column (no pulses in that run), val.csv with the pulses
    recorded (its header states their law, as phs simulate --out writes it), and the validation run's
    position with and without the pulses."""
    d = tmp_path_factory.mktemp("rec")
    (d / "msd2.py").write_text(MODEL_SOURCE)
    model = f"{d / 'msd2.py'}:msd2"
    t = np.linspace(0.0, 10.0, 201)
    f, _, y_without = _truth(model, t, "0")
    train = _write(d / "train.csv", {"t": t, "F": f, "position": y_without})
    f, p, y = _truth(model, t, PULSES)
    val = _write(d / "val.csv", {"t": t, "F": f, f"pulses_N [N] {{{PULSES}}}": p, "position": y})
    return model, train, val, y, y_without


def test_recordings_are_filled_only_where_a_column_is_missing(recordings):
    model, train, val, _, _ = recordings
    late = "square(2.0, 0.25, duty=0.2, bipolar=0, start=4.05)"  # an edge between the samples 4.0 and 4.1
    args = build_parser().parse_args(["fit", model, train, "--free", "k.K", "--validate", val, "--resample", "0.1",
                                      "--input", f"pulses_N=2 + {late}", "--hold", "pulses_N=zoh"])
    system, rec, check, free, outputs, _ = model_and_recordings(args)
    assert free == ["k.K"] and outputs == ["position"]
    # train.csv lacks the column: the law's values on the resampled grid, and the law itself between the samples
    assert len(rec) == 101 and rec.dt == pytest.approx(0.1)
    assert rec["pulses_N"].tolist() == [2.0 + 2.0 * (k > 40 and 1 <= k % 40 <= 8) for k in range(101)]
    law = rec.input_signal("pulses_N")
    assert (float(law(4.04)), float(law(4.06)), float(law(4.84)), float(law(4.86))) == (2.0, 4.0, 4.0, 2.0)
    assert rec.units["pulses_N"] == "N" and rec.source == train
    # val.csv has the column: its own samples (not 2 N more) on the same grid, held as --hold says (the option
    # concerns the files that have the column; train.csv has none)
    recorded = np.loadtxt(val, delimiter=",", skiprows=1, usecols=2)[::2]  # the resampled grid is every other row
    assert check["pulses_N"].tolist() == recorded.tolist() and recorded.max() == 2.0
    assert check.holds["pulses_N"] == "zoh" and float(check.input_signal("pulses_N")(4.75)) == 2.0  # linear: 1.0
    assert system.input_names == ["F", "pulses_N"]


def test_fit_with_a_missing_input_filled_recovers_the_stiffness(tmp_path, recordings, capsys):
    model, train, val, y_val, y_without = recordings
    out = tmp_path / "fit.json"
    rc = main(["fit", model, train, "--free", "k.K", "--param", "k.K=3.0", "--input", "pulses_N=0",
               "--validate", val, "--json", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "--input pulses_N=0" in captured.out
    doc = json.loads(out.read_text())
    # noise-free data generated at rtol 1e-10: the fit lands on K = 4 to the integrator's accuracy
    assert doc["values"]["k.K"] == pytest.approx(K_TRUE, rel=1e-4)
    assert doc["input"] == ["pulses_N=0"]
    # the validation run kept its recorded pulses: a near-perfect fit, where reading them as 0 gives about 3 %
    assert doc["validation"]["fit_percent"]["position"] > 99.0
    without = 100 * (1 - np.linalg.norm(y_val - y_without) / np.linalg.norm(y_val - y_val.mean()))
    assert without < 50.0


def test_diagnose_with_a_missing_input_filled_runs(tmp_path, recordings, capsys):
    model, train, val, _, _ = recordings
    out = tmp_path / "d.json"
    rc = main(["diagnose", model, train, "--input", "pulses_N=0", "--validate", val, "--free", "k.K",
               "--effects", "coulomb_friction", "--no-discover", "--jobs", "1", "--json", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    doc = json.loads(out.read_text())
    assert doc["baseline"]["parameters"]["k.K"] == pytest.approx(K_TRUE, rel=1e-3)
    assert doc["baseline"]["validation_fit_percent"]["position"] > 99.0  # the validation run's pulses were read


def test_without_the_option_the_missing_column_is_named(recordings, capsys):
    model, train, _, _, _ = recordings
    rc = main(["fit", model, train, "--free", "k.K", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "'pulses_N'" in err[0]


CASES = {
    # id: (--input value, fragments the one-line message must contain)
    "not an input": ("pulse=0", ["--input", "'pulse'", "inputs: F, pulses_N"]),
    "a CSV file": ("pulses.csv", ["--input", "'pulses.csv'", "NAME=EXPR"]),
    "a bare expression": ("square(1.0, 2)", ["--input", "NAME=EXPR", "F, pulses_N"]),
    "an unreadable expression": ("pulses_N=open('x')", ["--input", "pulses_N"]),
}


@pytest.mark.parametrize("command", ["fit", "diagnose"])
@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_bad_input_option_is_one_line_naming_it_and_writes_nothing(tmp_path, recordings, capsys, command, case):
    model, train, _, _, _ = recordings
    value, fragments = CASES[case]
    before = sorted(os.listdir(tmp_path))
    rc = main([command, model, train, "--free", "k.K", "--input", value, "--json", str(tmp_path / "o.json"), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    for fragment in fragments:
        assert fragment in err[0], (fragment, err[0])
    assert sorted(os.listdir(tmp_path)) == before
