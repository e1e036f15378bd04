"""The ``phs`` command line.

Each subcommand is one ``_add_<name>`` function declaring its options and one
``run_<name>`` function doing the work.  Errors the project raises on purpose
(:class:`~phs.errors.PHSError`) are printed as one line
``phs: error: <message>`` with exit code 2, and no output file is written.

Examples
--------
>>> main(["--version"])  # doctest: +ELLIPSIS
phs ...
0
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import sys
import time
from collections.abc import Sequence

import numpy as np

from phs.errors import InputDataError, PHSError
from phs.io import write_atomic
from phs.workflows.inputs import input_signals, parse_assignments
from phs.workflows.loader import load_model

EXIT_ERROR = 2


# -- shared options ------------------------------------------------------------------------
def _add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL", help="module:function or path/file.py:function returning a PHSystem")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    p.add_argument("--time", default="t", metavar="COLUMN", help="time column of CSV files (default: t)")
    p.add_argument("--map", action="append", default=[], metavar="COLUMN=SIGNAL",
                   help="read model signal SIGNAL from CSV column COLUMN (default: same names)")
    p.add_argument("--json", metavar="FILE", help="write a JSON summary")


def _positive(option: str):
    def convert(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{option} must be a positive finite number, got {text!r}")
        return v

    return convert


def _check_writable(*paths: str | None) -> None:
    """Fail before any work when an output's directory does not exist."""
    for path in paths:
        if path is None:
            continue
        d = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(d):
            raise InputDataError(f"cannot write {path!r}: directory {d!r} does not exist")


# -- simulate --------------------------------------------------------------------------------
def _add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a model and write its signals to CSV",
                       description="Simulate MODEL on the grid 0, DT, ..., T and write every signal to --out.")
    _add_model_options(p)
    p.add_argument("--t-end", required=True, type=_positive("--t-end"), metavar="T", help="final time [s]")
    p.add_argument("--dt", required=True, type=_positive("--dt"), metavar="DT", help="output step [s]")
    p.add_argument("--input", action="append", default=[], metavar="EXPR_OR_CSV",
                   help="FILE.csv, NAME=EXPR, or EXPR for a single-input model (e.g. 'square(1.0, 50)'); "
                        "inputs not given are 0")
    p.add_argument("--x0", action="append", default=[], metavar="NAME=VALUE", help="initial value of a state")
    p.add_argument("--rtol", type=_positive("--rtol"), default=1e-8, help="relative tolerance (default 1e-8)")
    p.add_argument("--atol", type=_positive("--atol"), default=1e-8, help="absolute tolerance (default 1e-8)")
    p.add_argument("--out", required=True, metavar="FILE", help="CSV file of every signal")
    p.add_argument("--plot", metavar="FILE", help="PNG figure of states, measured outputs and energy")
    p.set_defaults(run=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    """Run ``phs simulate`` with parsed arguments; returns the exit code.

    Every check runs and every output (CSV table, figure, summary) is
    prepared before the first file is written, so an error writes nothing.
    """
    _check_writable(args.out, args.plot, args.json)
    if args.dt > args.t_end:
        raise InputDataError(f"--dt {args.dt:g} is larger than --t-end {args.t_end:g}")
    if args.t_end / args.dt > 1e7:
        raise InputDataError(f"--t-end / --dt gives {args.t_end / args.dt:.3g} samples; at most 1e7 are allowed")
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    system = load_model(args.model, params)
    t = np.arange(0.0, args.t_end + args.dt / 2, args.dt)
    u = input_signals(system, args.input, time_column=args.time, mapping=mapping, span=(t[0], t[-1]))

    from codegen import simulate  # imported here: casadi is only needed once a model runs

    wall = time.perf_counter()
    res = simulate(system, t, u=u, x0=x0 or None, params=None, rtol=args.rtol, atol=args.atol)
    runtime = time.perf_counter() - wall

    png = _figure_png(res) if args.plot else None
    summary = _summary(args, res, runtime) if args.json else None
    res.to_csv(args.out)
    if png is not None:
        write_atomic(args.plot, png)
    if summary is not None:
        write_atomic(args.json, json.dumps(summary, indent=1) + "\n")
    return 0


def _energy_accounts(res) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative supplied and dissipated energy (integrator quadratures when available)."""
    q = getattr(res, "quadratures", None) or {}
    if "E_supplied" in q and "E_dissipated" in q:
        return np.asarray(q["E_supplied"]), np.asarray(q["E_dissipated"])

    def cumtrapz(f):
        return np.concatenate([[0.0], np.cumsum(np.diff(res.t) * (f[1:] + f[:-1]) / 2)])

    return cumtrapz(res.supplied), cumtrapz(res.dissipated)


def _figure_png(res) -> bytes:
    """PNG of the states (scaled), measured outputs and energy accounts, rendered without pyplot."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    s = res.system
    panels = ["states"] + (["measured"] if s.measured else []) + ["energy"]
    fig = Figure(figsize=(8, 2.6 * len(panels)), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, panel in zip(axes, panels, strict=True):
        if panel == "states":
            for st in s.states:
                ax.plot(res.t, res[st.name] / st.typical, label=f"{st.name} / {st.typical:g} {st.unit}")
            ax.set_ylabel("state / scale")
        elif panel == "measured":
            for mo in s.measured:
                ax.plot(res.t, res[mo.name], label=f"{mo.name} [{mo.unit}]")
            ax.set_ylabel("measured")
        else:
            supplied, dissipated = _energy_accounts(res)
            ax.plot(res.t, res.H - res.H[0], label="H - H(0)")
            ax.plot(res.t, supplied, label="supplied")
            ax.plot(res.t, dissipated, label="dissipated")
            ax.plot(res.t, res.H - res.H[0] - supplied + dissipated, "k:", label="balance residual")
            ax.set_ylabel("energy [J]")
        ax.legend(loc="best", fontsize="small")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"{s.name}: simulation")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
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


# -- entry point -------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``phs`` with one subparser per subcommand.

    Examples
    --------
    >>> args = build_parser().parse_args(["simulate", "systems.examples:rc_circuit", "--t-end", "1",
    ...                                   "--dt", "0.1", "--out", "r.csv"])
    >>> args.t_end, args.input
    (1.0, [])
    """
    import phs

    parser = argparse.ArgumentParser(prog="phs", description="Port-Hamiltonian models from the command line.")
    parser.add_argument("--version", action="version", version=f"phs {phs.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    _add_simulate(sub)
    return parser


def _one_line(message: str) -> str:
    return message.replace(":\n  - ", ": ").replace("\n  - ", "; ").replace("\n", " ")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``phs`` command line; returns the exit code.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 on a usage error or an error naming bad input.

    Examples
    --------
    >>> main(["simulate", "no_colon", "--t-end", "1", "--dt", "0.1", "--out", "r.csv"])
    2
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else EXIT_ERROR)
    try:
        return args.run(args)
    except PHSError as exc:
        print(f"phs: error: {_one_line(str(exc))}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        print(f"phs: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("phs: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
