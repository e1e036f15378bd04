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
import time

from phs.errors import InputDataError
from phs.workflows.cli_options import _check_distinct, _check_writable, _time_grid, _write_outputs
from phs.workflows.cli_vocabulary import _add_model_options, add_option
from phs.workflows.inputs import between_notes, input_signals, parse_assignments
from phs.workflows.interrupts import check
from phs.workflows.loader import load_model


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
                       description="Simulate MODEL on the grid 0, DT, ..., T (DT defaults to T/1000) and write every signal to --out "
                                   "(CSV, headers 'name [unit]') and/or a figure to --plot; at least one of them.")
    _add_model_options(p)
    add_option(p, "--t-end", required=True)
    add_option(p, "--dt")
    add_option(p, "--input")
    add_option(p, "--x0")
    add_option(p, "--rtol")
    add_option(p, "--atol")
    add_option(p, "--out", detail="CSV of every signal (headers 'name [unit]')")
    add_option(p, "--plot", detail="states, measured outputs and energy")
    p.set_defaults(run=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``phs simulate`` with parsed arguments; returns the exit code.

    Every check runs and every output (CSV table, figure, summary) is
    prepared before the first file is written, so an error writes nothing.
    On success one line on standard output says what was written.
    """
    if args.out is None and args.plot is None:
        raise InputDataError("nothing to write: give --out FILE.csv (every signal), --plot FILE.png (a figure), or both")
    _check_distinct(("--out", args.out), ("--plot", args.plot), ("--json", args.json))
    _check_writable(args.out, args.plot, args.json)
    t = _time_grid(args.t_end, args.dt)
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    system = load_model(args.model, params)
    u = input_signals(system, args.input, time_column=args.time, mapping=mapping, span=(t[0], t[-1]))

    from codegen import simulate  # imported here: casadi is only needed once a model runs

    wall = time.perf_counter()
    res = simulate(system, t, u=u, x0=x0 or None, params=None, rtol=args.rtol, atol=args.atol)
    runtime = time.perf_counter() - wall
    check()  # an interrupt the integrator swallowed (and may have recovered from) stops the command here

    files = {}
    if args.out is not None:  # with how each input behaved between the samples: a fit of the file replays this run
        notes = between_notes(system, args.input, u)
        files[args.out] = lambda path: res.to_csv(path, between=notes)
    if args.plot is not None:
        files[args.plot] = _figure_png(res)
    if args.json is not None:
        files[args.json] = json.dumps(_summary(args, res, runtime), indent=1) + "\n"
    _write_outputs(files)
    written = ", ".join(p for p in (args.out, args.plot, args.json) if p is not None)
    print(f"simulated {system.name!r}: {len(res.t)} samples to t = {res.t[-1]:g} s; wrote {written}")
    return 0


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
