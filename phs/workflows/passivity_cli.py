"""``phs passivity``: the passivity certificate of a model from a terminal.

    phs passivity MODEL [--box NAME=LO:HI ...] [--equilibrium NAME=VALUE ...] [--x0 NAME=VALUE ...]
                  [--input EXPR_OR_CSV ...] [--t-end T [--dt DT]] [--box-samples N] [--starts N] [--seed N]
                  [--param NAME=VALUE ...] [--time COLUMN] [--map COLUMN=SIGNAL ...] [--json FILE] [--report DIR]

prints the certificate (:func:`codegen.passivity.certify`) and exits with 0 when the model is certified
passive, 1 when it is not, and 2 on an error naming the bad option (nothing is written then).

Examples
--------
>>> from phs.workflows.cli import main
>>> main(["passivity", "systems.examples:rc_circuit", "--param", "R.R=-1000", "--box-samples", "32", "--starts", "1"])  # doctest: +ELLIPSIS
Passivity of 'rc' (model ...): NOT CERTIFIED PASSIVE; margin -2
...
1
"""

from __future__ import annotations

import argparse
import json
import math
import os

from phs.errors import InputDataError
from phs.workflows.cli_options import (
    _check_distinct,
    _check_writable,
    _nonnegative_int,
    _positive,
    _time_grid,
    _write_outputs,
)
from phs.workflows.cli_vocabulary import _add_model_options, add_deprecated_alias, add_option
from phs.workflows.inputs import input_signals, parse_assignments, read_input_csv
from phs.workflows.loader import load_model
from phs.workflows.terminal import Bar, wanted


def add_subcommand(sub) -> None:
    """Add the ``passivity`` subparser to the ``phs`` command line.

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> args = build_parser().parse_args(["passivity", "systems.examples:rc_circuit", "--box", "C.Q=-1e-6:1e-6"])
    >>> args.box, args.box_samples
    (['C.Q=-1e-6:1e-6'], 2000)
    """
    p = sub.add_parser(
        "passivity", help="certify that a model is passive over a box of states and parameters",
        description="Certify MODEL passive: J skew, [[R, P], [P^T, S]] positive semidefinite over the box "
                    "(symbolic where decidable, else sampled and optimised with the worst point), H bounded below; "
                    "optionally the dissipation inequality along a simulation (--input) and the passivity indices "
                    "of the linearisation at an equilibrium (--equilibrium).  Exit status 0: passive, 1: not "
                    "certified passive, 2: error.")
    _add_model_options(p)
    p.add_argument("--box", action="append", default=[], metavar="NAME=LO:HI",
                   help="bounds of a state (default: its declared range) or of a parameter to vary (NAME alone: "
                        "the parameter's declared range)")
    p.add_argument("--equilibrium", action="append", default=[], metavar="NAME=VALUE",
                   help="add the local test at an equilibrium: input values (the equilibrium is solved for) and/or "
                        "state values (checked to be an equilibrium)")
    add_option(p, "--x0", detail="also the start of the equilibrium solver")
    add_option(p, "--input", detail="adds the dissipation inequality along a simulation with these inputs (a "
                                    "CSV file's time grid unless --t-end)")
    add_option(p, "--t-end")
    add_option(p, "--dt")
    p.add_argument("--box-samples", type=_positive("--box-samples", integer=True), default=2000, metavar="N",
                   help="points of the dense sample of the box (default 2000)")
    add_deprecated_alias(p, "--samples", "--box-samples")
    p.add_argument("--starts", type=_nonnegative_int, default=8, metavar="N",
                   help="starts of each nlpsol minimisation (default 8)")
    add_option(p, "--seed", detail="of the sample of the box")
    add_option(p, "--report", detail="report.html (with plots), report.json, report.txt, *.png")
    add_option(p, "--quiet", detail="no progress bar")
    p.set_defaults(run=run_passivity)


def parse_box(items, system) -> dict:
    """Parse ``--box NAME=LO:HI`` (or ``NAME`` for a parameter's declared range) into ``{name: (lo, hi)}``.

    Raises
    ------
    InputDataError
        Naming the item: malformed bounds, non-finite values, lower > upper, an unknown name, a name given twice.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> parse_box(["C.Q=-1e-6:2e-6", "R.R"], rc_circuit())
    {'C.Q': (-1e-06, 2e-06), 'R.R': None}
    >>> parse_box(["C.Q=1:0"], rc_circuit())
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --box C.Q=1:0: lower bound 1 > upper bound 0
    """
    out: dict = {}
    for item in items or ():
        name, sep, value = str(item).partition("=")
        name = name.strip()
        if name in out:
            raise InputDataError(f"--box: {name!r} is given twice")
        if name not in system.state_names and name not in system.param_names:
            raise InputDataError(f"--box {item}: system {system.name!r} has no state or parameter {name!r} "
                                 f"(states: {', '.join(system.state_names)})")
        if not sep:
            if name in system.state_names:
                raise InputDataError(f"--box {item}: give the bounds of state {name!r} as {name}=LO:HI")
            out[name] = None
            continue
        lo, colon, hi = value.partition(":")
        try:
            a, b = float(lo), float(hi)
        except ValueError:
            a = b = None
        if not colon or a is None:
            raise InputDataError(f"--box {item}: expected NAME=LO:HI with numbers, e.g. {name}=-0.1:0.1")
        if not (math.isfinite(a) and math.isfinite(b)):
            raise InputDataError(f"--box {item}: bounds must be finite")
        if a > b:
            raise InputDataError(f"--box {item}: lower bound {a:g} > upper bound {b:g}")
        out[name] = (a, b)
    return out


def _equilibrium_spec(items, system):
    """(claimed states, inputs) from ``--equilibrium NAME=VALUE`` items."""
    values = parse_assignments(items, "--equilibrium", numeric=True)
    states, inputs = {}, {}
    for name, v in values.items():
        if name in system.state_names:
            states[name] = v
        elif name in system.input_names:
            inputs[name] = v
        else:
            raise InputDataError(f"--equilibrium {name}={v:g}: system {system.name!r} has no state or input {name!r} "
                                 f"(inputs: {', '.join(system.input_names) or 'none'}; states: "
                                 f"{', '.join(system.state_names)})")
    return states, inputs


def _trajectory(args, system, x0: dict):
    """``{"t", "u", "x0"}`` for the trajectory test, or None without --input / --t-end."""
    if not args.input and args.t_end is None:
        if args.dt is not None:
            raise InputDataError("--dt needs --t-end (or an --input CSV file giving the time grid)")
        return None
    mapping = parse_assignments(args.map, "--map")
    csvs = [s for s in args.input if str(s).strip().lower().endswith(".csv")]
    if args.t_end is not None:
        t = _time_grid(args.t_end, args.dt)
    elif csvs:
        t, _ = read_input_csv(csvs[0], system, args.time, mapping)
    else:
        raise InputDataError("--input with an expression needs --t-end")
    u = input_signals(system, args.input, time_column=args.time, mapping=mapping, span=(t[0], t[-1]))
    return {"t": t, "u": u, "x0": x0 or None}


def run_passivity(args: argparse.Namespace) -> int:
    """Run ``phs passivity`` with parsed arguments; returns 0 (passive), 1 (not certified passive).

    Every destination is checked (writable, no two options on one file) before any work; every check
    runs and every output is rendered before the first file is written, and they are written all or
    nothing (the report's directory included).
    """
    report_names = [os.path.join(args.report, n) for n in _REPORT] if args.report is not None else []
    _check_distinct(("--json", args.json), ("--report", args.report), *(("--report", f) for f in report_names))
    _check_writable(args.json)
    if args.report is not None:
        if os.path.exists(args.report) and not os.path.isdir(args.report):
            raise InputDataError(f"--report {args.report!r} exists and is not a directory")
        _check_writable(os.path.join(args.report, "report.html") if os.path.isdir(args.report) else args.report)
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    system = load_model(args.model)  # --param values are the certificate's what-if overrides: a value of the wrong
    system.param_vector(params, signs=False)  # sign is reported as a failure, not refused (unknown names raise)
    unknown = [k for k in x0 if k not in system.state_names]
    if unknown:
        raise InputDataError(f"--x0: system {system.name!r} has no state {unknown[0]!r} "
                             f"(states: {', '.join(system.state_names)})")
    box = parse_box(args.box, system)
    states, inputs = _equilibrium_spec(args.equilibrium, system)
    trajectory = _trajectory(args, system, x0)

    from codegen.passivity import certify  # imported here: casadi is only needed once a model runs

    equilibrium = (states or True) if args.equilibrium else None
    stages = ["structure"] + (["equilibrium"] if equilibrium or inputs else []) + (["trajectory"] if trajectory else []) \
        + ["sampling", "dissipation", "storage"]
    with Bar(wanted(args), f"passivity {system.name}", total=len(stages), unit="stage", ticking=True,
             bar_format="{desc}: {n_fmt}/{total_fmt} stages |{bar}| {elapsed}{postfix}") as bar:
        def stage(name: str) -> None:
            if name in stages:
                bar.to(stages.index(name))
            bar.stage(name)

        report = certify(system, box=box, params=params or None, equilibrium=equilibrium, u=inputs or None,
                         x0=x0 or None, trajectory=trajectory, samples=args.box_samples, starts=args.starts,
                         seed=args.seed, progress=stage)
        bar.to(len(stages))
    text = report.text()
    files: dict[str, str | bytes] = {}  # every output of --report and --json: all written, or none
    if args.report is not None:
        files.update({os.path.join(args.report, n): data for n, data in report.report_files().items()})
        _check_distinct(("--json", args.json), *(("--report", f) for f in files))  # the figures' names too
    if args.json:
        import phs

        doc = report.to_dict()
        doc.update({"command": "passivity", "model": args.model, "phs_version": phs.__version__})
        files[args.json] = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    from phs.workflows.interrupts import check

    check()  # an interrupt an integrator swallowed stops the command before anything is written
    print(text)
    _write_outputs(files, create=[args.report] if args.report is not None else [])
    return 0 if report.passive else 1


_REPORT = ("report.html", "report.json", "report.txt")  # --report DIR, besides one PNG per figure
