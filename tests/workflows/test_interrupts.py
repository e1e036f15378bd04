"""SIGINT and SIGTERM stop ``phs simulate`` and ``phs sweep`` (threads and Dask processes) with exit codes
130 and 143, write nothing for the work in flight, and a resumed sweep completes with no failed row
(:mod:`phs.workflows.interrupts`).

Each test runs the command in a subprocess and sends the signal once the command is busy: after the first
rows reached the sweep's part directory, or after a delay for ``simulate``.  The runs are made long
(a 50 Hz square wave over seconds: hundreds of integrator restarts per run) so that the signal lands
inside an integration, where CasADi would otherwise swallow it; one threaded sweep has a chunk of
seconds, so that the signal lands inside CasADi's threaded evaluation, which holds its calling thread.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from phs.workflows.cli import main
from phs.workflows.interrupts import Interrupted, Worker, check, deferred, received, watching

PHS = [sys.executable, "-m", "phs.workflows.cli"]
SWEEP = ["sweep", "systems.examples:rc_circuit", "--t-end", "2", "--dt", "1e-3", "--input", "square(1, 50)",
         "--range", "R.R=1e3:2e3:6", "--metric", "final:v_C", "--chunk", "1", "--quiet"]
TIMEOUT = 120  # generous: two cores shared with other work; the commands stop well within a second or two


def _default_signals() -> None:
    """In the child: SIGINT and SIGTERM at their defaults.  A test runner started in the background by a
    non-interactive shell ignores SIGINT, its children inherit that, and a command keeps an ignored signal
    ignored (as a shell's background job expects)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _start(args, cwd):
    return subprocess.Popen(PHS + args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_signals)


def _stop(proc, sig) -> tuple[int, str, float]:
    """Send ``sig``; the exit code, stderr and the seconds until the process ended."""
    sent = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=TIMEOUT)
    return proc.returncode, err, time.monotonic() - sent


def _wait_for_handlers(proc, timeout=TIMEOUT) -> None:
    """Until the command catches SIGTERM (Linux: ``SigCgt`` of ``/proc/PID/status``), that is, until it runs."""
    status = f"/proc/{proc.pid}/status"
    if not os.path.exists(status):
        time.sleep(5.0)
        return
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        with open(status) as fh:
            caught = int(next(line for line in fh if line.startswith("SigCgt:")).split()[1], 16)
        if caught & (1 << (signal.SIGTERM - 1)):
            return
        time.sleep(0.02)
    pytest.fail("the command never started")


def _wait_for_parts(proc, parts, n, timeout=TIMEOUT) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if os.path.isdir(parts) and sum(f.startswith("part-") for f in os.listdir(parts)) >= n:
            return
        if proc.poll() is not None:
            pytest.fail(f"the sweep ended before {n} parts were written: {proc.stderr.read()}")
        time.sleep(0.02)
    proc.kill()
    pytest.fail("no parts appeared")


def _rows(path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize(("sig", "engine"), [(signal.SIGINT, ["--threads", "1"]), (signal.SIGTERM, ["--threads", "2"])])
def test_an_interrupted_sweep_keeps_its_finished_rows_and_resumes(tmp_path, sig, engine):
    out = tmp_path / "out.csv"
    proc = _start(SWEEP + engine + ["--out", str(out), "--json", "s.json", "--plot", "s.png"], tmp_path)
    _wait_for_parts(proc, str(out) + ".parts", 2)
    code, err, seconds = _stop(proc, sig)
    assert code == 128 + sig, err  # 130 SIGINT, 143 SIGTERM
    assert f"interrupted ({signal.Signals(sig).name})" in err and "Traceback" not in err
    assert seconds < 10, seconds  # a run lasts ~0.2 s; the stop waits for none after the signal
    rows = _rows(out)
    assert 2 <= len(rows) < 6 and {r["status"] for r in rows} == {"ok"}  # no row for the run in flight
    assert sorted(os.listdir(tmp_path)) == ["out.csv", "out.csv.study.json"]  # no --json, no --plot
    assert main(SWEEP + engine + ["--out", str(out), "--resume"]) == 0  # in this process: no second start-up
    rows = _rows(out)
    assert [int(r["run"]) for r in rows] == list(range(6)) and {r["status"] for r in rows} == {"ok"}


# Two cheap runs (a 1 Hz sine), then a chunk of two runs driven by a 3 kHz sine over 10 s, one per thread of
# CasADi's threaded map (they share their input: one map call): CVODES resolves every period, and the chunk takes
# about 5 s idle (measured by the resume: its JSON's "seconds"; 1.9 s over 4 s, too close to a loaded machine's
# stop of 1.3 s for the comparison below).  A smooth input has no breakpoint: little is built
# before the chunk evaluates, so a signal shortly after the first part lands in the threaded evaluation.  Before
# the evaluation ran in a worker thread, such a signal waited for the chunk: the command stopped only when the chunk ended.
LONG_CHUNK = ["sweep", "systems.examples:rc_circuit", "--t-end", "10", "--dt", "1e-3", "--input", "U=sin(2*pi*f*t)",
              "--range", "f=1,3000", "--range", "R.R=1e3,2e3", "--metric", "final:v_C", "--chunk", "2", "--threads", "2",
              "--quiet"]
STOP_SECONDS = 3.0  # measured 0.3-1.3 s (the interpreter's exit competes with the abandoned chunk's two threads)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_threaded_sweep_stops_inside_its_chunk(tmp_path, sig):
    """The chunk in flight is abandoned: the command exits within a second or so, not when the chunk ends."""
    out = tmp_path / "out.csv"
    proc = _start(LONG_CHUNK + ["--out", str(out)], tmp_path)
    _wait_for_parts(proc, str(out) + ".parts", 1)
    time.sleep(0.5)  # inside the long chunk's evaluation (about 5 s)
    code, err, seconds = _stop(proc, sig)
    assert code == 128 + sig, err
    assert f"interrupted ({signal.Signals(sig).name})" in err and "Traceback" not in err
    assert seconds < STOP_SECONDS, seconds
    assert [(r["run"], r["status"]) for r in _rows(out)] == [("0", "ok"), ("1", "ok")]  # none of the chunk in flight
    assert sorted(os.listdir(tmp_path)) == ["out.csv", "out.csv.study.json"]  # no part, no temporary file left
    if sig == signal.SIGTERM:
        return  # the resume is the same for both signals: once is enough (it costs the chunk's time)
    assert main(LONG_CHUNK + ["--out", str(out), "--resume", "--json", str(tmp_path / "r.json")]) == 0
    rows = _rows(out)
    assert [int(r["run"]) for r in rows] == [0, 1, 2, 3] and {r["status"] for r in rows} == {"ok"}  # each run once
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["new_runs"] == 2  # only the chunk that was in flight ran again
    print(f"stopped {seconds:.2f} s after the signal; the chunk in flight takes {report['seconds']:.2f} s")  # -rP
    assert seconds < 0.5 * report["seconds"], (seconds, report["seconds"])  # waiting for it would take longer


@pytest.mark.slow  # starting and closing a local Dask cluster twice: about 20 s
def test_an_interrupted_sweep_on_dask_processes_stops_and_resumes(tmp_path):
    pytest.importorskip("dask.distributed")
    out = tmp_path / "out.csv"
    args = SWEEP + ["--processes", "1", "--threads", "1"]
    proc = _start(args + ["--out", str(out)], tmp_path)
    _wait_for_parts(proc, str(out) + ".parts", 1)
    code, err, seconds = _stop(proc, signal.SIGINT)
    assert code == 130, err
    assert seconds < 30, seconds  # includes closing the local cluster
    assert {r["status"] for r in _rows(out)} == {"ok"}
    done = subprocess.run(PHS + args + ["--out", str(out), "--resume"], cwd=tmp_path, capture_output=True, text=True,
                          timeout=TIMEOUT)
    assert done.returncode == 0, done.stderr
    assert {r["status"] for r in _rows(out)} == {"ok"} and len(_rows(out)) == 6


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_simulation_writes_nothing(tmp_path, sig):
    # about 10 s of integration (1500 restarts at the square wave's edges): the signal lands inside it
    proc = _start(["simulate", "systems.examples:rc_circuit", "--t-end", "30", "--dt", "1e-3", "--input",
                   "square(1, 50)", "--out", "big.csv", "--plot", "big.png"], tmp_path)
    _wait_for_handlers(proc)
    time.sleep(1.5)  # loading the model and building its functions: then it integrates
    code, err, seconds = _stop(proc, sig)
    assert code == 128 + sig, err
    assert "Traceback" not in err and seconds < 10, (err, seconds)
    assert os.listdir(tmp_path) == []  # neither output, nor a temporary file


def test_watching_restores_the_handlers_and_check_raises_the_signal_received():
    before = signal.getsignal(signal.SIGTERM)
    with watching():
        assert received() is None
        with pytest.raises(Interrupted) as info:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)  # the handler runs at the next bytecode; the sleep is interrupted
        assert info.value.exit_code == 143 and received() == signal.SIGTERM
        with pytest.raises(Interrupted):
            check()  # remembered: a result about to be kept is refused
        with pytest.raises(Interrupted), deferred():
            pass  # the renames of a command's outputs do not start after a signal
    assert signal.getsignal(signal.SIGTERM) is before and received() is None


def test_a_worker_call_is_abandoned_at_the_signal_and_the_streams_come_back():
    from codegen.batch import quiet, unsilence

    started, release, finished = threading.Event(), threading.Event(), threading.Event()
    seen = []

    def blocking():  # stands for a batch evaluation: silences the streams, holds its thread
        with quiet():
            started.set()
            release.wait(30)
        with quiet():  # a later silenced block of the abandoned evaluation
            seen.append(sys.stderr)
        finished.set()
        return "too late"

    def signal_when_started():
        started.wait(30)
        os.kill(os.getpid(), signal.SIGINT)

    # a runner launched in the background inherits SIGINT ignored, which watching() keeps ignored: the test
    # sends it to itself, so it starts from Python's own handler (restored after)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        worker, streams = Worker(on_abandon=unsilence), (sys.stdout, sys.stderr)
        assert worker(sum, [1, 2]) == 3  # an ordinary call: its value
        with watching():
            threading.Thread(target=signal_when_started, daemon=True).start()
            begin = time.monotonic()
            with pytest.raises(Interrupted) as info:
                worker(blocking)
            seconds = time.monotonic() - begin
            assert (sys.stdout, sys.stderr) == streams  # given back at once though the call still holds its quiet()
        release.set()
        assert finished.wait(30) and seen == [streams[1]]  # the abandoned call silences no more
        assert info.value.exit_code == 130 and seconds < 5, seconds  # at once, not after the call's 30 s
        assert worker(sum, [3, 4]) == 7  # a new thread serves the next call
        worker.close()
    finally:
        signal.signal(signal.SIGINT, previous)
