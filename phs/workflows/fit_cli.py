"""``phs fit``: fit parameters of a model to a CSV recording by output error
(:func:`phs.workflows.identify.identify`), with a JSON summary and a report directory."""

from __future__ import annotations

import argparse
import io
import json
import os

from phs.errors import InputDataError
from phs.workflows.cli_options import _check_distinct, _check_writable, _finite_or_none, _positive, _write_outputs
from phs.workflows.cli_recordings import add_recording_options, model_and_recordings
from phs.workflows.cli_vocabulary import _add_model_options, add_option
from phs.workflows.interrupts import check
from phs.workflows.terminal import Bar, wanted


def add_subcommand(sub) -> None:
    """Add the ``fit`` subcommand to the ``phs`` parser (``sub`` is its subparsers object).

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> args = build_parser().parse_args(["fit", "systems.examples:rc_circuit", "data.csv", "--free", "R.R"])
    >>> args.free, args.max_iter, args.report, args.quiet
    ('R.R', 100, None, False)
    """
    p = sub.add_parser(
        "fit", help="fit parameters of a model to a recording (output error)",
        description="Fit the --free parameters of MODEL to the recording DATA (CSV) by output error, print the "
                    "fitted values with confidence intervals and the NRMSE fit % per channel, and write a JSON "
                    "summary (--json) and a report directory (--report: fit.png, sensitivity.md, summary.txt).")
    _add_model_options(p)
    p.add_argument("data", metavar="DATA", help="CSV recording: a time column, the model's inputs and measured outputs")
    add_option(p, "--free", required=True)
    add_recording_options(p)
    add_option(p, "--report", detail="fit.png, sensitivity.md and summary.txt")
    p.add_argument("--max-iter", type=_positive("--max-iter", integer=True), default=100, metavar="N",
                   help="maximum number of residual evaluations (default 100)")
    add_option(p, "--quiet", detail="no progress bar of the optimiser's residual evaluations")
    p.set_defaults(run=run_fit)


def run_fit(args: argparse.Namespace) -> int:
    """Run ``phs fit`` with parsed arguments; returns the exit code.

    Every check, the fit, the validation, the sensitivity table and every output (figure,
    markdown, summary, JSON) are prepared in memory and every destination is checked (writable, no
    two on the same file) before the first file is written, so an error or an interrupt writes nothing.
    """
    report_files = [os.path.join(args.report, n) for n in _REPORT] if args.report is not None else []
    _check_distinct(("--json", args.json), *(("--report", f) for f in report_files))
    _check_writable(args.json)
    if args.report is not None:
        if os.path.exists(args.report) and not os.path.isdir(args.report):
            raise InputDataError(f"--report {args.report!r} exists and is not a directory")
        _check_writable(*(report_files if os.path.isdir(args.report) else [args.report]))
    system, rec, val, free, fitted_outputs, x0 = model_and_recordings(args)

    # imported here: casadi is only needed once a model runs
    from phs.workflows.identify import identify, sensitivity_markdown

    with Bar(wanted(args), f"fit {system.name}", total=args.max_iter, unit="eval") as bar:
        def step(evaluation: int, cost: float) -> None:
            bar.update(1)
            bar.stage(f"cost {cost:.4g}")

        result = identify(system, rec, free, x0=x0 or None, outputs=fitted_outputs, validation=val,
                          max_iter=args.max_iter, progress=step if wanted(args) else False)
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

    files = dict(zip(report_files, (png, markdown, summary + "\n"), strict=True)) if args.report is not None else {}
    if document is not None:
        files[args.json] = document
    created = args.report is not None and not os.path.isdir(args.report)
    check()  # an interrupt the integrator swallowed stops the command before anything is written
    try:
        if created:
            os.makedirs(args.report)
        _write_outputs(files)
    except BaseException:
        if created and os.path.isdir(args.report) and not os.listdir(args.report):
            os.rmdir(args.report)  # all or nothing: not even the report's directory
        raise
    return 0


_REPORT = ("fit.png", "sensitivity.md", "summary.txt")  # the files of --report DIR


def _echo(args: argparse.Namespace) -> str:
    """The command as given (``phs VERSION fit MODEL DATA --free ...``), quoted for a shell; without the
    arguments as given (a direct call of :func:`run_fit`), rebuilt from the parsed options that shape the fit."""
    import shlex

    import phs

    argv = getattr(args, "argv", None)
    if argv:
        return f"phs {phs.__version__} {shlex.join(argv)}"
    words = ["fit", args.model, args.data, "--free", args.free]
    for option, value in (("--validate", args.validate), ("--outputs", args.outputs), ("--resample", args.resample),
                          ("--time", None if args.time == "t" else args.time)):
        if value is not None:
            words += [option, str(value)]
    for option, values in (("--param", args.param), ("--x0", args.x0), ("--map", args.map), ("--scale", args.scale),
                           ("--hold", getattr(args, "hold", None)), ("--input", getattr(args, "input", None))):
        for v in values or ():
            words += [option, str(v)]
    return f"phs {phs.__version__} {shlex.join(words)}"


def _fit_summary_text(args: argparse.Namespace, result) -> str:
    head = [_echo(args),
            f"model hash {result.system.model_hash()}; {len(result.residuals[result.outputs[0]])} samples; "
            f"outputs {', '.join(result.outputs)}"]
    return "\n".join(head + [result.summary()])


def _fit_figure_png(result) -> bytes:
    import matplotlib.pyplot as plt

    fig = result.plot()
    try:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90)
    finally:
        plt.close(fig)
    return buf.getvalue()


def _fit_json(args: argparse.Namespace, result, val, sensitivity: dict) -> str:
    import phs

    doc = result.to_dict()
    doc.update({
        "command": "fit",
        "model": args.model,
        "data": args.data,
        "input": list(getattr(args, "input", None) or ()),  # inputs the recordings lacked, as --input NAME=EXPR
        "phs_version": phs.__version__,
        "x0": {name: float(v) for name, v in zip(result.system.state_names, result.x0, strict=True)},
        "validation": None if val is None else {"data": args.validate, "samples": len(val),
                                                "fit_percent": result.validation_fit_percent},
    })
    if sensitivity:
        doc["sensitivity_by_channel"] = {ch: {k: {str(s): f for s, f in row.items()} for k, row in table.items()}
                                         for ch, table in sensitivity.items()}
    return json.dumps(_finite_or_none(doc), indent=1, allow_nan=False) + "\n"
