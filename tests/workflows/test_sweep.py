"""Design studies (phs.workflows.sweep): executors agree, interrupted studies resume, failures are recorded.

* The same 200-run study of the MSD HASEL (step amplitude and damping on a
  grid, load mass sampled; about a third of the runs leave the validity
  domain) evaluated serially, in threads and on a Dask ``LocalCluster`` of two
  worker processes gives bitwise the same table (one code path: the batch
  evaluator's functions), and agrees with a plain loop over
  ``Simulator.run`` computing the same metrics to 1e-12 relative (it is
  another code path through the same integrators; in practice it is bitwise too).
* A study killed at each dangerous point of its store (a part's or the results
  file's temporary file synced; before and after the rename of a part or of the
  results file) and resumed ends with every run exactly once, the values of an
  uninterrupted study and no temporary file; only the missing runs run again.
* Failing runs (domain exits, a metric raising, a failing input function) are
  recorded with their errors and do not stop the study.
"""

from __future__ import annotations

import logging
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from codegen import Simulator
from phs import DomainError, InputDataError, ParameterError
from phs.signals import step
from phs.workflows.cli import main
from phs.workflows.sweep import (
    LogNormal,
    LogUniform,
    MultivariateNormal,
    Normal,
    Study,
    StudyResult,
    Uniform,
    from_fit,
    sweep,
)
from phs.workflows.sweep.metrics import Metric, energy, final, fit, metric, peak, rise_time, rise_time_of, values_at
from phs.workflows.sweep.store import read_rows

ROOT = Path(__file__).resolve().parents[2]
REL = 1e-12  # relative agreement of two code paths through the same integrators (observed: bitwise)
X0 = {"x": 2.9e-5}  # near the 0 kV equilibrium under the default load


# -- the 200-run study -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def msd_hasel_system():
    from systems.msd_hasel import msd_hasel

    return msd_hasel(fit_length="mm")


def overshoot(res) -> float:
    """A user's metric: how far the displacement overshoots its final value."""
    y = res["displacement"]
    return float(y.max() - y[-1])


def step_input(values: dict) -> dict:
    return {"V": step(values["V_kV"] * 1e3, 0.02)}


def study_200(system) -> Study:
    return Study(system, np.linspace(0.0, 0.2, 201), u_for=step_input, x0=X0,
                 grid={"V_kV": np.linspace(0.5, 5.0, 10), "b": [1.0, 2.0, 5.0, 10.0]},
                 distributions={"m": Uniform(0.03, 0.07)}, samples=5, seed=3,
                 metrics={"final": "final:displacement", "peak": "peak:displacement",
                          "rise": rise_time("displacement", start=0.02), "energy": "energy",
                          "margin": "passivity_margin", "overshoot": overshoot})


@pytest.fixture(scope="module")
def dask_client():
    """A LocalCluster of two worker processes (one thread each), always closed."""
    distributed = pytest.importorskip("dask.distributed")
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this test module
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=logging.ERROR)
    try:
        client = distributed.Client(cluster, timeout="60s")
        try:
            yield client
        finally:
            client.close(timeout=20)
    finally:
        cluster.close(timeout=20)
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])


def _table(res: StudyResult) -> dict:
    return {c: res[c] for c in res.columns}


def _assert_tables_equal(a: dict, b: dict, what: str) -> None:
    assert list(a) == list(b), what
    for c in a:
        if a[c].dtype == object:
            assert list(a[c]) == list(b[c]), f"{what}: column {c}"
        else:
            assert np.array_equal(a[c], b[c], equal_nan=True), f"{what}: column {c}"


def test_serial_threads_and_dask_give_the_same_200_runs(msd_hasel_system, dask_client, tmp_path):
    study = study_200(msd_hasel_system)
    assert study.n_runs == 200
    serial = sweep(study, tmp_path / "serial.parquet", threads=1, progress=False)
    threaded = sweep(study, tmp_path / "threads.csv", threads=2, progress=False)
    dask = sweep(study, tmp_path / "dask.parquet", scheduler=dask_client, chunk_size=20, progress=False)
    ok = serial.ok
    assert 40 < int((~ok).sum()) < 120, "the study must mix successful and failing runs"
    assert all("validity domain" in e for _, e in serial.failed)
    _assert_tables_equal(_table(serial), _table(threaded), "threads vs serial")
    _assert_tables_equal(_table(serial), _table(dask), "dask vs serial")
    # what was written is what was returned, in both formats
    _assert_tables_equal(_table(serial), _table(StudyResult.read(tmp_path / "serial.parquet")), "parquet file")
    _assert_tables_equal(_table(threaded), _table(StudyResult.read(tmp_path / "threads.csv")), "csv file")
    assert StudyResult.read(tmp_path / "dask.parquet").variables == ["V_kV", "b", "m"]
    assert not any(p.name.endswith(".parts") for p in tmp_path.iterdir())

    # a plain loop over the project's simulator computing the same metrics
    sim = Simulator(msd_hasel_system)
    t = study.t
    for k in range(study.n_runs):
        values = study.values(k)
        assert np.array_equal([serial[v][k] for v in study.variables], [values[v] for v in study.variables])
        try:
            res = sim.run(t, u=step_input(values), x0=X0, params={"b": values["b"], "m": values["m"]})
        except DomainError as exc:
            # the same condition; the simulator names the first point outside (its integration stops there),
            # a batch run the first grid point outside (it integrates on: codegen._batch_plan), at most a step later
            got, want = serial["error"][k], str(exc)
            assert serial["status"][k] == "failed" and _condition(got) == _condition(want), (got, want)
            assert 0.0 <= _exit_time(got) - _exit_time(want) <= t[1] - t[0] + 1e-12, (got, want)
            continue
        assert serial["status"][k] == "ok", serial["error"][k]
        for m in study.metrics:
            (expected,) = m(res)
            got = serial[m.name][k]
            assert got == pytest.approx(expected, rel=REL, abs=1e-300), (k, m.name)


def _exit_time(message: str) -> float:
    return float(re.search(r"left the validity domain at t=([-+0-9.eE]+)", message).group(1))


def _condition(message: str) -> str:
    return re.search(r"at t=[-+0-9.eE]+: (.*?), value", message).group(1)


def test_dask_scheduler_given_by_address(msd_hasel_system, dask_client):
    """The executor connects to a scheduler by address (and closes its own client)."""
    study = Study(msd_hasel_system, np.linspace(0.0, 0.1, 51), u={"V": step(1e3, 0.02)}, x0=X0,
                  grid={"b": [2.0, 4.0, 8.0]}, metrics=["peak:displacement"])
    remote = sweep(study, scheduler=dask_client.scheduler.address, progress=False)
    local = sweep(study, threads=1, progress=False)
    _assert_tables_equal(_table(remote), _table(local), "by address")


# -- interruption and resume -------------------------------------------------------------------------
# The study runs in a subprocess whose os.fsync / os.replace (and the store's atomic writer) stop the process (os._exit: no cleanup, no
# flush, as a SIGKILL) at exactly one dangerous point of the store: the nth time a part's or the results
# file's temporary file has been synced, or just before / just after the nth rename of a part or of the
# results file.  Chunks of 4 runs, the results file rewritten after every chunk (flush_seconds=0): 10 parts,
# 10 rewrites, deterministic.
KILLED = 86
KILLED_STUDY = """
import os, sys
import numpy as np
from phs.workflows.sweep import Study, sweep, Uniform
from systems.examples import rc_circuit

def build():
    return Study(rc_circuit(), np.linspace(0.0, 2e-3, 41), u={"U": 1.0}, grid={"R.R": np.linspace(500.0, 2000.0, 4)},
                 distributions={"C.C": Uniform(5e-7, 2e-6)}, samples=10, seed=1,
                 metrics={"final": "final:v_C", "energy": "energy"})

def kill_at(out, point, nth):
    # stop the process at the nth occurrence of point: part-fsynced, part-before-rename, part-after-rename,
    # results-fsynced, results-before-rename, results-after-rename
    import phs.workflows.sweep.store as store

    real_fsync, real_replace, real_write = os.fsync, os.replace, store.write_atomic
    parts = out + ".parts"
    state = {"writing": None, "seen": 0}

    def kind_of(path):  # a part, or the results file (written staged in the parts, then renamed onto out)
        path = os.path.abspath(path)
        if path == out:
            return "results"
        if os.path.dirname(path) == parts:
            return "part" if os.path.basename(path).startswith("part-") else "staged"
        return None

    def stop_if(key):
        if key == point:
            state["seen"] += 1
            if state["seen"] == nth:
                os._exit(int(sys.argv[4]))

    def write_atomic(path, data):
        state["writing"] = {"part": "part", "staged": "results"}.get(kind_of(path))
        try:
            real_write(path, data)
        finally:
            state["writing"] = None

    def fsync(fd):
        real_fsync(fd)
        if state["writing"] is not None:  # the temporary file of a part or of the results file is on disk
            stop_if(state["writing"] + "-fsynced")

    def replace(src, dst):
        kind = kind_of(dst)
        if kind in ("part", "results"):
            stop_if(kind + "-before-rename")
        real_replace(src, dst)
        if kind in ("part", "results"):
            stop_if(kind + "-after-rename")

    store.write_atomic, os.fsync, os.replace = write_atomic, fsync, replace

if __name__ == "__main__":
    out, point, nth = os.path.abspath(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    kill_at(out, point, nth)
    sweep(build(), out, chunk_size=4, threads=1, progress=False, flush_seconds=0)
"""
# (point, nth, runs on disk when killed, leftover in the part directory that resuming must remove)
KILL_POINTS = [
    ("part-fsynced", 1, 0, ".tmp-"),             # before the first rename: only a temporary file exists
    ("part-before-rename", 3, 8, ".tmp-"),
    ("part-after-rename", 1, 4, None),
    ("part-after-rename", 3, 12, None),
    ("results-fsynced", 1, 4, ".tmp-"),          # the first results file, synced, not yet staged
    ("results-before-rename", 1, 4, "results."),  # staged, not yet renamed onto OUT (which does not exist)
    ("results-before-rename", 3, 12, "results."),  # staged, OUT holds the rows of the previous rewrite
    ("results-after-rename", 3, 12, None),
    ("results-after-rename", 10, 40, None),       # the final rewrite: the parts are not yet removed
]


@pytest.fixture(scope="module")
def killed_study(tmp_path_factory):
    """The study of KILLED_STUDY, its script, and the table of an uninterrupted run."""
    script = tmp_path_factory.mktemp("killed") / "study.py"
    script.write_text(KILLED_STUDY)
    namespace: dict = {"__name__": "killed_study"}
    exec(compile(KILLED_STUDY, str(script), "exec"), namespace)
    study = namespace["build"]()
    reference = sweep(study, threads=1, progress=False)
    return script, study, _table(reference)


@pytest.mark.parametrize(("point", "nth", "on_disk", "leftover"), KILL_POINTS)
def test_study_killed_at_each_dangerous_point_resumes_with_every_run_exactly_once(tmp_path, killed_study, point,
                                                                                   nth, on_disk, leftover):
    script, study, reference = killed_study
    out = tmp_path / "results.parquet"
    parts = Path(str(out) + ".parts")
    proc = subprocess.run([sys.executable, str(script), str(out), point, str(nth), str(KILLED)], cwd=ROOT, capture_output=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == KILLED, f"the kill point was not reached (exit {proc.returncode}): " \
                                      + proc.stderr.decode()[-2000:]
    left = sorted(p.name for p in parts.iterdir() if not p.name.startswith("part-")) if parts.is_dir() else []
    if leftover is None:
        assert not left
    else:
        assert left and all(name.startswith(leftover) for name in left), left
    with pytest.raises(InputDataError, match="resume"):
        sweep(study, out, progress=False)  # nothing is overwritten without resume
    done_before = set()
    for src in ([out] if out.exists() else []) + sorted(parts.glob("part-*.parquet")):
        done_before |= {int(r["run"]) for r in read_rows(src)[0]}
    assert len(done_before) == on_disk

    resumed = sweep(study, out, resume=True, threads=2, progress=False)
    assert resumed.new_runs == study.n_runs - on_disk  # finished runs are not redone
    rows, _ = read_rows(out)
    assert sorted(int(r["run"]) for r in rows) == list(range(study.n_runs))  # every run exactly once
    assert not parts.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["results.parquet"]  # no temp file
    _assert_tables_equal(_table(resumed), reference, "resumed vs uninterrupted")
    _assert_tables_equal(_table(StudyResult.read(out)), reference, "file vs uninterrupted")


def test_a_refused_resume_leaves_the_leftovers_of_a_kill_alone(tmp_path, rc):
    """Leftovers are removed only once the files on disk are known to belong to the study resumed."""
    def build(metric):
        return Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3, 2e3]}, metrics=[metric])

    out = tmp_path / "r.csv"
    parts = Path(str(out) + ".parts")
    parts.mkdir()
    (parts / "part-00000000000000000001-abcdef01.csv").write_text("run,R.R,final_v_C,status,error\n0,1000.0,0.5,ok,\n")
    orphan = parts / ".tmp-x1y2z3.csv"
    orphan.write_text("run,R.R,final_v_")
    with pytest.raises(InputDataError, match="columns differ"):
        sweep(build("peak:v_C"), out, resume=True, progress=False)
    assert orphan.exists()
    res = sweep(build("final:v_C"), out, resume=True, progress=False)
    assert res.new_runs == 1 and not parts.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.csv.study.json"]  # the CSV's study beside it


def test_interrupted_in_process_study_keeps_its_finished_runs(tmp_path, rc):
    """Ctrl-C: the finished chunks are consolidated into the file; resume runs only the rest."""
    calls = []

    def final_or_interrupt(res):
        calls.append(1)
        if len(calls) == 23:
            raise KeyboardInterrupt
        return float(res["v_C"][-1])

    def build(fn):
        return Study(rc, np.linspace(0.0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": np.linspace(500.0, 2000.0, 40)},
                     metrics={"final": fn})

    out = tmp_path / "r.csv"
    with pytest.raises(KeyboardInterrupt):
        sweep(build(final_or_interrupt), out, chunk_size=5, threads=1, progress=False)
    kept = sorted(int(r["run"]) for r in read_rows(out)[0])
    assert kept == list(range(20))  # four whole chunks; the interrupted one is not recorded
    resumed = sweep(build(lambda res: float(res["v_C"][-1])), out, resume=True, progress=False)
    assert resumed.new_runs == 20 and resumed["run"].tolist() == list(range(40)) and resumed.ok.all()


def test_resuming_another_study_is_refused(tmp_path, rc):
    def build(seed):
        return Study(rc, [0.0, 1e-3], u={"U": 1.0}, distributions={"R.R": LogUniform(500.0, 5e3)}, samples=6,
                     seed=seed, metrics=["final:v_C"])

    out = tmp_path / "r.parquet"
    sweep(build(0), out, progress=False)
    with pytest.raises(InputDataError, match=r"holds another study \(seed stored 0, requested 1\)"):
        sweep(build(1), out, resume=True, progress=False)
    other = Study(rc, [0.0, 1e-3], u={"U": 1.0}, distributions={"R.R": LogUniform(500.0, 5e3)}, samples=6,
                  metrics=["peak:v_C"])
    with pytest.raises(InputDataError, match=r"metrics stored \[final_v_C\], requested \[peak_v_C\]"):
        sweep(other, out, resume=True, progress=False)
    assert len(read_rows(out)[0]) == 6  # untouched


# -- failures are recorded ---------------------------------------------------------------------------------
def test_failing_runs_are_recorded_with_their_errors(msd_hasel_system, rc):
    def bad_metric(res):
        if res.p[0] > 1500.0:
            raise ValueError("too large")
        return 1.0

    def inputs(values):
        if values["R.R"] < 600.0:
            raise RuntimeError("no input for this run")
        return {"U": 1.0}

    study = Study(rc, np.linspace(0, 1e-3, 11), u_for=inputs, grid={"R.R": [500.0, 1000.0, 2000.0]},
                  metrics={"final": "final:v_C", "bad": bad_metric})
    res = sweep(study, progress=False)
    assert res["status"].tolist() == ["failed", "ok", "failed"]
    assert "preparing the run's inputs failed: RuntimeError: no input for this run" in res["error"][0]
    assert np.isnan(res["final"][0])
    assert res["error"][2] == "metric 'bad': ValueError: too large"
    assert res["final"][2] == pytest.approx(1 - math.exp(-1e-3 / (2000.0 * 1e-6)), rel=1e-6)  # others still measured

    # domain exits of the MSD HASEL: a 5 kV step with the printed damping overshoots past the input map's zero
    s = msd_hasel_system
    st_ = Study(s, np.linspace(0, 0.15, 151), u={"V": step(5e3, 0.02)}, x0=X0, grid={"b": [1.0, 10.0]},
                metrics=["peak:displacement"])
    r = sweep(st_, threads=2, progress=False)
    assert r["status"].tolist() == ["failed", "ok"]
    with pytest.raises(DomainError) as exc:
        Simulator(s).run(st_.t, u={"V": step(5e3, 0.02)}, x0=X0, params={"b": 1.0})
    got, want = r["error"][0], str(exc.value)  # the same condition, named at most one grid step later
    assert _condition(got) == _condition(want) and "input map" in got, (got, want)
    assert 0.0 <= _exit_time(got) - _exit_time(want) <= st_.t[1] - st_.t[0] + 1e-12, (got, want)
    assert "failed (1 runs)" in r.summary()


def test_retry_failed_runs_them_again(tmp_path, rc):
    state = {"fail": True}

    def flaky(res):
        if state["fail"] and res.p[0] == 1000.0:
            raise ValueError("flaky")
        return float(res["v_C"][-1])

    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [500.0, 1000.0]}, metrics={"v": flaky})
    out = tmp_path / "r.csv"
    assert sweep(study, out, progress=False)["status"].tolist() == ["ok", "failed"]
    state["fail"] = False
    assert sweep(study, out, resume=True, progress=False).new_runs == 0  # failed runs are finished runs
    again = sweep(study, out, resume=True, retry_failed=True, progress=False)
    assert again.new_runs == 1 and again["status"].tolist() == ["ok", "ok"]
    assert [r["status"] for r in read_rows(out)[0]] == ["ok", "ok"]


# -- designs and distributions ---------------------------------------------------------------------------
def test_grid_times_samples_design(rc):
    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [1.0e3, 2.0e3, 3.0e3]},
                  distributions={"C.C": Uniform(1e-6, 2e-6)}, samples=4, metrics=["final:v_C"])
    d = study.design
    assert study.n_runs == 12
    assert d["R.R"].tolist() == [1e3] * 4 + [2e3] * 4 + [3e3] * 4  # the first axis varies slowest
    assert np.array_equal(d["C.C"][:4], d["C.C"][4:8]) and np.array_equal(d["C.C"][:4], d["C.C"][8:])  # same samples
    assert len(set(d["C.C"][:4])) == 4


@settings(max_examples=25, deadline=None, database=None, derandomize=True)
@given(n=st.integers(1, 60), seed=st.integers(0, 10_000), lo=st.floats(-5.0, 5.0), width=st.floats(0.1, 10.0))
def test_latin_hypercube_puts_one_sample_in_each_stratum(rc, n, seed, lo, width):
    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, distributions={"R.R": Uniform(lo, lo + width)}, samples=n, seed=seed,
                  metrics=["final:v_C"])
    q = (study.design["R.R"] - lo) / width
    bins = np.minimum((q * n).astype(int), n - 1)
    assert sorted(bins.tolist()) == list(range(n))


def test_distributions_transform_quantiles_as_their_laws():
    q = np.array([[0.025], [0.5], [0.975]])
    assert Normal(2.0, 0.5).transform(q)[:, 0] == pytest.approx([2.0 - 1.959964 * 0.5, 2.0, 2.0 + 1.959964 * 0.5],
                                                                  rel=1e-6)
    assert LogNormal(3.0, 0.2).transform(q)[:, 0] == pytest.approx(3.0 * np.exp(0.2 * np.array([-1.959964, 0, 1.959964])),
                                                                     rel=1e-6)
    assert LogUniform(1e-3, 1e3).transform(np.array([[0.25], [0.75]]))[:, 0] == pytest.approx([10**-1.5, 10**1.5])
    cov = np.array([[4.0, 1.2], [1.2, 1.0]])
    z = MultivariateNormal([1.0, np.log(5.0)], cov, log=[False, True])
    rng = np.random.default_rng(0)
    x = z.transform(rng.uniform(size=(200_000, 2)))
    # Monte Carlo: 200k samples estimate the covariance to ~0.5 %; 3 % leaves room for the seed
    emp = np.cov(np.column_stack([x[:, 0], np.log(x[:, 1])]).T)
    assert emp == pytest.approx(cov, rel=0.03, abs=0.03)
    for bad in (lambda: Uniform(1.0, 1.0), lambda: LogUniform(0.0, 1.0), lambda: Normal(0.0, -1.0),
                lambda: MultivariateNormal([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])):
        with pytest.raises(InputDataError):
            bad()


def test_from_fit_samples_the_identified_uncertainty(rc):
    """A fit's standard errors and correlation become the study's joint distribution (log-normal for log-scaled)."""
    doc = {"free": ["R.R", "C.C"], "values": {"R.R": 1500.0, "C.C": 1e-6}, "std_errors": {"R.R": 15.0, "C.C": 2e-8},
           "correlation": [[1.0, -0.8], [-0.8, 1.0]], "log_scaled": ["C.C"]}
    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, distributions=from_fit(doc), samples=2000, sampling="random",
                  metrics=["final:v_C"])
    R, C = study.design["R.R"], study.design["C.C"]
    # 2000 samples: standard errors of the mean and sd estimates are ~2 % of sd; tolerances 10 % of sd
    assert R.mean() == pytest.approx(1500.0, abs=1.5) and R.std() == pytest.approx(15.0, rel=0.1)
    assert np.log(C).std() == pytest.approx(0.02, rel=0.1) and np.median(C) == pytest.approx(1e-6, rel=2e-3)
    assert np.corrcoef(R, np.log(C))[0, 1] == pytest.approx(-0.8, abs=0.05)
    with pytest.raises(InputDataError, match="standard errors"):
        from_fit({**doc, "std_errors": {"R.R": None, "C.C": 1e-8}})


# -- metrics ----------------------------------------------------------------------------------------------
def test_metrics_on_an_analytic_rc_charge(rc):
    """v_C = 1 - exp(-t / RC): rise time ln(9) RC, energy C U^2 (1 - exp(-t/RC)), fit 100 % to itself."""
    from codegen import simulate
    from phs.workflows.recording import Recording

    t = np.linspace(0.0, 0.02, 20001)
    res = simulate(rc, t, u={"U": 1.0}, rtol=1e-10)
    assert rise_time("v_C")(res)[0] == pytest.approx(math.log(9) * 1e-3, rel=1e-5)  # 1 us grid: 1e-5 relative
    assert rise_time_of(t, np.ones_like(t)) != rise_time_of(t, np.ones_like(t))  # NaN when nothing changes
    assert energy()(res)[0] == pytest.approx(1e-6 * (1 - math.exp(-20.0)), rel=1e-8)
    assert peak("v_C")(res)[0] == pytest.approx(1 - math.exp(-20.0), rel=1e-8)
    assert final("v_C")(res)[0] == res["v_C"][-1]
    assert values_at("v_C", [1e-3, 2e-3])(res) == pytest.approx((1 - math.exp(-1), 1 - math.exp(-2)), rel=1e-7)
    rec = Recording.from_arrays(t, {"U": np.ones_like(t), "v_C": res["v_C"]})
    assert fit(rec, "v_C")(res)[0] == 100.0
    with pytest.raises(InputDataError, match="returned 2 value"):
        Metric("two", lambda r: [1.0, 2.0])(res)


def test_passivity_margin_metric_is_the_dissipation_margin(msd):
    passivity = pytest.importorskip("codegen.passivity")
    study = Study(msd, [0.0, 0.1], u={"F": 0.0}, grid={"b.b": [0.2, 0.4, 0.8]}, metrics=["passivity_margin"])
    res = sweep(study, progress=False)
    expected = [passivity.dissipation_margin(msd, params={"b.b": b}) for b in (0.2, 0.4, 0.8)]
    assert res["passivity_margin"].tolist() == expected


def test_monte_carlo_band_from_values_at(rc):
    study = Study(rc, np.linspace(0, 3e-3, 61), u={"U": 1.0}, distributions={"R.R": LogNormal(1e3, 0.1)},
                  samples=50, metrics=[values_at("v_C", [1e-3, 2e-3])])
    res = sweep(study, progress=False)
    assert res.metrics == ["v_C@0.001", "v_C@0.002"]
    lo, hi = np.quantile(res["v_C@0.001"], [0.05, 0.95])
    assert lo < 1 - math.exp(-1) < hi


# -- invalid studies --------------------------------------------------------------------------------------
@pytest.mark.parametrize(("kwargs", "error", "match"), [
    ({"grid": {"bogus": [1.0]}}, ParameterError, "'bogus' is not a parameter"),
    ({"grid": {"R.R": []}}, InputDataError, "grid 'R.R'"),
    ({"grid": {"R.R": [1.0]}, "params": {"R.R": 2.0}}, InputDataError, "also fixed by params"),
    ({"distributions": {"R.R": Uniform(1.0, 2.0)}}, InputDataError, "samples is 0"),
    ({"samples": 3}, InputDataError, "no distributions"),
    ({"grid": {"R.R": [1.0]}, "sampling": "sobol"}, InputDataError, "sampling"),
    ({"grid": {"R.R": [1.0]}, "metrics": []}, InputDataError, "at least one metric"),
    ({"grid": {"R.R": [1.0]}, "metrics": ["peak:nope"]}, InputDataError, "'nope', which is not a signal of 'rc'"),
    ({"grid": {"R.R": [1.0]}, "metrics": ["final:v_C", "final:v_C"]}, InputDataError, "both write a column"),
    ({"grid": {"R.R": [1.0]}, "metrics": [lambda r: 1.0]}, InputDataError, "needs a name"),
    ({"grid": {"R.R": [1.0]}, "metrics": {"run": "final:v_C"}}, InputDataError, "reserved"),
    ({"grid": {"R.R": [1.0]}, "metrics": ["median:v_C"]}, InputDataError, "median:v_C"),
    ({"grid": {"R.R": [1.0]}, "u_for": lambda v: {}}, InputDataError, "either as u"),
    ({"grid": {"R.R": [1.0]}, "params": {"bogus": 1.0}}, ParameterError, "bogus"),
])
def test_invalid_studies_name_the_culprit(rc, kwargs, error, match):
    kw = {"u": {"U": 1.0}, "metrics": ["final:v_C"], **kwargs}
    with pytest.raises(error, match=match):
        Study(rc, [0.0, 1e-3], **kw)


def test_invalid_sweep_arguments(rc, tmp_path):
    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3]}, metrics=["final:v_C"])
    with pytest.raises(InputDataError, match="parquet or .csv"):
        sweep(study, tmp_path / "r.txt", progress=False)
    with pytest.raises(InputDataError, match="directory"):
        sweep(study, tmp_path / "missing" / "r.csv", progress=False)
    with pytest.raises(InputDataError, match="not both"):
        sweep(study, processes=2, scheduler="tcp://127.0.0.1:1", progress=False)
    with pytest.raises(InputDataError, match="chunk_size"):
        sweep(study, chunk_size=0, progress=False)
    assert os.listdir(tmp_path) == []


# -- command line ----------------------------------------------------------------------------------------
MSD = "systems.examples:mass_spring_damper"


def test_cli_sweep_writes_rows_plot_and_json_and_resumes(tmp_path, capsys):
    out, png, js = tmp_path / "s.csv", tmp_path / "s.png", tmp_path / "s.json"
    args = ["sweep", MSD, "--range", "k.K=1:4:4", "--range", "b.b=0.2:0.6", "--samples", "3", "--input",
            "F=step(A, 0.5)", "--range", "A=0.5,1.0", "--metric", "peak:position", "--metric", "energy",
            "--t-end", "5", "--dt", "0.01", "--out", str(out), "--quiet"]
    assert main([*args, "--plot", str(png), "--json", str(js)]) == 0
    printed = capsys.readouterr().out
    assert "24 runs, 24 ok" in printed
    res = StudyResult.read(out)
    assert len(res) == 24 and res.ok.all()
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import json

    doc = json.loads(js.read_text())
    assert doc["runs"] == 24 and doc["variables"] == ["k.K", "A", "b.b"] and doc["metrics"] == ["peak_position", "energy"]
    # the step amplitude A is an input variable: peaks scale with it (same k, b)
    a1 = (res["A"] == 1.0)
    assert np.allclose(res["peak_position"][a1], 2 * res["peak_position"][~a1], rtol=1e-6)
    # an existing file is not overwritten; --resume finds nothing left to do
    assert main(args) == 2 and "resume" in capsys.readouterr().err
    assert main([*args, "--resume"]) == 0


@pytest.mark.parametrize(("extra", "match"), [
    (["--range", "k.K=1:4:1"], "N >= 2"),
    (["--range", "k.K=4:1:3"], "LO must be below HI"),
    (["--range", "k.K=1:x:3"], "'x' is not a number"),
    (["--range", "bogus=1:2:3"], "'bogus' is not a parameter"),
    (["--range", "k.K=1:2"], "need --samples"),
    (["--range", "k.K=1:2:3", "--samples", "4"], "--samples needs a sampled range"),
    (["--range", "k.K=1:2:3", "--metric", "peak:nope"], "'nope', which is not a signal"),
    (["--range", "k.K=1:2:3", "--from-fit", "missing.json", "--samples", "3"], "--from-fit"),
])
def test_cli_sweep_invalid_options(tmp_path, capsys, extra, match):
    out = tmp_path / "s.csv"
    base = ["sweep", MSD, "--metric", "peak:position", "--t-end", "1", "--dt", "0.1", "--out", str(out), "--quiet"]
    assert main(base + extra) == 2
    assert match in capsys.readouterr().err
    assert not out.exists()


def test_cli_sweep_against_a_recording_scores_fit_percent(tmp_path, capsys):
    """--data: the recording's grid and inputs drive every run; fit:SIGNAL compares with its column."""
    from codegen import simulate
    from systems.examples import rc_circuit

    t = np.linspace(0.0, 0.02, 201)
    u = np.where((t % 0.008) < 0.004, 1.0, -0.5)
    y = simulate(rc_circuit().with_params({"R.R": 1500.0}), t, u={"U": u}, rtol=1e-10)["v_C"]
    data = tmp_path / "rec.csv"
    data.write_text("time,volts,vc\n" + "".join(f"{a:.17g},{b:.17g},{c:.17g}\n" for a, b, c in zip(t, u, y)))
    out = tmp_path / "fit.csv"
    assert main(["sweep", "systems.examples:rc_circuit", "--range", "R.R=1000:2000:5", "--data", str(data),
                 "--time", "time", "--map", "volts=U", "--map", "vc=v_C", "--metric", "fit:v_C", "--out", str(out),
                 "--quiet"]) == 0
    res = StudyResult.read(out)
    best = res["R.R"][np.argmax(res["fit_v_C"])]
    assert best == 1500.0 and res["fit_v_C"].max() > 99.9  # the recording's own resistance fits it exactly
    assert main(["sweep", "systems.examples:rc_circuit", "--range", "R.R=1000:2000:5", "--data", str(data),
                 "--t-end", "1", "--dt", "0.1", "--metric", "fit:v_C", "--out", str(tmp_path / "x.csv")]) == 2
    assert "--data gives the time grid" in capsys.readouterr().err


@pytest.mark.parametrize("dt", ["1e-5", "1e-4"])
def test_cli_sweep_of_a_square_wave_with_edges_on_the_grid(tmp_path, capsys, dt):
    """200 Hz on a grid of 10 or 100 us: every edge lands on a grid point, up to rounding."""
    from codegen import simulate
    from phs.signals import square
    from systems.examples import rc_circuit

    out = tmp_path / "sw.csv"
    assert main(["sweep", "systems.examples:rc_circuit", "--range", "R.R=500:2000:4", "--input", "square(1.0, 200)",
                 "--metric", "peak:v_C", "--t-end", "0.01", "--dt", dt, "--out", str(out), "--quiet"]) == 0
    res = StudyResult.read(out)
    assert res.ok.all(), res.failed
    t = np.arange(0.0, 0.01 + float(dt) / 2, float(dt))
    for r, highest in zip(res["R.R"], res["peak_v_C"]):
        assert highest == simulate(rc_circuit(), t, u={"U": square(1.0, 200.0)}, params={"R.R": r})["v_C"].max()


MAX_FAILED_CASES = [  # (extra options, exit code, failed runs): U = 1/(V - 1000 t) is infinite at t = 0 for V = 0
    (["--range", "V=0,100,200"], 0, 1),                              # a third failed: below the default half
    (["--range", "V=0,100,200", "--max-failed", "0.2"], 2, 1),       # more than the share allowed
    (["--range", "V=0,0,100", "--max-failed", "0.5"], 2, 2),         # two thirds
    (["--range", "V=0,-0.0", "--max-failed", "1"], 2, 2),            # every run failed: always an error
]


@pytest.mark.parametrize(("extra", "code", "n_failed"), MAX_FAILED_CASES)
def test_cli_sweep_fails_loudly_when_too_many_runs_failed(tmp_path, capsys, extra, code, n_failed):
    out = tmp_path / "f.csv"
    assert main(["sweep", "systems.examples:rc_circuit", "--input", "U=1/(V-1000*t)", "--metric", "peak:v_C",
                 "--t-end", "0.01", "--dt", "1e-3", "--out", str(out), "--quiet", *extra]) == code
    res = StudyResult.read(out)  # the results are written either way
    assert len(res.failed) == n_failed
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("phs: error")]
    if code == 0:
        assert not err
        return
    assert len(err) == 1 and "first failure, run 0: simulation of 'rc': the integrator failed" in err[0]
    assert ("every run failed" if n_failed == len(res) else f"{n_failed} of {len(res)} runs failed") in err[0]


def test_max_failed_must_be_a_share(tmp_path, capsys):
    assert main(["sweep", MSD, "--range", "k.K=1:2:2", "--metric", "peak:position", "--t-end", "1", "--dt", "0.1",
                 "--out", str(tmp_path / "s.csv"), "--max-failed", "1.5"]) == 2
    assert "--max-failed must be a share from 0 to 1" in capsys.readouterr().err


def test_progress_bar_on_stderr(rc, capsys):
    study = Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3, 2e3, 3e3]}, metrics=["final:v_C"])
    sweep(study, progress=True)
    err = capsys.readouterr().err
    assert "sweep rc" in err and "3/3" in err


def test_cli_metric_specifications():
    assert metric("rise_time:x:0.1:").name == "rise_time_x"
    with pytest.raises(InputDataError, match="a fit needs a recording"):
        metric("fit:tip")


# -- plots are written atomically, with units on their axes ------------------------------------------------
def _study_and_fit(rc):
    import phs
    from codegen import simulate
    from phs.workflows.recording import Recording

    study = sweep(Study(rc, np.linspace(0.0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": [1e3, 2e3]},
                        metrics=["final:v_C", "energy"]), progress=False)
    t = np.linspace(0.0, 5e-3, 101)
    u = np.where(t < 2e-3, 1.0, 0.0)
    rec = Recording.from_arrays(t, {"U": u, "v_C": simulate(rc.with_params({"R.R": 1500.0}), t, u={"U": u})["v_C"]})
    return study, phs.identify(rc, rec, free=["R.R"])


def test_plots_label_their_axes_with_units(rc, tmp_path):
    study, fit = _study_and_fit(rc)
    fig = study.plot(tmp_path / "study.png")
    labels = {a.get_xlabel() for a in fig.axes} | {a.get_ylabel() for a in fig.axes}
    assert {"R.R [Ohm]", "final_v_C [V]", "energy [J]"} <= labels
    assert fit.plot(tmp_path / "fit.png").axes[-1].get_xlabel() == "t [s]"
    assert fit.plot().axes[0].get_ylabel() == "v_C [V]"
    out = tmp_path / "r.parquet"
    sweep(Study(rc, [0.0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3]}, metrics=["peak:v_C"]), out, progress=False)
    assert StudyResult.read(out).units == {"R.R": "Ohm", "peak_v_C": "V"}  # carried by the Parquet file
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit.png", "r.parquet", "study.png"]


@pytest.mark.parametrize("which", ["study", "fit"])
def test_a_plot_failing_midway_leaves_no_file_and_an_existing_one_untouched(rc, tmp_path, monkeypatch, which):
    from matplotlib.figure import Figure

    study, fit = _study_and_fit(rc)
    plot = study.plot if which == "study" else fit.plot
    real = Figure.savefig

    def half_then_fail(self, fname, *args, **kwargs):
        real(self, fname, *args, **kwargs)  # the image is rendered (into memory), then the disk is full
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", half_then_fail)
    new = tmp_path / "new.png"
    with pytest.raises(OSError):
        plot(new)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no partial file, no temporary file
    old = tmp_path / "old.png"
    old.write_bytes(b"the previous figure")
    with pytest.raises(OSError):
        plot(old)
    assert old.read_bytes() == b"the previous figure" and sorted(p.name for p in tmp_path.iterdir()) == ["old.png"]
    monkeypatch.undo()
    plot(old)
    assert old.read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(InputDataError, match="unknown image format 'xyz'"):
        plot(tmp_path / "f.xyz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.png"]
