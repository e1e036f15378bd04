"""A resumed sweep continues only the same study: the identity stored with the results (Parquet metadata,
``OUT.study.json`` beside a CSV) is compared field by field, and another study is refused in one line naming
the field with its stored and requested values (:meth:`phs.workflows.sweep.study.Study.identity`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from phs.errors import InputDataError
from phs.workflows.cli import main
from phs.workflows.sweep import LogUniform, Study, sweep
from phs.workflows.sweep.store import read_rows
from systems.examples import rc_circuit

BASE = ["sweep", "systems.examples:rc_circuit", "--t-end", "1e-3", "--dt", "1e-4", "--input", "step(1, 1e-4)",
        "--range", "R.R=1e3:2e3:3", "--metric", "final:v_C", "--quiet"]


@pytest.fixture(scope="module")
def rc():
    return rc_circuit()


def _study(rc, **kw):
    args = dict(t=np.linspace(0.0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": [1e3, 2e3]}, metrics=["final:v_C"])
    args.update(kw)
    return Study(rc, args.pop("t"), **args)


# each field of the identity, changed alone: (keyword changes of the Study, the words expected)
CHANGES = {
    "params": ({"params": {"C.C": 2e-6}}, r"parameter C\.C stored 1e-06, requested 2e-06"),
    "inputs": ({"u": {"U": 2.0}}, r"inputs stored \{'U': 1\.0\}, requested \{'U': 2\.0\}"),
    "t_end": ({"t": np.linspace(0.0, 2e-3, 11)}, r"t_end stored 0\.001, requested 0\.002"),
    "samples": ({"t": np.linspace(0.0, 1e-3, 21)}, r"samples stored 11, requested 21"),
    "x0": ({"x0": {"C.Q": 1e-7}}, r"x0 stored none, requested \{'C\.Q': 1e-07\}"),
    "rtol": ({"rtol": 1e-6}, r"rtol stored 1e-08, requested 1e-06"),
    "atol": ({"atol": 1e-12}, r"atol stored none, requested 1e-12"),
    "max_steps": ({"max_steps": 500}, r"max_steps stored 20000, requested 500"),
    "metrics": ({"metrics": ["peak:v_C"]}, r"metrics stored \[final_v_C\], requested \[peak_v_C\]"),
    "design": ({"grid": {"R.R": [1e3, 3e3]}}, r"design \(same variables and runs, other values"),
    "n_runs": ({"grid": {"R.R": [1e3, 2e3, 3e3]}}, r"n_runs stored 2, requested 3"),
    "variables": ({"grid": {"C.C": [1e-6, 2e-6]}}, r"variables stored \[R\.R\], requested \[C\.C\]"),
}


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
@pytest.mark.parametrize("field", list(CHANGES))
def test_resuming_with_one_field_changed_is_refused_naming_it(tmp_path, rc, fmt, field):
    if fmt == "parquet":
        pytest.importorskip("pyarrow")
    out = tmp_path / f"r.{fmt}"
    sweep(_study(rc), out, progress=False)
    kept = out.read_bytes()
    change, words = CHANGES[field]
    with pytest.raises(InputDataError, match=r"holds another study \(.*" + words) as info:
        sweep(_study(rc, **change), out, resume=True, progress=False)
    assert "\n" not in str(info.value)
    assert out.read_bytes() == kept  # untouched
    assert sweep(_study(rc), out, resume=True, progress=False).new_runs == 0  # the same study resumes


def test_another_seed_or_sampling_is_named(tmp_path, rc):
    def study(**kw):
        return Study(rc, [0.0, 1e-3], u={"U": 1.0}, distributions={"R.R": LogUniform(500.0, 5e3)}, samples=3,
                     metrics=["final:v_C"], **kw)

    out = tmp_path / "r.csv"
    sweep(study(seed=1), out, progress=False)
    with pytest.raises(InputDataError, match=r"seed stored 1, requested 2"):
        sweep(study(seed=2), out, resume=True, progress=False)
    with pytest.raises(InputDataError, match=r"sampling stored lhs, requested random"):
        sweep(study(seed=1, sampling="random"), out, resume=True, progress=False)


def test_a_changed_model_is_named_by_its_hash(tmp_path, rc):
    out = tmp_path / "r.csv"
    sweep(_study(rc), out, progress=False)
    stored = json.loads((tmp_path / "r.csv.study.json").read_text())["identity"]
    assert stored["model_hash"] == rc.model_hash()
    stored["model_hash"] = "0" * 16  # a model whose structure changed since (same names and values)
    (tmp_path / "r.csv.study.json").write_text(json.dumps({"identity": stored}))
    with pytest.raises(InputDataError, match=rf"model_hash stored 0{{16}}, requested {rc.model_hash()}"):
        sweep(_study(rc), out, resume=True, progress=False)


def test_the_cli_refuses_a_resume_with_other_options_in_one_line(tmp_path, capsys):
    """The reported case: killed after some runs, resumed with another --t-end and a --param."""
    out = str(tmp_path / "r.csv")
    assert main(BASE + ["--out", out]) == 0
    capsys.readouterr()
    argv = [a if a != "1e-3" else "5e-4" for a in BASE] + ["--param", "C.C=2e-6", "--out", out, "--resume"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("phs: error: ") and "\n" not in err
    assert "parameter C.C stored 1e-06, requested 2e-06" in err and "t_end stored 0.001, requested 0.0005" in err
    assert [r["status"] for r in read_rows(out)[0]] == ["ok"] * 3
    assert main(BASE + ["--out", out, "--resume"]) == 0  # the same options continue it


def test_results_written_before_identities_were_stored_still_resume(tmp_path, rc):
    """A CSV without ``OUT.study.json`` (an older study): only the run-by-run design check applies."""
    out = tmp_path / "r.csv"
    sweep(_study(rc), out, progress=False)
    (tmp_path / "r.csv.study.json").unlink()
    assert sweep(_study(rc, rtol=1e-6), out, resume=True, progress=False).new_runs == 0
