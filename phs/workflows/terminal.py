"""What the ``phs`` command line shows on a terminal while it works: progress bars and solver chatter.

A progress bar goes to standard error, and only when standard error is a terminal or the user asked for it
(``--progress``); ``--quiet`` refuses it.  Piped or captured output (a log, a test) therefore stays free of
bars unless asked.  A bar whose work sits inside one long call (an eigen-decomposition over a sample, one
integrator call) keeps its elapsed time moving with a small refreshing thread.

Third-party solvers (CasADi, IPOPT, SUNDIALS) write warnings of their own on standard error ("Failed to
calculate multipliers"); the command says what matters in its own words, so :func:`solver_chatter` keeps
those lines off the terminal unless ``--verbose``.

Examples
--------
>>> import argparse
>>> wanted(argparse.Namespace(progress=True, quiet=False)), wanted(argparse.Namespace(progress=True, quiet=True))
(True, False)
>>> with Bar(False, "nothing shown", total=3) as bar:
...     bar.update(3)
"""

from __future__ import annotations

import contextlib
import re
import sys
import threading
from collections.abc import Iterator


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # a closed or exotic stream
        return False


def wanted(args) -> bool:
    """Whether a command shows progress bars: ``--quiet`` refuses them, ``--progress`` asks for them, and
    otherwise only when standard error is a terminal.

    Examples
    --------
    >>> import argparse
    >>> wanted(argparse.Namespace())   # under a test runner standard error is not a terminal
    False
    """
    if getattr(args, "quiet", False):
        return False
    if getattr(args, "progress", False):
        return True
    return _is_terminal(sys.stderr)


class Bar:
    """A tqdm progress bar on standard error, or nothing when ``enabled`` is False.

    Parameters
    ----------
    enabled : bool
        Show the bar (:func:`wanted`).
    desc : str
        What is running (``"passivity hydrogel_arm"``).
    total : float, optional
        Amount of work; None for a bar that counts stages without an end.
    unit : str
        Unit of the work counted.
    ticking : bool
        Refresh the bar twice a second, so that its elapsed time moves during one long call.
    stream : file, optional
        Where the bar is drawn (default: standard error as it is when the bar starts).
    **options
        Passed to ``tqdm`` (``bar_format``).

    Examples
    --------
    >>> import io
    >>> out = io.StringIO()
    >>> with Bar(True, "demo", total=2, stream=out) as bar:
    ...     bar.stage("first")
    ...     bar.update(2)
    >>> "demo" in out.getvalue() and "2/2" in out.getvalue()
    True
    """

    def __init__(self, enabled: bool, desc: str, total: float | None = None, unit: str = "it",
                 ticking: bool = False, stream=None, **options):
        self._bar = None
        self._stop = threading.Event()
        self._thread = None
        if not enabled:
            return
        from tqdm import tqdm

        if stream is None:  # the terminal itself, not the filter of solver chatter (which holds partial lines)
            stream = sys.stderr.target if isinstance(sys.stderr, _Filtered) else sys.stderr
        self._bar = tqdm(total=total, desc=desc, unit=unit, file=stream,
                         dynamic_ncols=True, mininterval=0.2, leave=True, **options)
        if ticking:
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            bar = self._bar
            if bar is not None:
                bar.refresh()

    def update(self, n: float = 1) -> None:
        """Count ``n`` more units of work done."""
        if self._bar is not None:
            self._bar.update(n)

    def to(self, done: float) -> None:
        """Set the work done to ``done`` (never backwards)."""
        if self._bar is not None and done > self._bar.n:
            self._bar.update(done - self._bar.n)

    def stage(self, label: str) -> None:
        """Name the stage that is running now (shown after the bar)."""
        if self._bar is not None:
            self._bar.set_postfix_str(label)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Bar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


#: Lines that third-party solvers write on their own: a CasADi warning, a SUNDIALS message, IPOPT's banner.
CHATTER = re.compile(r"^(CasADi - .*(WARNING|Warning)|\[(CVODES|IDAS|KINSOL|CVODE|IDA)\b|\*{10,}|This program contains "
                     r"Ipopt|\s*Ipopt is released|\s*For more information visit https?://github.com/coin-or/Ipopt)")


class _Filtered:
    """A text stream forwarding whole lines to ``target`` except solver chatter (:data:`CHATTER`, with the
    indented lines that continue it), which is counted and dropped."""

    def __init__(self, target):
        self.target, self.dropped, self._pending, self._in_chatter = target, 0, "", False

    def write(self, text: str) -> int:
        self._pending += text
        *lines, self._pending = self._pending.split("\n")
        for line in lines:
            self._line(line + "\n")
        if "\r" in self._pending:  # a progress bar redrawing its line: no solver writes one, pass it at once
            self.target.write(self._pending)
            self._pending = ""
        return len(text)

    def _line(self, line: str) -> None:
        if CHATTER.match(line) or (self._in_chatter and line[:1] in (" ", "\t") and line.strip()):
            self._in_chatter = True
            self.dropped += 1
            return
        self._in_chatter = False
        self.target.write(line)

    def flush(self) -> None:
        if self._pending and not CHATTER.match(self._pending):
            self.target.write(self._pending)
            self._pending = ""
        self.target.flush()

    def isatty(self) -> bool:
        return _is_terminal(self.target)

    def fileno(self) -> int:
        return self.target.fileno()

    def __getattr__(self, name):  # encoding, errors, buffer: those of the stream underneath
        return getattr(self.target, name)


@contextlib.contextmanager
def solver_chatter(verbose: bool = False) -> Iterator[None]:
    """Keep third-party solvers' own messages (:data:`CHATTER`) off standard error inside the block, unless
    ``verbose``; every other line passes through at once, in order.

    Examples
    --------
    >>> import io, contextlib
    >>> err = io.StringIO()
    >>> with contextlib.redirect_stderr(err), solver_chatter():
    ...     print('CasADi - 2026-01-01 10:00:00 WARNING("Failed to calculate multipliers")', file=sys.stderr)
    ...     print("phs: warning: our own words", file=sys.stderr)
    >>> err.getvalue()
    'phs: warning: our own words\\n'
    """
    if verbose:
        yield
        return
    real = sys.stderr
    filtered = _Filtered(real)
    sys.stderr = filtered
    try:
        yield
    finally:
        if sys.stderr is filtered:
            sys.stderr = real
        filtered.flush()
