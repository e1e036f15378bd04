"""Running independent fits side by side: forked worker processes, results in the order asked for."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp


def run_forked(fn, calls: list, n_jobs: int, done=None) -> list:
    """``[fn(*args) for args in calls]``, computed in up to ``n_jobs`` forked processes.

    Forked workers inherit the loaded modules (no re-import of the user's script, no ``__main__``
    guard); ``fn`` and its arguments are pickled.  ``done(k, i, result)`` is called as each result
    arrives (``k``: how many have arrived, ``i``: its index in ``calls``).  When a worker dies (e.g.
    out of memory), or with one job or one call, everything runs in this process instead.

    Examples
    --------
    >>> run_forked(pow, [(2, 3), (3, 2)], n_jobs=2)
    [8, 9]
    """
    out = [None] * len(calls)
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
