"""Running a study: its runs in chunks, in threads on this machine or as Dask tasks, rows to the store."""

from __future__ import annotations

import math
import time as _time

import numpy as np

from phs.errors import InputDataError
from phs.workflows.interrupts import Worker, check, watching
from phs.workflows.sweep.evaluate import _describe, _evaluate_chunk, _Evaluator, _failed_row
from phs.workflows.sweep.metrics import column_units
from phs.workflows.sweep.result import StudyResult
from phs.workflows.sweep.store import ResultStore
from phs.workflows.sweep.study import Study

_MEMORY_PER_CHUNK = 128e6  # bytes of trajectories held per chunk (the chunk size follows from it)


def _chunk_size(study: Study, n_todo: int, workers: int) -> int:
    s = study.system
    nq = 2 + len(s.dissipators) if study.options["energy"] else 0
    width = 2 * len(s.states) + nq + 2 * len(s.inputs) + len(s.conditions) + len(s.measured) + len(s.inputs) + 3
    per_run = 8.0 * len(study.t) * width
    by_memory = max(1, int(_MEMORY_PER_CHUNK // per_run))
    balance = max(1, math.ceil(n_todo / (4 * workers)))  # several chunks per worker: progress and balance
    return max(1, min(by_memory, balance, 256))


def _chunks(todo: list, size: int, exact: bool = False) -> list[list]:
    """Split the runs into chunks of ``size``, or of a slightly smaller size that divides their number
    (every chunk size builds its own mapped functions and work memory once)."""
    if not exact:
        for s in range(size, max(1, math.ceil(0.6 * size)) - 1, -1):
            if len(todo) % s == 0:
                size = s
                break
    return [todo[i:i + size] for i in range(0, len(todo), size)]


class _Progress:
    """A tqdm progress bar over runs counting the failed ones (nothing when disabled or tqdm is missing)."""

    def __init__(self, total: int, enabled: bool, name: str):
        self.bar, self.failed = None, 0
        if enabled and total:
            try:
                from tqdm.auto import tqdm
            except ImportError:  # the study runs without a bar
                return
            self.bar = tqdm(total=total, unit="run", desc=f"sweep {name}", smoothing=0.1)

    def update(self, rows) -> None:
        if self.bar is None:
            return
        self.failed += sum(r["status"] != "ok" for r in rows)
        if self.failed:
            self.bar.set_postfix(failed=self.failed, refresh=False)
        self.bar.update(len(rows))

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def sweep(study: Study, out=None, *, resume: bool = False, retry_failed: bool = False, threads: int | None = None,
          processes: int | None = None, scheduler=None, chunk_size: int | None = None, progress: bool = True,
          flush_seconds: float = 5.0) -> StudyResult:
    """Evaluate every run of ``study``; write the rows to ``out`` as they finish.

    Parameters
    ----------
    study : Study
    out : str, optional
        Results file, ``.parquet`` or ``.csv``; without it the rows stay in memory.
    resume : bool
        Continue a study whose file (or the parts of an interrupted run) exists: finished runs are
        kept, only missing ones run.  Without it an existing file is an error (nothing is overwritten).
    retry_failed : bool
        With ``resume``, run the failed runs again.
    threads : int, optional
        Threads of the batched evaluation (default: the processors available; 1 runs the runs one
        after the other through the same functions).  With Dask: threads per task (default 1).
    processes : int, optional
        Evaluate on a local Dask cluster of this many worker processes (one thread each).
    scheduler : str or distributed.Client, optional
        Evaluate on a Dask cluster: its scheduler's address (``"tcp://host:8786"``) or a client.
    chunk_size : int, optional
        Runs per chunk (per Dask task); default from the memory a run's trajectories take.
    progress : bool
        Show a progress bar (on stderr).
    flush_seconds : float
        How often the results file is rewritten from the finished runs (parts are written at once;
        0 rewrites it after every chunk).

    Returns
    -------
    StudyResult
        Every run of the study (including those found in a resumed file).

    Raises
    ------
    InputDataError
        When ``out`` exists without ``resume``, holds another study (the message names what differs:
        :meth:`Study.identity`), has an unknown suffix, or the
        Dask scheduler cannot be reached.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.sweep import LogUniform
    >>> from systems.examples import rc_circuit
    >>> study = Study(rc_circuit(), np.linspace(0, 2e-3, 21), u={"U": 1.0},
    ...               distributions={"C.C": LogUniform(5e-7, 2e-6)}, samples=4, metrics=["energy"])
    >>> res = sweep(study, progress=False)
    >>> bool(np.allclose(res["energy"], res["C.C"] * (1 - np.exp(-2e-3 / (1e3 * res["C.C"])))))
    True
    """
    if not isinstance(study, Study):
        raise InputDataError(f"sweep needs a Study, got {type(study).__name__}")
    if scheduler is not None and processes is not None:
        raise InputDataError("give either processes (a local Dask cluster) or scheduler (an existing one), not both")
    for name, v in (("threads", threads), ("processes", processes), ("chunk_size", chunk_size)):
        if v is not None and (not isinstance(v, (int, np.integer)) or v < 1):
            raise InputDataError(f"{name} must be a positive integer, got {v!r}")
    numeric = study.columns
    import casadi

    import phs

    meta = {"system": study.system.name, "model_hash": study.system.model_hash(), "phs_version": phs.__version__,
            "casadi_version": casadi.__version__, "variables": study.variables,
            "metrics": [c for m in study.metrics for c in m.columns], "n_runs": study.n_runs, "seed": study.seed,
            "sampling": study.sampling, "samples": study.samples,
            "units": column_units(study.system, study.metrics, study.variables), "identity": study.identity()}

    def design(run):
        return study.values(run) if 0 <= run < study.n_runs else None

    store = ResultStore(out, numeric, design, study.variables, resume=resume, retry_failed=retry_failed,
                        metadata=meta, flush_seconds=flush_seconds)
    todo = [k for k in range(study.n_runs) if k not in store.done]
    distributed = scheduler is not None or processes is not None
    wall = _time.perf_counter()
    bar = _Progress(len(todo), progress, study.system.name)
    with watching():  # SIGINT/SIGTERM: the finished runs are kept, the runs in flight leave no row
        _run(study, todo, store, bar, distributed, threads, processes, scheduler, chunk_size)
    seconds = _time.perf_counter() - wall
    metrics = [c for m in study.metrics for c in m.columns]
    return StudyResult(store.table(), study.variables, metrics, path=store.path, seconds=seconds,
                       new_runs=len(todo), system_name=study.system.name, units=meta["units"])


def _run(study, todo, store, bar, distributed, threads, processes, scheduler, chunk_size) -> None:
    try:
        if todo:
            if distributed:
                _run_dask(study, todo, store, bar, scheduler, processes, threads or 1, chunk_size)
            else:
                from codegen.batch import default_threads, unsilence

                n_threads = threads or default_threads()
                size = chunk_size or _chunk_size(study, len(todo), n_threads)
                ev = _Evaluator(study, n_threads)
                # CasADi's threaded evaluation holds the thread that calls it until the chunk is done: in a
                # worker thread, so that a signal stops the sweep at once (the chunk in flight is dropped)
                worker = Worker(on_abandon=unsilence) if n_threads > 1 else None
                try:
                    for chunk in _chunks(todo, size, exact=chunk_size is not None):
                        check()
                        runs = [(k, study.values(k)) for k in chunk]
                        rows = worker(ev, runs) if worker is not None else ev(runs)
                        check()
                        store.add(rows)
                        bar.update(rows)
                finally:
                    if worker is not None:
                        worker.close()
    finally:
        bar.close()
        store.close()


def _run_dask(study, todo, store, bar, scheduler, processes, threads, chunk_size) -> None:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise InputDataError("the Dask executor needs dask.distributed: pip install 'dask[distributed]'") from None
    cluster = None
    owned = False
    if isinstance(scheduler, Client):
        client = scheduler
    else:
        owned = True
        try:
            if scheduler is not None:
                client = Client(scheduler, timeout="20s")
            else:
                cluster = LocalCluster(n_workers=processes, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40)
                client = Client(cluster)
        except (OSError, TimeoutError) as exc:
            raise InputDataError(f"cannot reach the Dask scheduler {scheduler or 'of the local cluster'}: {exc}") from None
    try:
        workers = max(1, len(client.scheduler_info().get("workers", {})) or (processes or 1))
        size = chunk_size or _chunk_size(study, len(todo), workers)
        chunks = _chunks(todo, size, exact=chunk_size is not None)
        [ev] = client.scatter([_Evaluator(study, threads)], broadcast=True)
        pending = iter(chunks)
        runs_of = {}

        def submit():
            chunk = next(pending, None)
            if chunk is None:
                return None
            fut = client.submit(_evaluate_chunk, ev, [(k, study.values(k)) for k in chunk], pure=False)
            runs_of[fut.key] = chunk
            return fut

        window = [f for f in (submit() for _ in range(2 * workers + 2)) if f is not None]
        queue = as_completed(window)
        for fut in queue:
            check()
            chunk = runs_of.pop(fut.key)
            try:
                rows = fut.result()
            except Exception as exc:  # a task lost with its worker, or failing outside any run
                check()  # a worker stopped by the same signal: its runs were interrupted, not failed
                rows = [_task_failed(study, k, exc) for k in chunk]
            store.add(rows)
            bar.update(rows)
            nxt = submit()
            if nxt is not None:
                queue.add(nxt)
    finally:
        if owned:
            client.close()
            if cluster is not None:
                cluster.close()


def _task_failed(study, run, exc) -> dict:
    return _failed_row(study.metrics, run, study.values(run), f"the Dask task of this run failed: {_describe(exc)}")
