"""Many recordings in one diagnosis (``phs diagnose MODEL DATA...``, :func:`diagnose_trials`): the recurring
effect named across trials, the same verdicts and values on a Dask cluster, resuming, refusing a resume of
other options, and the joint fit of shared parameters (:func:`fit_shared`).

The trials are short: the concealed sensor offset of ``examples/concealed_effects.py`` (1.5 s at 1 kHz, three
sizes) for the recurring effect, and the RC circuit of ``systems.examples`` with a sensor offset (the example
of :func:`phs.workflows.diagnose.diagnose`, 401 samples) elsewhere; candidates are restricted to a few effects."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from codegen import simulate
from phs.workflows.cli import main
from phs.workflows.diagnose.pool import on_cluster
from phs.workflows.diagnose.trials import diagnose_trials, fit_shared
from phs.workflows.recording import Recording
from systems.examples import mass_spring_damper, rc_circuit

RC_ARGS = ["systems.examples:rc_circuit", "--free", "R.R", "--effects", "offset,leakage", "--quiet"]


def _write(path, t, cols: dict) -> None:
    header = "t," + ",".join(cols)
    np.savetxt(path, np.column_stack([t, *cols.values()]), delimiter=",", header=header, comments="")


def _rc_trials(folder, offsets=(0.03, 0.05, 0.07)) -> None:
    """RC trials at three input amplitudes, each with a sensor offset and 2 mV of noise."""
    os.makedirs(folder, exist_ok=True)
    t = np.linspace(0, 0.02, 401)
    for i, c in enumerate(offsets):
        u = (1 + 0.5 * i) * np.sin(2 * np.pi * 150 * t)
        y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + c + 0.002 * np.random.default_rng(i).standard_normal(len(t))
        _write(os.path.join(folder, f"amp{i}.csv"), t, {"U {linear}": u, "v_C": y})


def _rc_recordings(tmp_path) -> dict:
    _rc_trials(tmp_path / "data")
    return {f"amp{i}": Recording.from_csv(str(tmp_path / "data" / f"amp{i}.csv")) for i in range(3)}


def _comparable(record) -> dict:
    """A trial's record without its wall times (which differ from run to run)."""
    doc = json.loads(json.dumps(record))
    doc.pop("seconds", None)
    doc.pop("summary", None)  # it states the wall time
    d = doc["diagnosis"]
    d.pop("seconds", None)
    for h in d["hypotheses"]:
        h.pop("seconds", None)
    ((d.get("baseline") or {}).get("starts") or {}).get("check", {}).pop("seconds", None)  # the plain check's wall time
    return doc


@pytest.fixture(scope="module")
def rc_run(tmp_path_factory):
    """The RC trials diagnosed once from the command line into ``out`` (with --json and --plot); tests that
    change them work on a copy."""
    root = tmp_path_factory.mktemp("rc_run")
    _rc_trials(root / "data")
    args = ["diagnose", RC_ARGS[0], str(root / "data"), *RC_ARGS[1:], "--out", str(root / "out"),
            "--json", str(root / "summary.json"), "--plot", str(root / "effects.png")]
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(args)
    return root, args, code, buf.getvalue()


def _copy(rc_run, tmp_path):
    """The finished run's folder copied under ``tmp_path``, and its command line there."""
    import shutil

    root, args, _, printed = rc_run
    shutil.copytree(root / "data", tmp_path / "data")
    shutil.copytree(root / "out", tmp_path / "out")
    return [a.replace(str(root), str(tmp_path)) for a in args[:-4]], printed


def test_folder_of_trials_names_the_recurring_effect(rc_run):
    """Three RC trials, offsets 0.03, 0.05, 0.07 V under 2 mV of noise: offset in 3 of 3, each value to 1 mV."""
    root, _, code, printed = rc_run
    assert code == 0
    assert printed.splitlines()[0].endswith("offset in 3/3")
    doc = json.loads((root / "summary.json").read_text())
    assert json.loads((root / "out" / "summary.json").read_text()) == doc
    top = doc["recurring"][0]
    assert (top["effect"], top["count"], top["of"], top["trials"]) == ("offset", 3, 3, ["amp0", "amp1", "amp2"])
    stats = top["parameters"]["offset.v_C"]
    # 401 samples of 2 mV noise: an offset's standard error is about 0.1 mV; 1 mV leaves room for R.R's share
    assert stats["values"] == pytest.approx([0.03, 0.05, 0.07], abs=1e-3)
    assert stats["std"] == pytest.approx(np.std(stats["values"], ddof=1), rel=1e-12)
    assert stats["mean"] == pytest.approx(0.05, abs=1e-3)
    assert doc["nominal"]["R.R"]["mean"] == pytest.approx(1e3, rel=1e-3)  # the truth's R
    rows = (root / "out" / "summary.csv").read_text().splitlines()
    assert rows[0] == "effect,trials,of,share,parameter,n,mean,std,min,max"
    assert rows[1].startswith("offset,3,3,1,offset.v_C,3,0.0")
    assert rows[2].startswith("nominal,3,3,1,R.R,3,")
    assert sorted(os.listdir(root / "out" / "trials")) == ["amp0.json", "amp1.json", "amp2.json"]
    assert (root / "effects.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_folder_of_concealed_trials_names_the_recurring_effect(tmp_path, capsys):
    """The concealed sensor offset of the electrostatic actuator at three sizes (1.5 s each; about a minute)."""
    from examples.concealed_effects import generate, write_csv

    data = tmp_path / "trials"
    data.mkdir()
    sizes = (0.7, 1.0, 1.4)
    for s in sizes:
        rec, _ = generate("offset", seconds=1.5, seed=1, size=s)
        write_csv(rec, str(data / f"size{s}.csv"))
    out, js, png = tmp_path / "out", tmp_path / "summary.json", tmp_path / "effects.png"
    code = main(["diagnose", "systems.electrostatic_actuator:electrostatic_actuator", str(data), "--free", "k,b,eps",
                 "--effects", "offset,leakage", "--out", str(out), "--json", str(js), "--plot", str(png), "--quiet"])
    printed = capsys.readouterr().out
    assert code == 0
    assert "offset in 3/3" in printed.splitlines()[0]
    doc = json.loads(js.read_text())
    top = doc["recurring"][0]
    assert (top["effect"], top["count"], top["of"]) == ("offset", 3, 3)
    assert sorted(os.listdir(out / "trials")) == [f"size{s}.json" for s in sizes]
    assert json.loads((out / "summary.json").read_text()) == doc
    [param] = [k for k in top["parameters"] if k.startswith("offset.")]
    stats = top["parameters"][param]
    values = dict(zip(stats["trials"], stats["values"], strict=True))
    # the truth's offset and gain error both scale with the size: the fitted offset grows with it
    assert values["size0.7"] < values["size1.0"] < values["size1.4"]
    assert stats["std"] == pytest.approx(np.std(stats["values"], ddof=1), rel=1e-12)
    rows = (out / "summary.csv").read_text().splitlines()
    assert rows[0] == "effect,trials,of,share,parameter,n,mean,std,min,max"
    assert rows[1].startswith(f"offset,3,3,1,{param},3,")
    assert png.read_bytes()[:4] == b"\x89PNG"


def _cluster(processes: bool):
    distributed = pytest.importorskip("dask.distributed")
    # in-process: one worker thread (tasks one at a time, no import or code generation to repeat); processes:
    # two workers of one thread each, every task pickled to them as to a remote cluster
    cluster = distributed.LocalCluster(n_workers=2 if processes else 1, threads_per_worker=1, processes=processes,
                                       dashboard_address=None, silence_logs=40)
    return cluster, distributed.Client(cluster)


@pytest.fixture(scope="module")
def client():
    """An in-process LocalCluster, always closed."""
    cluster, c = _cluster(processes=False)
    try:
        yield c
    finally:
        c.close()
        cluster.close()


def _local_and_dask(tmp_path, scheduler):
    from components.candidates import LIBRARY

    recs = _rc_recordings(tmp_path)
    cands = [c for c in LIBRARY if c.effect in ("offset", "leakage")]
    local = diagnose_trials(rc_circuit(), recs, free=["R.R"], candidates=cands, n_jobs=2)
    dask = diagnose_trials(rc_circuit(), recs, free=["R.R"], candidates=cands, scheduler=scheduler)
    return local, dask


def test_trials_on_a_dask_cluster_match_the_local_run(tmp_path, client):
    local, dask = _local_and_dask(tmp_path, client)
    assert [r["verdict"]["effect"] for r in local.records] == ["offset"] * 3
    # the same computations elsewhere: identical verdicts and values, to the last bit
    assert [_comparable(r) for r in dask.records] == [_comparable(r) for r in local.records]


@pytest.mark.slow
def test_trials_on_dask_worker_processes_match_the_local_run(tmp_path):
    """As above on two worker processes (about 20 s: the workers start, import and generate their functions)."""
    cluster, c = _cluster(processes=True)
    try:
        local, dask = _local_and_dask(tmp_path, c)
        with on_cluster(c):  # the hypotheses of one diagnosis spread over the two workers
            from phs.workflows.diagnose import diagnose
            from phs.workflows.diagnose.trials_summary import trial_record

            rec = _rc_recordings(tmp_path)["amp1"]
            there = diagnose(rc_circuit(), rec, free=["R.R"], n_jobs=2)
    finally:
        c.close()
        cluster.close()
    assert [_comparable(r) for r in dask.records] == [_comparable(r) for r in local.records]
    here = diagnose(rc_circuit(), rec, free=["R.R"], n_jobs=2)
    assert _comparable(trial_record("a", there)) == _comparable(trial_record("a", here))


def test_hypothesis_fits_on_a_dask_cluster_match_the_local_run(tmp_path, client):
    from components.candidates import LIBRARY
    from phs.workflows.diagnose import diagnose
    from phs.workflows.diagnose.trials_summary import trial_record

    rec = _rc_recordings(tmp_path)["amp1"]
    cands = [c for c in LIBRARY if c.effect in ("offset", "leakage", "series_resistance")]
    here = diagnose(rc_circuit(), rec, free=["R.R"], candidates=cands, n_jobs=2)
    with on_cluster(client):
        there = diagnose(rc_circuit(), rec, free=["R.R"], candidates=cands, n_jobs=2)
    assert len(here.hypotheses) > 1  # several fits to spread
    assert _comparable(trial_record("a", there)) == _comparable(trial_record("a", here))


def test_command_line_on_a_scheduler_address(tmp_path, client, capsys):
    _rc_trials(tmp_path / "data")
    code = main(["diagnose", RC_ARGS[0], str(tmp_path / "data"), *RC_ARGS[1:], "--scheduler", client.scheduler.address])
    assert code == 0 and "offset in 3/3" in capsys.readouterr().out


def test_resume_reruns_only_the_missing_trial(rc_run, tmp_path, capsys):
    args, first = _copy(rc_run, tmp_path)
    out = tmp_path / "out"
    kept = {n: (out / "trials" / n).read_bytes() for n in ("amp0.json", "amp2.json")}
    stamps = {n: os.stat(out / "trials" / n).st_mtime_ns for n in kept}
    (out / "trials" / "amp1.json").unlink()  # as if the run had been killed before amp1 finished
    assert main([*args, "--resume"]) == 0
    second = capsys.readouterr().out
    assert "(1 run now, 2 resumed)" in second
    assert {n: (out / "trials" / n).read_bytes() for n in kept} == kept
    assert {n: os.stat(out / "trials" / n).st_mtime_ns for n in kept} == stamps
    assert (out / "trials" / "amp1.json").exists()
    # the same table: the rerun trial repeats its verdict and values
    assert second.splitlines()[1:4] == first.splitlines()[1:4]


def test_resume_with_other_options_or_data_is_refused_in_one_line(rc_run, tmp_path, capsys):
    args, _ = _copy(rc_run, tmp_path)
    out = tmp_path / "out"
    before = {n: (out / "trials" / n).read_bytes() for n in os.listdir(out / "trials")}
    other = [a if a != "offset,leakage" else "offset" for a in args]
    assert main([*other, "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "effects stored [leakage, offset], requested [offset]" in err and "amp0.json" in err
    _rc_trials(tmp_path / "data", offsets=(0.03, 0.05, 0.08))  # amp2 recorded again
    (out / "trials" / "amp0.json").unlink()
    (out / "trials" / "amp1.json").unlink()
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "amp2.json" in err and "data_sha256 stored" in err
    assert main(args) == 2  # without --resume nothing is overwritten
    assert "--resume" in capsys.readouterr().err
    assert (out / "trials" / "amp2.json").read_bytes() == before["amp2.json"]


def test_options_of_several_recordings_are_refused_with_one(tmp_path, capsys):
    _rc_trials(tmp_path / "data")
    one = str(tmp_path / "data" / "amp0.csv")
    assert main(["diagnose", RC_ARGS[0], one, *RC_ARGS[1:], "--out", str(tmp_path / "o")]) == 2
    assert "--out is for several recordings" in capsys.readouterr().err
    assert main(["diagnose", RC_ARGS[0], str(tmp_path / "data"), *RC_ARGS[1:], "--report", str(tmp_path / "r")]) == 2
    assert "--report is for one recording" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


def test_shared_parameters_are_fitted_jointly():
    """Three recordings of a mass-spring-damper with one stiffness and three dampings: k shared, b per recording.
    Noise-free data: the joint fit recovers the truth to the fit's tolerance (1e-4 relative)."""
    t = np.linspace(0, 10, 501)
    recs, truth_b = {}, {"r0": 0.3, "r1": 0.6, "r2": 1.2}
    for name, b in truth_b.items():
        F = np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t)
        y = simulate(mass_spring_damper().with_params({"k.K": 6.0, "b.b": b}), t, u={"F": F})["position"]
        recs[name] = Recording.from_arrays(t, {"F": F, "position": y}, holds={"F": "linear"})
    fit = fit_shared(mass_spring_damper(), recs, ["k.K"], ["b.b"])
    assert fit["shared"]["k.K"] == pytest.approx(6.0, rel=1e-4)
    for name, b in truth_b.items():
        assert fit["local"][name]["b.b"] == pytest.approx(b, rel=1e-4)


def test_shared_parameters_are_held_in_every_trial(tmp_path):
    from components.candidates import LIBRARY

    recs = _rc_recordings(tmp_path)
    res = diagnose_trials(rc_circuit(), recs, shared=["C.C"], free=["R.R"], n_jobs=1, out=str(tmp_path / "out"),
                          candidates=[c for c in LIBRARY if c.effect == "offset"])
    assert set(res.shared["shared"]) == {"C.C"}
    c = res.shared["shared"]["C.C"]
    for r in res.records:  # C.C is not refitted: every trial's final model holds the joint value
        assert r["diagnosis"]["final"]["parameters"].get("C.C", c) == c
        assert "C.C" not in r["nominal"]
        assert r["identity"]["shared_values"] == {"C.C": c}
    assert json.loads((tmp_path / "out" / "shared.json").read_text())["fit"]["shared"] == {"C.C": c}
    assert "Shared by every trial" in res.summary()
