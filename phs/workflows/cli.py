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
import importlib
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

# Subcommands defined in their workflow's own module: each has ``add_subcommand(sub)``, which adds
# its parser and sets ``run`` (a function of the parsed arguments returning the exit code).
_SUBCOMMAND_MODULES: tuple[str, ...] = (
    "phs.workflows.passivity_cli",
    "phs.workflows.control_cli",
    "phs.workflows.diagnose.cli",
    "phs.workflows.sweep_cli",
)


# -- shared options ------------------------------------------------------------------------
def _add_model_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL", help="module:function or path/file.py:function returning a PHSystem")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    p.add_argument("--time", default="t", metavar="COLUMN", help="time column of CSV files (default: t)")
    p.add_argument("--map", action="append", default=[], metavar="COLUMN=SIGNAL",
                   help="read model signal SIGNAL from CSV column COLUMN (default: same names)")
    p.add_argument("--json", metavar="FILE", help="write a JSON summary")


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


# -- fit ---------------------------------------------------------------------------------------------
def _add_fit(sub) -> None:
    p = sub.add_parser(
        "fit", help="fit parameters of a model to a recording (output error)",
        description="Fit the --free parameters of MODEL to the recording DATA (CSV) by output error, print the "
                    "fitted values with confidence intervals and the NRMSE fit % per channel, and write a JSON "
                    "summary (--json) and a report directory (--report: fit.png, sensitivity.md, summary.txt).")
    _add_model_options(p)
    p.add_argument("data", metavar="DATA", help="CSV recording: a time column, the model's inputs and measured outputs")
    p.add_argument("--free", required=True, metavar="NAME,NAME", help="parameters to fit (comma-separated)")
    add_recording_options(p)
    p.add_argument("--report", metavar="DIR", help="write DIR/fit.png, DIR/sensitivity.md and DIR/summary.txt")
    p.add_argument("--max-iter", type=_positive("--max-iter", integer=True), default=100, metavar="N",
                   help="maximum number of residual evaluations (default 100)")
    p.add_argument("--quiet", action="store_true", help="do not print the optimiser's progress on stderr")
    p.set_defaults(run=run_fit)


def add_recording_options(p: argparse.ArgumentParser) -> None:
    """Options of the subcommands that fit a model to a recording (``fit``, ``diagnose``)."""
    p.add_argument("--x0", action="append", default=[], metavar="NAME=VALUE", help="initial value of a state")
    p.add_argument("--scale", action="append", default=[], metavar="COLUMN=FROM:TO",
                   help="convert a column's unit (pos=mm:m, volt=kV:V) or multiply it by a factor (COLUMN=FACTOR)")
    p.add_argument("--resample", type=_positive("--resample"), metavar="DT",
                   help="resample the recordings onto a uniform grid of step DT [s] (linear interpolation)")
    p.add_argument("--outputs", metavar="NAME,NAME",
                   help="measured outputs to fit (default: every one the recording provides)")
    p.add_argument("--validate", metavar="DATA2", help="second CSV recording scored with the fitted model")


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


def parse_scales(items) -> dict:
    """Parse ``--scale COLUMN=FROM:TO`` (unit conversion) or ``COLUMN=FACTOR`` values.

    Raises
    ------
    InputDataError
        Naming the option and the column: malformed item, unknown unit, units of different
        dimensions, a factor that is not a finite non-zero number.

    Examples
    --------
    >>> parse_scales(["pos=mm:m", "volt=kV:V", "i=0.5"])
    {'pos': ('mm', 'm'), 'volt': ('kV', 'V'), 'i': 0.5}
    >>> parse_scales(["pos=mm:V"])
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --scale pos=mm:V: cannot convert 'mm' to 'V': different dimensions
    """
    from phs.workflows.recording import unit_factor

    out: dict = {}
    for column, value in parse_assignments(items, "--scale").items():
        if ":" in value:
            src, _, dst = value.partition(":")
            src, dst = src.strip(), dst.strip()
            if not src or not dst:
                raise InputDataError(f"--scale {column}={value}: expected FROM:TO units such as mm:m")
            try:
                unit_factor(src, dst)
            except InputDataError as exc:
                raise InputDataError(f"--scale {column}={value}: {exc}") from None
            out[column] = (src, dst)
            continue
        try:
            factor = float(value)
        except ValueError:
            raise InputDataError(f"--scale {column}={value}: expected FROM:TO units (mm:m) or a number") from None
        if not (math.isfinite(factor) and factor != 0):
            raise InputDataError(f"--scale {column}={value}: the factor must be a finite non-zero number")
        out[column] = factor
    return out


def _csv_header(path: str) -> list[str] | None:
    """Column names of a CSV file, or None when it cannot be read (the recording reader then says why)."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for cells in csv.reader(fh):
                if cells and any(c.strip() for c in cells):
                    return [c.strip() for c in cells]
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    return None


def _read_recording(path: str, system, args, mapping: dict, scales: dict, outputs: list[str]):
    """Read the columns of ``path`` that the fit needs (inputs and fitted outputs) as a Recording."""
    from phs.workflows.recording import Recording

    known = system.measured_names + system.output_names + system.state_names
    column_of = {sig: col for col, sig in mapping.items()}
    header = _csv_header(path)
    columns = None
    if header is not None:
        if outputs:
            wanted = system.input_names + outputs
        else:
            signal_of = {c: mapping.get(c, c) for c in header if c != args.time}
            wanted = system.input_names + [signal_of[c] for c in signal_of if signal_of[c] in known]
        columns = list(dict.fromkeys(column_of.get(sig, sig) for sig in wanted))
        columns += [c for c in scales if c in header and c not in columns and c != args.time]
    try:
        return Recording.from_csv(path, time_column=args.time, mapping=mapping, scales=scales,
                                  resample=args.resample, columns=columns)
    except InputDataError as exc:  # say it with the command line's option names
        raise InputDataError(str(exc).replace("pass resample=DT", "pass --resample DT")) from None


def model_and_recordings(args: argparse.Namespace):
    """Load the model and the recordings of a fitting subcommand (``fit``, ``diagnose``), checking every
    name given on the command line first.  Returns ``(system, recording, validation or None, free,
    fitted outputs, x0)``."""
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    scales = parse_scales(args.scale)
    free = _name_list(args.free, "--free")
    outputs = _name_list(args.outputs, "--outputs")
    system = load_model(args.model, params)
    for name in free:
        system.param(name)  # ParameterError naming an unknown parameter and the known ones
    known = system.measured_names + system.output_names + system.state_names
    seen: dict = {}
    for column, signal in mapping.items():
        if signal in seen:
            raise InputDataError(f"--map: signal {signal!r} is mapped from two columns ({seen[signal]!r} and "
                                 f"{column!r})")
        seen[signal] = column
        if signal not in system.input_names and signal not in known:
            raise InputDataError(f"--map {column}={signal}: system {system.name!r} has no input or output "
                                 f"{signal!r} (inputs: {', '.join(system.input_names) or 'none'}; measured: "
                                 f"{', '.join(system.measured_names) or 'none'})")
    bad = [o for o in outputs if o not in known]
    if bad:
        raise InputDataError(f"--outputs: system {system.name!r} has no output {bad[0]!r} "
                             f"(measured: {', '.join(system.measured_names) or 'none'})")
    if x0:
        unknown = [k for k in x0 if k not in system.state_names]
        if unknown:
            raise InputDataError(f"--x0: system {system.name!r} has no state {unknown[0]!r} "
                                 f"(states: {', '.join(system.state_names)})")
    rec = _read_recording(args.data, system, args, mapping, scales, outputs)
    _, fitted_outputs = rec.check_for(system, outputs or None)
    val = None
    if args.validate is not None:
        val = _read_recording(args.validate, system, args, mapping, scales, fitted_outputs)
        val.check_for(system, fitted_outputs)
    return system, rec, val, free, fitted_outputs, x0


def run_fit(args: argparse.Namespace) -> int:
    """Run ``phs fit`` with parsed arguments; returns the exit code.

    Every check, the fit, the validation, the sensitivity table and every output (figure,
    markdown, summary, JSON) are prepared in memory before the first file is written, so an
    error writes nothing.
    """
    _check_writable(args.json)
    if args.report is not None:
        if os.path.exists(args.report) and not os.path.isdir(args.report):
            raise InputDataError(f"--report {args.report!r} exists and is not a directory")
        _check_writable(os.path.join(args.report, "summary.txt") if os.path.isdir(args.report) else args.report)
    system, rec, val, free, fitted_outputs, x0 = model_and_recordings(args)

    from phs.workflows.identify import identify  # imported here: casadi is only needed once a model runs

    result = identify(system, rec, free, x0=x0 or None, outputs=fitted_outputs, validation=val,
                      max_iter=args.max_iter, progress=not args.quiet)
    summary = _fit_summary_text(args, result)
    sensitivity = {}
    png = markdown = None
    if args.report is not None:
        for ch in reversed(fitted_outputs):  # the first channel last: it is the one kept in result.sensitivity
            sensitivity[ch] = result.sensitivity_table(channel=ch)
        sensitivity = {ch: sensitivity[ch] for ch in fitted_outputs}
        png = _fit_figure_png(result)
        markdown = sensitivity_markdown(sensitivity, result)
    document = _fit_json(args, result, val, sensitivity) if args.json else None
    print(summary)

    if args.report is not None:
        os.makedirs(args.report, exist_ok=True)
        write_atomic(os.path.join(args.report, "fit.png"), png)
        write_atomic(os.path.join(args.report, "sensitivity.md"), markdown)
        write_atomic(os.path.join(args.report, "summary.txt"), summary + "\n")
    if document is not None:
        write_atomic(args.json, document)
    return 0


def _fit_summary_text(args: argparse.Namespace, result) -> str:
    import phs

    head = [f"phs {phs.__version__} fit {args.model} {args.data}" + (f" --validate {args.validate}" if args.validate
                                                                      else ""),
            f"model hash {result.system.model_hash()}; {len(result.residuals[result.outputs[0]])} samples; "
            f"outputs {', '.join(result.outputs)}"]
    return "\n".join(head + [result.summary()])


def sensitivity_markdown(tables: dict, result=None) -> str:
    """The ±5/±10 % sensitivity tables (one per channel) as markdown.

    Parameters
    ----------
    tables : dict
        ``{channel: {parameter: {step: fit %, ..., "std": sd}}}`` as returned per channel by
        ``IdentificationResult.sensitivity_table``.
    result : IdentificationResult, optional
        Adds the fitted values to the table.

    Examples
    --------
    >>> row = {-0.1: 80.0, -0.05: 90.0, 0.0: 95.0, 0.05: 90.0, 0.1: 80.0, "std": 6.52}
    >>> print(sensitivity_markdown({"tip": {"K_b": row}}))  # doctest: +NORMALIZE_WHITESPACE
    ## Sensitivity of the fit of `tip` (NRMSE fit %)
    <BLANKLINE>
    | parameter | -10 % | -5 % | 0 % | +5 % | +10 % | SD |
    | --- | ---: | ---: | ---: | ---: | ---: | ---: |
    | `K_b` | 80.00 | 90.00 | 95.00 | 90.00 | 80.00 | 6.5200 |
    <BLANKLINE>
    """
    out = []
    for ch, table in tables.items():
        steps = sorted(k for row in table.values() for k in row if k != "std")
        steps = list(dict.fromkeys(steps))
        cols = [f"{s * 100:+.0f} %".replace("+0 %", "0 %") for s in steps]
        fitted = result is not None
        out.append(f"## Sensitivity of the fit of `{ch}` (NRMSE fit %)\n")
        out.append("| parameter" + (" | fitted value" if fitted else "") + " | " + " | ".join(cols) + " | SD |")
        out.append("| ---" + (" | ---:" if fitted else "") + " | ---:" * (len(cols) + 1) + " |")
        for name, row in sorted(table.items(), key=lambda kv: -np.nan_to_num(kv[1]["std"], nan=-1.0)):
            value = f" | {result.values[name]:.6g}" if fitted else ""
            out.append(f"| `{name}`{value} | " + " | ".join(f"{row[s]:.2f}" for s in steps) + f" | {row['std']:.4f} |")
        out.append("")
    if result is not None:
        out.append("Each row moves one fitted parameter alone by the given relative step and re-simulates; "
                   "SD is the sample standard deviation of the five fits (the curling HASEL paper's Table 5). "
                   "Rows are sorted from the most to the least sensitive parameter.\n")
    return "\n".join(out)


def _fit_figure_png(result) -> bytes:
    import matplotlib.pyplot as plt

    fig = result.plot()
    try:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90)
    finally:
        plt.close(fig)
    return buf.getvalue()


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


def _fit_json(args: argparse.Namespace, result, val, sensitivity: dict) -> str:
    import phs

    doc = result.to_dict()
    doc.update({
        "command": "fit",
        "model": args.model,
        "data": args.data,
        "phs_version": phs.__version__,
        "x0": {name: float(v) for name, v in zip(result.system.state_names, result.x0, strict=True)},
        "validation": None if val is None else {"data": args.validate, "samples": len(val),
                                                "fit_percent": result.validation_fit_percent},
    })
    if sensitivity:
        doc["sensitivity_by_channel"] = {ch: {k: {str(s): f for s, f in row.items()} for k, row in table.items()}
                                         for ch, table in sensitivity.items()}
    return json.dumps(_finite_or_none(doc), indent=1, allow_nan=False) + "\n"


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
    _add_fit(sub)
    for module in _SUBCOMMAND_MODULES:
        importlib.import_module(module).add_subcommand(sub)
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
