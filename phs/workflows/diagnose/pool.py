"""Running independent fits side by side: forked worker processes, or the workers of a Dask cluster inside
:func:`on_cluster`; results in the order asked for."""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import contextvars
import multiprocessing as mp
from collections.abc import Iterator

from phs.errors import InputDataError

_CLUSTER: contextvars.ContextVar = contextvars.ContextVar("phs_diagnose_cluster", default=None)
"""The Dask client :func:`run_forked` submits to, set only inside :func:`on_cluster` (None: forked processes)."""


def run_forked(fn, calls: list, n_jobs: int, done=None) -> list:
    """``[fn(*args) for args in calls]``, computed in up to ``n_jobs`` forked processes, or on the workers
    of a Dask cluster inside :func:`on_cluster`.

    Forked workers inherit the loaded modules (no re-import of the user's script, no ``__main__``
    guard); ``fn`` and its arguments are pickled.  ``done(k, i, result)`` is called as each result
    arrives (``k``: how many have arrived, ``i``: its index in ``calls``).  When a worker dies (e.g.
    out of memory), or with one job or one call, everything runs in this process instead.

    Inside :func:`on_cluster` every call is one Dask task whatever ``n_jobs`` (the cluster's workers set
    how many run at once; a single call still runs here); the results are the same values, in the same
    order.  Calls whose worker was lost run in this process.

    Examples
    --------
    >>> run_forked(pow, [(2, 3), (3, 2)], n_jobs=2)
    [8, 9]
    """
    out = [None] * len(calls)
    client = _CLUSTER.get()
    if client is not None and len(calls) > 1:
        return _run_dask(client, fn, calls, out, done)
    if n_jobs > 1 and len(calls) > 1 and "fork" in mp.get_all_start_methods():
        try:
            with cf.ProcessPoolExecutor(max_workers=n_jobs, mp_context=mp.get_context("fork")) as ex:
                futs = {ex.submit(fn, *args): i for i, args in enumerate(calls)}
                for k, f in enumerate(cf.as_completed(futs), 1):
                    i = futs[f]
                    out[i] = f.result()
                    if done is not None:
                        done(k, i, out[i])
            return out
        except cf.process.BrokenProcessPool:  # finish serially
            pass
    for k, args in enumerate(calls, 1):
        out[k - 1] = fn(*args)
        if done is not None:
            done(k, k - 1, out[k - 1])
    return out


def _run_dask(client, fn, calls: list, out: list, done) -> list:
    """The calls as Dask tasks (one each, never merged by key: ``pure=False``); a call whose task was lost
    with its worker (``KilledWorker``, cancelled) runs in this process; an exception of ``fn`` itself is
    raised here, as in a forked process, after the other tasks are cancelled."""
    from dask.distributed import as_completed

    futs = [client.submit(_on_worker, fn, *args, pure=False) for args in calls]
    index = {f.key: i for i, f in enumerate(futs)}
    lost, k = [], 0
    try:
        for f in as_completed(futs):
            i = index[f.key]
            try:
                out[i] = f.result()
            except Exception as exc:
                if type(exc).__name__ not in ("KilledWorker", "CancelledError", "FutureCancelledError"):
                    raise
                lost.append(i)
                continue
            k += 1
            if done is not None:
                done(k, i, out[i])
    finally:
        client.cancel([f for f in futs if not f.done()])
    for i in lost:
        out[i] = fn(*calls[i])
        k += 1
        if done is not None:
            done(k, i, out[i])
    return out


def _on_worker(fn, *args):
    """``fn(*args)`` as a Dask task: its own calls of :func:`run_forked` stay on its worker (a worker thread of an
    in-process cluster may see this process's :func:`on_cluster`; a task waiting for tasks could starve it)."""
    token = _CLUSTER.set(None)
    try:
        return fn(*args)
    finally:
        _CLUSTER.reset(token)


@contextlib.contextmanager
def on_cluster(scheduler) -> Iterator:
    """Within the block, :func:`run_forked` (the hypothesis fits of a diagnosis, its nominal model's starts,
    the trials of :func:`~phs.workflows.diagnose.trials.diagnose_trials`) runs its calls on a Dask cluster.

    Parameters
    ----------
    scheduler : str, distributed.Client or None
        The scheduler's address (``"tcp://host:8786"``; a client is made and closed with the block), a
        client (kept open), or None (nothing changes: forked processes).  The workers must import the
        model's modules as this process does (the same environment, a model from an installed module).

    Raises
    ------
    InputDataError
        When the scheduler cannot be reached, or dask.distributed is not installed.

    Examples
    --------
    >>> with on_cluster(None):
    ...     run_forked(pow, [(2, 3), (3, 2)], n_jobs=1)
    [8, 9]
    """
    if scheduler is None:
        yield None
        return
    client, owned = _connect(scheduler)
    _by_value()
    token = _CLUSTER.set(client)
    try:
        yield client
    finally:
        _CLUSTER.reset(token)
        if owned:
            client.close()


def _connect(scheduler):
    """``(client, owned)`` for a scheduler address or a client (the reach and the messages of ``phs sweep``)."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise InputDataError("the Dask executor needs dask.distributed: pip install 'dask[distributed]'") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    try:
        return Client(scheduler, timeout="20s"), True
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputDataError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None


def _by_value() -> None:
    """Models loaded from a ``path/file.py`` (modules ``_phs_model_*`` of :mod:`phs.workflows.loader`, which the
    workers cannot import) travel to them by value."""
    import sys

    import cloudpickle

    for name, module in list(sys.modules.items()):
        if name.startswith("_phs_model_"):
            cloudpickle.register_pickle_by_value(module)
