"""Options and checks shared by the subcommands of the ``phs`` command line."""

from __future__ import annotations

import argparse
import math
import os

import numpy as np

from phs.errors import InputDataError


def _positive(option: str, integer: bool = False):
    """argparse type: a positive finite number (an integer >= 1 when ``integer``), errors naming the option."""
    what = "a positive integer" if integer else "a positive finite number"

    def convert(text: str):
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{option} must be {what}, got {text!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{option} must be {what}, got {text!r}")
        return v

    return convert


def _nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a nonnegative integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a nonnegative integer, got {text!r}")
    return v


def _time_grid(t_end: float, dt: float | None) -> np.ndarray:
    """The output grid 0, DT, ..., T of ``--t-end T --dt DT`` (DT defaults to T/1000), checked.

    Examples
    --------
    >>> _time_grid(1.0, None)[:3], len(_time_grid(1.0, 0.25))
    (array([0.   , 0.001, 0.002]), 5)
    """
    if dt is None:
        dt = t_end / 1000
    if dt > t_end:
        raise InputDataError(f"--dt {dt:g} is larger than --t-end {t_end:g}")
    if t_end / dt > 1e7:
        raise InputDataError(f"--t-end / --dt gives {t_end / dt:.3g} samples; at most 1e7 are allowed")
    return np.arange(0.0, t_end + dt / 2, dt)


def _check_writable(*paths: str | None) -> None:
    """Fail before any work when an output cannot be written: its directory is missing or not writable,
    or the path is a directory.

    Examples
    --------
    >>> _check_writable(None, "here.csv")
    >>> _check_writable("no/such/dir/r.csv")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: cannot write 'no/such/dir/r.csv': directory ... does not exist
    """
    for path in paths:
        if path is None:
            continue
        d = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(d):
            raise InputDataError(f"cannot write {path!r}: directory {d!r} does not exist")
        if os.path.isdir(path):
            raise InputDataError(f"cannot write {path!r}: it is a directory")
        if not os.access(d, os.W_OK | os.X_OK):
            raise InputDataError(f"cannot write {path!r}: directory {d!r} is not writable")


def _check_distinct(*options: tuple[str, str | None]) -> None:
    """Refuse outputs given as ``(option, path)`` pairs when two of them name the same file.

    Examples
    --------
    >>> _check_distinct(("--out", "a.csv"), ("--plot", "a.png"), ("--json", None))
    >>> _check_distinct(("--out", "x.csv"), ("--plot", "./x.csv"))
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --out and --plot both name './x.csv': give each output its own file
    """
    seen: dict[str, str] = {}
    for option, path in options:
        if path is None:
            continue
        key = os.path.normcase(os.path.realpath(path))
        if key in seen:
            raise InputDataError(f"{seen[key]} and {option} both name {os.fspath(path)!r}: give each output its own file")
        seen[key] = option


def _write_outputs(files: dict, create=()) -> None:
    """Write a command's prepared outputs ``{path: text or bytes}`` all or nothing
    (:func:`phs.io.write_all_atomic`, which makes the directories ``create`` first and removes them again
    on a failure); a signal received before the renames stops the command with nothing written
    (:mod:`phs.workflows.interrupts`).

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _write_outputs({os.path.join(d, "r.json"): "{}"})
    ...     os.listdir(d)
    ['r.json']
    """
    from phs.io import write_all_atomic
    from phs.workflows.interrupts import check, deferred

    check()
    write_all_atomic(files, commit=deferred, create=create)


def _name_list(text: str | None, option: str) -> list[str]:
    """``"a, b,c"`` -> ``["a", "b", "c"]``; empty items and repeats are errors naming the option."""
    if text is None:
        return []
    names = [n.strip() for n in text.split(",")]
    if not any(names) or "" in names:
        raise InputDataError(f"{option} {text!r}: expected NAME,NAME,... without empty names")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputDataError(f"{option}: {dup[0]!r} is given twice")
    return names


def _finite_or_none(obj):
    """JSON-ready copy: NaN and infinities become null (strict JSON has no NaN)."""
    if isinstance(obj, dict):
        return {str(k): _finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_or_none(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return _finite_or_none(obj.tolist())
    return obj
