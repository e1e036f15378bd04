"""One vocabulary of options for every subcommand of the ``phs`` command line.

An option used by more than one subcommand is declared once, in :data:`OPTIONS`, and added to a
subcommand's parser with :func:`add_option`: the same name then has the same type, default,
metavar and meaning everywhere.  A subcommand may append a sentence of its own to the help text
(``detail=``), never change its start.  :func:`vocabulary_problems` walks a parser and lists every
departure from the table; ``tests/workflows/test_cli_vocabulary.py`` runs it on ``phs`` itself.

An option renamed in a subcommand keeps its old name for one release through
:func:`add_deprecated_alias`: hidden from ``--help``, it still works and warns on stderr.

Examples
--------
>>> import argparse
>>> p = argparse.ArgumentParser(prog="demo")
>>> add_option(p, "--rtol")
>>> add_option(p, "--t-end", required=True, detail="simulate the closed loop for T seconds")
>>> p.parse_args(["--t-end", "2"]).rtol
1e-08
>>> vocabulary_problems({"demo": p})
[]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Any

from phs.workflows.cli_options import _nonnegative_int, _positive


@dataclass(frozen=True)
class _Option:
    """The canonical declaration of one option: help text (its start), metavar, type, default, action."""

    help: str
    metavar: str | None = None
    type: Any = None
    default: Any = None
    action: str = "store"


#: The canonical options of the ``phs`` command line, by name.
OPTIONS: dict[str, _Option] = {
    "--param": _Option("override a parameter", "NAME=VALUE", action="append"),
    "--json": _Option("write a JSON summary", "FILE"),
    "--time": _Option("time column of CSV files (default: t)", "COLUMN", default="t"),
    "--map": _Option("read model signal SIGNAL from CSV column COLUMN (default: same names)", "COLUMN=SIGNAL",
                     action="append"),
    "--x0": _Option("initial value of a state", "NAME=VALUE", action="append"),
    "--t-end": _Option("final time of the simulation [s]", "T", _positive("--t-end")),
    "--dt": _Option("output step of the simulation [s] (default: T/1000)", "DT", _positive("--dt")),
    "--input": _Option("input signal: FILE.csv, NAME=EXPR, or EXPR for a single-input model (e.g. 'square(1.0, 50)'); "
                       "inputs not given are 0", "EXPR_OR_CSV", action="append"),
    "--rtol": _Option("relative tolerance of the integrator (default 1e-8)", "TOL", _positive("--rtol"), 1e-8),
    "--atol": _Option("absolute tolerance of the integrator on scaled states (default: rtol/100)", "TOL",
                      _positive("--atol")),
    "--seed": _Option("seed of the random sampling (default 0)", "N", _nonnegative_int, 0),
    "--free": _Option("parameters to fit (comma-separated)", "NAME,NAME"),
    "--outputs": _Option("measured outputs to fit (default: every one the recording provides)", "NAME,NAME"),
    "--scale": _Option("convert a column's unit (pos=mm:m, volt=kV:V) or multiply it by a factor (COLUMN=FACTOR)",
                       "COLUMN=FROM:TO", action="append"),
    "--resample": _Option("resample the recordings onto a uniform grid of step DT [s] (linear interpolation)", "DT",
                          _positive("--resample")),
    "--hold": _Option("how a recorded input behaves between samples: zoh (held by a DAC) or linear (a sampled continuous "
                      "signal); default: as the header's {annotation} says, else linear", "COLUMN=zoh|linear",
                      action="append"),
    "--validate": _Option("second CSV recording scored with the fitted model", "DATA2"),
    "--out": _Option("write the results table to FILE", "FILE"),
    "--plot": _Option("write a PNG figure to FILE", "FILE"),
    "--report": _Option("write a report directory DIR", "DIR"),
    "--resume": _Option("continue the study in --out", action="store_true", default=False),
    "--scheduler": _Option("evaluate on the Dask cluster at ADDRESS", "ADDRESS"),
    "--quiet": _Option("no progress output on stderr", action="store_true", default=False),
    "--progress": _Option("show progress bars on stderr even when it is not a terminal (default: only on a terminal)",
                          action="store_true", default=False),
    "--verbose": _Option("let solvers' own messages through to stderr (CasADi, IPOPT, SUNDIALS warnings)",
                         action="store_true", default=False),
    "--strict-ranges": _Option("make an input outside its declared range, or a state leaving its range, an error "
                               "(default: a warning, once per run)", action="store_true", default=False),
}


def add_option(p: argparse.ArgumentParser, name: str, *, required: bool = False, detail: str | None = None) -> None:
    """Add the canonical option ``name`` of :data:`OPTIONS` to the parser ``p``.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The parser of one subcommand.
    name : str
        An option of :data:`OPTIONS` (``"--t-end"``).
    required : bool, optional
        Whether the subcommand requires it.
    detail : str, optional
        A sentence appended to the canonical help text (what this subcommand does with it).

    Examples
    --------
    >>> p = argparse.ArgumentParser()
    >>> add_option(p, "--x0", detail="also the start of the equilibrium solver")
    >>> p.parse_args(["--x0", "C.Q=1e-6", "--x0", "L.p=0"]).x0
    ['C.Q=1e-6', 'L.p=0']
    """
    o = OPTIONS[name]
    text = o.help if detail is None else f"{o.help}; {detail}"
    if o.action == "store_true":
        p.add_argument(name, action="store_true", required=required, help=text)
    elif o.action == "append":
        p.add_argument(name, action="append", default=[], metavar=o.metavar, type=o.type, required=required, help=text)
    else:
        p.add_argument(name, default=o.default, metavar=o.metavar, type=o.type, required=required, help=text)


class _DeprecatedAlias(argparse.Action):
    """An old option name kept for one release: acts as ``new`` and warns on stderr."""

    def __init__(self, option_strings, dest, new: str, append: bool, **kwargs):
        self.new, self.append = new, append
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"phs: warning: {option_string} is deprecated and will be removed in the next release; use {self.new}",
              file=sys.stderr)
        if self.append:
            setattr(namespace, self.dest, [*(getattr(namespace, self.dest, None) or []), values])
        else:
            setattr(namespace, self.dest, values)


def add_deprecated_alias(p: argparse.ArgumentParser, old: str, new: str) -> None:
    """Let ``old`` act as the option ``new`` already added to ``p``, hidden from the help, with a warning.

    Examples
    --------
    >>> p = argparse.ArgumentParser()
    >>> _ = p.add_argument("--box-samples", type=int, default=10)
    >>> add_deprecated_alias(p, "--samples", "--box-samples")
    >>> p.parse_args(["--samples", "3"]).box_samples  # also prints a warning on stderr
    3
    """
    target = next(a for a in p._actions if new in a.option_strings)
    p.add_argument(old, action=_DeprecatedAlias, dest=target.dest, new=new, type=target.type, metavar=target.metavar,
                   append=isinstance(target, argparse._AppendAction), default=argparse.SUPPRESS, help=argparse.SUPPRESS)


def _add_model_argument(p: argparse.ArgumentParser) -> None:
    """The positional MODEL and ``--param``."""
    p.add_argument("model", metavar="MODEL",
                   help="module:function or path/file.py:function returning a PHSystem, or a saved model FILE.json")
    add_option(p, "--param")


def _add_model_options(p: argparse.ArgumentParser, csv: bool = True) -> None:
    """The positional MODEL, ``--param``, ``--json``, ``--progress`` and ``--verbose``; with ``csv`` (a
    subcommand that reads CSV files) also ``--time`` and ``--map``."""
    _add_model_argument(p)
    if csv:
        add_option(p, "--time")
        add_option(p, "--map")
    add_option(p, "--json")
    add_option(p, "--progress")
    add_option(p, "--verbose")


def _options_of(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {o: a for a in parser._actions if not isinstance(a, (argparse._HelpAction, _DeprecatedAlias))
            for o in a.option_strings}


def vocabulary_problems(parsers: dict[str, argparse.ArgumentParser]) -> list[str]:
    """Every departure from :data:`OPTIONS` in the parsers of the subcommands ``{name: parser}``.

    An option of the table must keep its type, default, metavar and action and its help must start
    with the canonical text; an option outside the table must not be used by two subcommands.
    Deprecated aliases are not counted.

    Examples
    --------
    >>> good, bad = argparse.ArgumentParser(), argparse.ArgumentParser()
    >>> add_option(good, "--atol")
    >>> _ = bad.add_argument("--atol", type=float, default=1e-8, help="absolute tolerance")
    >>> vocabulary_problems({"good": good, "bad": bad})  # doctest: +NORMALIZE_WHITESPACE
    ["bad --atol: help does not start with 'absolute tolerance of the integrator on scaled states (default: rtol/100)'",
     'bad --atol: metavar None, not the canonical TOL',
     'bad --atol: type float, not the canonical convert',
     'bad --atol: default 1e-08, not the canonical None']
    """
    problems: list[str] = []
    users: dict[str, list[str]] = {}
    for command, parser in parsers.items():
        for name, action in _options_of(parser).items():
            users.setdefault(name, []).append(command)
            o = OPTIONS.get(name)
            if o is None:
                continue
            where = f"{command} {name}"
            if not (action.help or "").startswith(o.help):
                problems.append(f"{where}: help does not start with {o.help!r}")
            kind = {"append": argparse._AppendAction, "store_true": argparse._StoreTrueAction}.get(o.action,
                                                                                                 argparse._StoreAction)
            if type(action) is not kind:
                problems.append(f"{where}: action {type(action).__name__}, not the canonical {o.action!r}")
            if action.metavar != o.metavar:
                problems.append(f"{where}: metavar {action.metavar}, not the canonical {o.metavar}")
            if action.type is not o.type:
                problems.append(f"{where}: type {getattr(action.type, '__name__', action.type)}, not the canonical "
                                f"{getattr(o.type, '__name__', o.type)}")
            default = [] if o.action == "append" else o.default
            if action.default != default:
                problems.append(f"{where}: default {action.default!r}, not the canonical {default!r}")
    for name, commands in sorted(users.items()):
        if name not in OPTIONS and len(commands) > 1:
            problems.append(f"{name} is used by {', '.join(commands)} but is not in the canonical table")
    return problems
