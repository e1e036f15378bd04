"""CasADi functions mapped over many runs in threads, and their console output.

CasADi releases Python's GIL during its calls, so ``Function.map(n, "thread", k)`` evaluates ``n``
runs in ``k`` threads of one process.  A mapped function is called through its buffer interface
(numpy arrays in and out, no copies); a buffer holds the evaluation's work memory, so each thread
keeps its own (:class:`Mapped`).  Failed runs are reported as PHS errors, so CasADi's own messages
are silenced while a batch evaluates (:func:`quiet`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import weakref

import casadi as ca


def default_threads() -> int:
    """Number of threads used by default: the processors this process may run on.

    Examples
    --------
    >>> default_threads() >= 1
    True
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class Mapped:
    """A mapped function and its call buffers (one per thread: a buffer holds the evaluation's work memory,
    whose allocation costs as much as a short evaluation).

    Examples
    --------
    >>> x = ca.SX.sym("x")
    >>> m = Mapped(ca.Function("sq", [x], [x * x]).map(3))
    >>> m.buffer() is m.buffer()
    True
    """

    def __init__(self, f: ca.Function):
        self.f = f
        self._local = threading.local()

    def buffer(self):
        hit = getattr(self._local, "buffer", None)
        if hit is None:
            hit = self._local.buffer = self.f.buffer()
        return hit


class _Discard:
    """A text stream that drops what it is given."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


_QUIET_LOCK = threading.Lock()
_QUIET = {"depths": {}, "saved": None}  # per thread inside quiet(): its depth; the streams to give back
_ABANDONED: weakref.WeakSet = weakref.WeakSet()  # threads that silence no longer (see unsilence)


@contextlib.contextmanager
def quiet():
    """Silence CasADi's diagnostics (failed runs are reported as PHS errors instead).

    CasADi prints through Python's ``sys.stdout``/``sys.stderr``; they are swapped once for all
    threads inside (a per-call ``redirect_stdout`` would, with several threads, restore another
    thread's sink and lose the console for good), and given back when the last thread leaves.

    Examples
    --------
    >>> with quiet():
    ...     print("not shown")
    """
    me = threading.current_thread()
    with _QUIET_LOCK:
        counted = me not in _ABANDONED
        if counted:
            if not _QUIET["depths"]:
                _QUIET["saved"] = (sys.stdout, sys.stderr)
                sys.stdout = sys.stderr = _Discard()
            _QUIET["depths"][me] = _QUIET["depths"].get(me, 0) + 1
    try:
        yield
    finally:
        with _QUIET_LOCK:
            depths = _QUIET["depths"]
            if counted and me in depths:  # not unsilenced meanwhile
                depths[me] -= 1
                if not depths[me]:
                    del depths[me]
                if not depths:
                    sys.stdout, sys.stderr = _QUIET["saved"]


def unsilence(thread: threading.Thread) -> None:
    """Give the streams back now and for good from ``thread``, whose evaluation was abandoned.

    An evaluation abandoned at an interrupt (its caller stopped waiting for it) runs on unobserved;
    its :func:`quiet` blocks, current and to come, must not hide what the caller says next (the
    interrupt's notice).  Other threads inside :func:`quiet` keep the streams silenced
    until they leave.

    Examples
    --------
    >>> before = sys.stdout
    >>> with quiet():
    ...     unsilence(threading.current_thread())
    ...     sys.stdout is before
    True
    >>> with quiet():  # this thread silences no more
    ...     sys.stdout is before
    True
    >>> _ABANDONED.discard(threading.current_thread())
    """
    with _QUIET_LOCK:
        _ABANDONED.add(thread)
        depths = _QUIET["depths"]
        if depths.pop(thread, None) and not depths:
            sys.stdout, sys.stderr = _QUIET["saved"]
