"""``phs simulate``: simulate a model and write its signals to CSV and/or a figure.

Examples
--------
>>> from phs.workflows.cli import build_parser
>>> args = build_parser().parse_args(["simulate", "systems.examples:rc_circuit", "--t-end", "1",
...                                   "--dt", "0.1", "--input", "step(1.0, 0.2)", "--out", "r.csv"])
>>> args.input, args.rtol, args.plot
(['step(1.0, 0.2)'], 1e-08, None)
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time

import numpy as np

from phs.errors import DomainError, InputDataError
from phs.workflows.cli_options import _check_distinct, _check_writable, _time_grid, _write_outputs
from phs.workflows.cli_output import size_warning, table_columns, write_csv
from phs.workflows.cli_vocabulary import _add_model_options, add_option
from phs.workflows.inputs import between_notes, input_signals, parse_assignments, read_input_csv
from phs.workflows.interrupts import check
from phs.workflows.loader import load_model
from phs.workflows.ranges import input_report, range_messages, range_report
from phs.workflows.terminal import Bar, wanted


def add_subcommand(sub) -> None:
    """Add the ``simulate`` subcommand to the ``phs`` parser (``sub`` is its subparsers object).

    Examples
    --------
    >>> import argparse
    >>> parser = argparse.ArgumentParser(prog="phs")
    >>> add_subcommand(parser.add_subparsers())
    >>> parser.parse_args(["simulate", "m:f", "--t-end", "1", "--dt", "0.1", "--out", "r.csv"]).dt
    0.1
    """
    p = sub.add_parser("simulate", help="simulate a model and write its signals to CSV and/or a figure",
                       description="Simulate MODEL on the grid 0, DT, ..., T (DT defaults to T/1000; without --t-end, "
                                   "the time grid of the --input CSV file) and write every signal to --out "
                                   "(CSV, headers 'name [unit]') and/or a figure to --plot; at least one of them.")
    _add_model_options(p)
    add_option(p, "--t-end", detail="default: the end of the --input CSV file's time grid")
    add_option(p, "--dt")
    add_option(p, "--input")
    add_option(p, "--x0")
    add_option(p, "--rtol")
    add_option(p, "--atol")
    add_option(p, "--out", detail="CSV of every signal (headers 'name [unit]'); its size is estimated first and a "
                                  "large one warned about")
    add_option(p, "--plot", detail="states, measured outputs and energy")
    add_option(p, "--strict-ranges")
    add_option(p, "--quiet", detail="no progress bar")
    p.set_defaults(run=run_simulate)


def _grid_and_inputs(args: argparse.Namespace, system, mapping: dict):
    """The output grid and the input signals: ``--t-end``/``--dt``, or without ``--t-end`` the time grid of the
    ``--input`` CSV file (every ``DT`` over its span with ``--dt``)."""
    if args.t_end is not None:
        t = _time_grid(args.t_end, args.dt)
        return t, input_signals(system, args.input, time_column=args.time, mapping=mapping, span=(t[0], t[-1]))
    csvs = [s for s in args.input if str(s).strip().lower().endswith(".csv")]
    if not csvs:
        raise InputDataError("--t-end is needed unless an --input CSV file gives the time grid")
    if len(csvs) > 1:
        raise InputDataError(f"--input: give at most one CSV file (got {', '.join(csvs)})")
    u = input_signals(system, [s for s in args.input if s not in csvs])  # the expressions, then the file once
    file_t, read = read_input_csv(csvs[0], system, args.time, mapping, skip=u)
    u.update(read)
    t = np.asarray(file_t, dtype=float)
    if args.dt is not None:
        if args.dt > t[-1] - t[0]:
            raise InputDataError(f"--dt {args.dt:g} is longer than the {t[-1] - t[0]:g} s of {csvs[0]}")
        t = t[0] + _time_grid(t[-1] - t[0], args.dt)
        t = t[t <= file_t[-1] + 1e-9 * args.dt]
    elif len(t) > 1e7 + 1:
        raise InputDataError(f"{csvs[0]} has {len(t)} rows; at most 1e7 output times are allowed (give --dt)")
    return t, u


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``phs simulate`` with parsed arguments; returns the exit code.

    Every check runs and every output (CSV table, figure, summary) is
    prepared before the first file is written, so an error writes nothing.
    A CSV estimated above :data:`~phs.workflows.cli_output.LARGE_OUTPUT` bytes is warned about before the
    simulation starts; inputs outside their declared ranges are warned about before it, states leaving
    theirs after it (errors with ``--strict-ranges``: :mod:`phs.workflows.ranges`).  Progress bars of the
    simulation and of the writing show on a terminal (:mod:`phs.workflows.terminal`).
    On success one line on standard output says what was written.
    """
    if args.out is None and args.plot is None:
        raise InputDataError("nothing to write: give --out FILE.csv (every signal), --plot FILE.png (a figure), or both")
    _check_distinct(("--out", args.out), ("--plot", args.plot), ("--json", args.json))
    _check_writable(args.out, args.plot, args.json)
    if args.t_end is not None:
        _time_grid(args.t_end, args.dt)  # a bad grid is refused before the model is built
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    system = load_model(args.model, params)
    t, u = _grid_and_inputs(args, system, mapping)
    strict = getattr(args, "strict_ranges", False)
    _say(range_messages({"inputs": input_report(system, t, u)}, system.name), strict, InputDataError)
    if args.out is not None:
        warning = size_warning("--out", args.out, len(t), table_columns(system))
        if warning is not None:
            print(f"phs: warning: {warning}", file=sys.stderr, flush=True)

    from codegen import simulate  # imported here: casadi is only needed once a model runs

    show = wanted(args)
    wall = time.perf_counter()
    with Bar(show, f"simulate {system.name}", total=1.0, unit="run", ticking=True,
             bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}") as bar:
        res = simulate(system, t, u=u, x0=x0 or None, params=None, rtol=args.rtol, atol=args.atol, progress=bar.to)
    runtime = time.perf_counter() - wall
    check()  # an interrupt the integrator swallowed (and may have recovered from) stops the command here
    _say(range_messages({"states": range_report(res)["states"]}, system.name), strict, DomainError)

    files = {}
    if args.out is not None:  # with how each input behaved between the samples: a fit of the file replays this run
        notes = between_notes(system, args.input, u)
        files[args.out] = lambda path: _write_table(res, notes, path, show)
    if args.plot is not None:
        files[args.plot] = _figure_png(res)
    if args.json is not None:
        files[args.json] = json.dumps(_summary(args, res, runtime), indent=1) + "\n"
    _write_outputs(files)
    written = ", ".join(p for p in (args.out, args.plot, args.json) if p is not None)
    print(f"simulated {system.name!r}: {len(res.t)} samples to t = {res.t[-1]:g} s; wrote {written}")
    return 0


def _say(messages: list[str], strict: bool, error) -> None:
    """Range messages of one run: one warning line on stderr, or with ``--strict-ranges`` an ``error`` naming the first."""
    if not messages:
        return
    if strict:
        raise error(messages[0] + " (--strict-ranges)")
    print("phs: warning: " + "; ".join(messages) + " (--strict-ranges makes this an error)", file=sys.stderr, flush=True)


def _write_table(res, notes: dict, path: str, show: bool) -> None:
    """The CSV of ``res`` at ``path`` (the bytes of ``res.to_csv(path, between=notes)``), with a progress bar."""
    header, data = res.table()
    cells = [f"{name} [{res.unit(name)}]" + (f" {{{notes[name]}}}" if name in notes else "") for name in header]
    with Bar(show and len(data) >= 100_000, "write", total=len(data), unit="row") as bar:
        write_csv(path, cells, data, bar)


def _figure_png(res) -> bytes:
    """PNG of :meth:`SimulationResult.plot <codegen.results.SimulationResult.plot>`, rendered in memory."""
    buf = io.BytesIO()
    res.plot().savefig(buf, format="png", dpi=110)
    return buf.getvalue()


def _summary(args: argparse.Namespace, res, runtime: float) -> dict:
    s = res.system
    import phs

    return {
        "command": "simulate",
        "model": args.model,
        "system": s.name,
        "model_hash": s.model_hash(),
        "phs_version": phs.__version__,
        "params": s.param_values(),
        "t_end": float(res.t[-1]),
        "samples": len(res.t),
        "final_state": {name: float(res[name][-1]) for name in s.state_names},
        "final_measured": {name: float(res[name][-1]) for name in s.measured_names},
        "energy_balance_error": res.energy_balance_error(),
        "runtime_seconds": runtime,
        "out": args.out,
    }
