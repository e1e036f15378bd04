"""Interrupts (SIGINT, SIGTERM) that stop a command, even when they arrive inside an integrator.

CasADi catches a Python ``KeyboardInterrupt`` raised inside its integrators and reports it as a
solver failure (``psetup failed: KeyboardInterrupt``), from which CVODES may even recover: the
interrupt would be lost, or recorded as a failed run.  While :func:`watching` is active, SIGINT and
SIGTERM are caught by a handler that remembers the signal and raises :class:`Interrupted`; should
CasADi swallow it, a one-shot profile hook raises it again as soon as control is back in Python
(when the next function returns, unless an interrupt is already being handled), and
:func:`check` raises it wherever a result is about to be kept (after a solver reports, between
the runs of a sweep, before the outputs of a command are written).  A second signal ends the
process at once.  On leaving :func:`watching` the previous handlers are restored.

Python runs signal handlers in the main thread only, between two of its bytecodes: a CasADi call
that evaluates in threads of its own (a mapped function's ``"thread"`` evaluation) holds the main
thread until every thread is done, and the signal would wait for it.  :class:`Worker` runs such a
call in a daemon thread while the main thread waits in short intervals, so the signal stops the
command at once; the abandoned call runs on unobserved (its result is never kept) and ends with the
process.

Examples
--------
>>> with watching():
...     check()  # no signal: nothing happens
>>> received() is None
True
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

_SIGNALS = (signal.SIGINT, signal.SIGTERM)

#: Seconds between the main thread's looks at a signal while a :class:`Worker` computes (a signal
#: usually interrupts the wait at once; this bounds the delay where it does not).
POLL_SECONDS = 0.05
_state = {"depth": 0, "received": None, "deferred": False}


class Interrupted(KeyboardInterrupt):
    """The command was stopped by the signal ``signum``; its exit code is ``128 + signum``.

    Examples
    --------
    >>> exc = Interrupted(signal.SIGTERM)
    >>> exc.exit_code, str(exc)
    (143, 'SIGTERM')
    """

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(signal.Signals(self.signum).name)

    @property
    def exit_code(self) -> int:
        """``128 + signum``: 130 for SIGINT, 143 for SIGTERM (the shell's convention)."""
        return 128 + self.signum


def _handler(signum, frame) -> None:
    if _state["received"] is not None:  # a second signal: stop now, whatever is running
        os._exit(128 + signum)
    _state["received"] = signum
    if not _state["deferred"]:
        exc = Interrupted(signum)  # built first: the hook must not fire on the returns inside its constructor
        sys.setprofile(_again)  # in case an integrator swallows the exception raised here
        raise exc


def _again(frame, event, arg) -> None:
    """Profile hook (main thread): raise the interrupt again when a Python function returns, unless it is
    already being handled (cleanup in ``finally`` blocks runs undisturbed).  The returns of the handler
    itself and of a stream's ``write`` (called by CasADi while it reports the failure) are inside the
    integrator, where the exception would be swallowed again; the hook waits for the next one."""
    if event != "return" or frame.f_code is _handler.__code__ or frame.f_code.co_name in ("write", "flush"):
        return
    sys.setprofile(None)
    if _state["received"] is not None and not _state["deferred"] and not isinstance(sys.exc_info()[1], KeyboardInterrupt):
        raise Interrupted(_state["received"])


@contextlib.contextmanager
def watching() -> Iterator[None]:
    """Catch SIGINT and SIGTERM while the block runs (see the module docstring); nests.

    Outside the main thread (where Python cannot install signal handlers) it does nothing.  A signal
    that was ignored when the block started (``SIG_IGN``) stays ignored.

    Examples
    --------
    >>> with watching(), watching():
    ...     signal.getsignal(signal.SIGTERM) is _handler
    True
    >>> signal.getsignal(signal.SIGTERM) is _handler
    False
    """
    if threading.current_thread() is not threading.main_thread() or _state["depth"]:
        _state["depth"] += bool(_state["depth"])
        try:
            yield
        finally:
            _state["depth"] -= bool(_state["depth"])
        return
    old = {s: signal.getsignal(s) for s in _SIGNALS}
    _state.update(depth=1, received=None, deferred=False)
    for s, h in old.items():
        if h is not signal.SIG_IGN:
            signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            if h is not signal.SIG_IGN:
                signal.signal(s, h if h is not None else signal.SIG_DFL)
        if sys.getprofile() is _again:
            sys.setprofile(None)
        _state.update(depth=0, received=None, deferred=False)


def received() -> int | None:
    """The signal received while :func:`watching` (None when none was).

    Examples
    --------
    >>> received() is None
    True
    """
    return _state["received"]


def check() -> None:
    """Raise :class:`Interrupted` when a signal was received (one swallowed by a solver included).

    Examples
    --------
    >>> check()
    """
    if _state["received"] is not None:
        raise Interrupted(_state["received"])


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """:func:`check`, then run the block to its end even when a signal arrives.

    For the few renames that put a command's prepared outputs in place: all of them happen, or
    (when a signal came before) none; a signal arriving during them comes too late to stop the
    command, which has finished its work.

    Examples
    --------
    >>> with deferred():
    ...     pass
    """
    check()
    before = _state["deferred"]
    _state["deferred"] = True
    try:
        yield
    finally:
        _state["deferred"] = before


class Worker:
    """Run blocking calls in a daemon thread while the calling (main) thread waits in short intervals.

    A call made from the main thread is handed to the worker thread (started at the first call, one
    call at a time, so that per-thread caches such as CasADi's call buffers are reused), and the main
    thread waits for it :data:`POLL_SECONDS` at a time: a signal received meanwhile raises
    :class:`Interrupted` in the main thread at once, and the call goes on in the worker thread,
    abandoned: its result or error is dropped, ``on_abandon(thread)`` is called (to undo what the
    call holds for the process: the batch evaluation's silenced streams, :func:`codegen.batch.unsilence`),
    and, the thread being a daemon, it neither delays nor blocks the end of the process.  The next
    call gets a new thread.  The call's exception is raised in the caller.  Called from another
    thread, the call runs in place.  :meth:`close` lets the thread end after its current call.

    Parameters
    ----------
    on_abandon : callable, optional
        Called with the worker thread when a call is abandoned.

    Examples
    --------
    >>> w = Worker()
    >>> w(sum, [1, 2, 3])
    6
    >>> w(int, "x")
    Traceback (most recent call last):
    ...
    ValueError: invalid literal for int() with base 10: 'x'
    >>> w.close()
    """

    def __init__(self, on_abandon: Callable[[threading.Thread], None] | None = None):
        self.on_abandon = on_abandon
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None

    def __call__(self, fn: Callable[..., Any], /, *args, **kwargs) -> Any:
        if threading.current_thread() is not threading.main_thread():
            return fn(*args, **kwargs)
        if self._thread is None:
            self._thread = threading.Thread(target=self._serve, args=(self._jobs,), name="phs-worker", daemon=True)
            self._thread.start()
        done, box = threading.Event(), {}
        self._jobs.put((fn, args, kwargs, done, box))
        try:
            while not done.wait(POLL_SECONDS):  # the signal's handler runs here and raises Interrupted
                pass
        except BaseException:
            if not done.is_set():  # abandoned: the thread ends after the call; the next call gets another
                thread = self._thread
                self.close()
                self._jobs = queue.SimpleQueue()
                if self.on_abandon is not None:
                    self.on_abandon(thread)
            raise
        if "error" in box:
            raise box["error"]
        return box["value"]

    @staticmethod
    def _serve(jobs: queue.SimpleQueue) -> None:
        while (job := jobs.get()) is not None:
            fn, args, kwargs, done, box = job
            try:
                box["value"] = fn(*args, **kwargs)
            except BaseException as exc:  # handed to the caller (dropped when the caller has left)
                box["error"] = exc
            finally:
                done.set()
            del job, fn, args, kwargs, done, box  # nothing of a finished call stays alive in the thread

    def close(self) -> None:
        """Let the worker thread end once its current call (if any) returns.

        Examples
        --------
        >>> Worker().close()  # never started: nothing to end
        """
        if self._thread is not None:
            self._jobs.put(None)
            self._thread = None
