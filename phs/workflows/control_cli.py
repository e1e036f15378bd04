"""``phs control``: design an IDA-PBC controller from a terminal.

    phs control MODEL --target NAME=VALUE [...] [--controlled NAME ...] [--fixed NAME=VALUE ...] [--x0 NAME=VALUE ...]
                [--neglect STATE,STATE] [--damping R | --damping STATE=D] [--stiffness STATE=K ...]
                [--integral {passive,output}] [--integral-time T] [--t-end T] [--dt DT] [--plant-param NAME=VALUE ...]
                [--rays N] [--simulations N] [--export-c DIR] [--param NAME=VALUE ...] [--json FILE] [--report DIR]

assigns the equilibrium at which the targets hold (NAME is a state or a measured output: ``--target tip=0.03``),
solves the matching equations, prints the design and its certificates
(:mod:`codegen.idapbc`), and optionally simulates the closed loop (``--t-end``; the plant is the full model,
with ``--plant-param`` overrides for a plant/controller mismatch), exports the law to C (``--export-c``) and
writes a report directory (``controller.txt``, ``certificates.json``, ``closed_loop.png``, ``closed_loop.csv``).
Exit status: 0 when every certificate passed and, with ``--t-end``, every target is within 1 % of its value
at the end of the simulated time; 1 when a certificate failed or a target was not reached in the simulated
time (the summary line of that target says ``NOT REACHED``); 2 on an error (an unreachable target included);
nothing is written on an error.

Examples
--------
>>> from phs.workflows.cli import main
>>> main(["control", "systems.examples:mass_spring_damper", "--target", "position=0.5", "--stiffness", "k.l=6",
...       "--damping", "2", "--rays", "8", "--simulations", "2"])  # doctest: +ELLIPSIS
IDA-PBC controller for 'msd'
...
Certificates of the IDA-PBC controller for 'msd': all passed
...
0
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os

import numpy as np

from phs.errors import InputDataError
from phs.workflows.cli_options import (
    _check_distinct,
    _check_writable,
    _finite_or_none,
    _name_list,
    _positive,
    _time_grid,
    _write_outputs,
)
from phs.workflows.cli_vocabulary import _add_model_options, add_deprecated_alias, add_option
from phs.workflows.inputs import parse_assignments
from phs.workflows.interrupts import check
from phs.workflows.loader import load_model
from phs.workflows.terminal import Bar, wanted


def add_subcommand(sub) -> None:
    """Add the ``control`` subparser to the ``phs`` command line.

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> args = build_parser().parse_args(["control", "systems:curling_hasel", "--target", "tip=0.03"])
    >>> args.target, args.integral
    (['tip=0.03'], None)
    """
    p = sub.add_parser(
        "control", help="design an IDA-PBC controller holding a model at a target, with certificates",
        description="Design an IDA-PBC controller for MODEL that holds the targets (states or measured outputs), "
                    "print the assigned equilibrium, the solved matching equations and the certificates (matching "
                    "residual, J_d skew, R_d PSD, critical point, Hessian, closed-loop eigenvalues, region of "
                    "attraction, closed-loop simulations).  Exit status 0: all certificates passed and (with --t-end) every "
                    "target within 1 % of its value at the end of the simulated time; 1: a certificate failed or a "
                    "target was not reached in the simulated time (the summary says which); 2: error (an unreachable "
                    "target included).")
    _add_model_options(p, csv=False)
    p.add_argument("--target", action="append", default=[], required=True, metavar="NAME=VALUE",
                   help="value to hold a state or measured output at (one per controlled input)")
    p.add_argument("--controlled", action="append", default=[], metavar="NAME",
                   help="controlled input (default: all inputs, when as many as targets)")
    add_deprecated_alias(p, "--input", "--controlled")
    p.add_argument("--fixed", action="append", default=[], metavar="NAME=VALUE", help="value of an input not controlled")
    add_option(p, "--x0", detail="also picks the leaf to regulate on (e.g. seg1.l_p=0.015)")
    p.add_argument("--neglect", metavar="STATE,STATE", help="storages left out of the design (globs such as seg*.Q1)")
    p.add_argument("--damping", metavar="R|STATE=D", default="0",
                   help="damping injection: R in R_a = R g g^T, or STATE=D for the dissipation D added on that row at x*")
    p.add_argument("--stiffness", action="append", default=[], metavar="STATE=K",
                   help="curvature of the added energy along a state at x* (energy shaping)")
    p.add_argument("--structure", choices=("auto", "ansatz", "electromechanical"), default="auto",
                   help="how the matching equations are solved (default: auto)")
    p.add_argument("--integral", choices=("passive", "output"), help="integral action on the passive output or the "
                                                                    "target error")
    p.add_argument("--integral-time", type=_positive("--integral-time"), metavar="T",
                   help="time constant of the integral action [s]")
    add_option(p, "--t-end", detail="simulates the closed loop")
    add_option(p, "--dt")
    p.add_argument("--plant-param", action="append", default=[], metavar="NAME=VALUE",
                   help="parameter of the simulated plant only (plant/controller mismatch)")
    p.add_argument("--rays", type=_positive("--rays", integer=True), default=32, metavar="N",
                   help="rays of the region-of-attraction estimate (default 32)")
    p.add_argument("--simulations", type=_positive("--simulations", integer=True), default=6, metavar="N",
                   help="closed-loop runs from random states in that region (default 6)")
    p.add_argument("--export-c", metavar="DIR", help="write the control law as C source and header into DIR")
    add_option(p, "--report", detail="controller.txt, certificates.json, closed_loop.png/.csv")
    add_option(p, "--quiet", detail="no progress bar")
    p.set_defaults(run=run_control)


def _damping(text: str):
    if "=" in text:
        (name, value), = parse_assignments([text], "--damping", numeric=True).items()
        return {name: value}
    try:
        v = float(text)
    except ValueError:
        raise InputDataError(f"--damping {text!r}: expected a number or STATE=VALUE") from None
    if not (math.isfinite(v) and v >= 0):
        raise InputDataError(f"--damping {text!r}: must be a finite number >= 0")
    return v


def _check_dir(option: str, path: str | None) -> None:
    if path is None:
        return
    if os.path.exists(path) and not os.path.isdir(path):
        raise InputDataError(f"{option} {path!r} exists and is not a directory")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise InputDataError(f"{option} {path!r}: directory {parent!r} does not exist")
    writable = path if os.path.isdir(path) else parent
    if not os.access(writable, os.W_OK | os.X_OK):
        raise InputDataError(f"{option} {path!r}: directory {writable!r} is not writable")


def run_control(args: argparse.Namespace) -> int:
    """Run ``phs control`` with parsed arguments; returns the exit code (0, 1; errors raise).

    1 when a certificate failed, or when the closed-loop simulation (``--t-end``) ends with a target
    not within 1 % of its value: the summary then says so in words.

    Everything (design, certificates, simulation, figure, C sources, JSON) is computed before the first
    file is written.
    """
    report_names = [os.path.join(args.report, n) for n in _REPORT] if args.report is not None else []
    _check_distinct(("--json", args.json), ("--report", args.report), *(("--report", f) for f in report_names))
    _check_distinct(("--json", args.json), ("--export-c", args.export_c))  # one directory may take both
    _check_writable(args.json)
    _check_dir("--report", args.report)
    _check_dir("--export-c", args.export_c)
    params = parse_assignments(args.param, "--param", numeric=True)
    target = parse_assignments(args.target, "--target", numeric=True)
    fixed = parse_assignments(args.fixed, "--fixed", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    stiffness = parse_assignments(args.stiffness, "--stiffness", numeric=True)
    plant_params = parse_assignments(args.plant_param, "--plant-param", numeric=True)
    neglect = _name_list(args.neglect, "--neglect")
    damping = _damping(args.damping)
    if args.dt is not None and args.t_end is None:
        raise InputDataError("--dt needs --t-end")
    t = None if args.t_end is None else _time_grid(args.t_end, args.dt)
    system = load_model(args.model, params)
    if not system.inputs:
        raise InputDataError(f"system {system.name!r} has no inputs: there is nothing for a controller to drive")
    if not args.controlled and len(target) != len(system.inputs):
        raise InputDataError(f"system {system.name!r} has {len(system.inputs)} input(s) ({', '.join(system.input_names)}) "
                             f"and {len(target)} --target: name the inputs the controller drives with --controlled "
                             "(one per target; the others held with --fixed NAME=VALUE)")
    if plant_params:
        system.param_vector(plant_params)  # ParameterError naming an unknown parameter before any work

    from codegen.idapbc import design  # imported here: casadi is only needed once a model runs

    stages = ["design", "certificates"] + (["closed loop"] if t is not None else [])
    res = None
    with Bar(wanted(args), f"control {system.name}", total=len(stages), unit="stage", ticking=True,
             bar_format="{desc}: {n_fmt}/{total_fmt} stages |{bar}| {elapsed}{postfix}") as bar:
        bar.stage("design")
        ctrl = design(system, target, inputs=args.controlled or None, fixed_inputs=fixed, x0=x0 or None,
                      neglect=neglect, structure=args.structure, damping=damping, stiffness=stiffness,
                      integral=args.integral, integral_time=args.integral_time)
        bar.to(1)
        bar.stage("certificates")
        report = ctrl.certify(rays=args.rays, simulations=args.simulations)
        if t is not None:
            bar.to(2)
            bar.stage("closed loop")
            res = ctrl.simulate(t, plant=system, params=plant_params, x0=x0 or None)  # default: start_state
        bar.to(len(stages))
    text = ctrl.summary() + "\n" + report.text()
    unreached: list[str] = []
    if res is not None:
        lines = [f"closed loop on {system.name!r}" + (f" with {', '.join(f'{k}={v:g}' for k, v in plant_params.items())}"
                                                      if plant_params else "") + f", {args.t_end:g} s"
                 + (f" from the loaded rest state ({res.info['loaded']})" if res.info["loaded"] else "") + ":"]
        for tg in ctrl.targets:
            e = res.error(tg.name)
            settled = res.settling_time(0.01, tg.name)
            line = f"  {tg.name}: final {res[tg.name][-1]:.6g} {tg.unit} (error {100 * e[-1]:+.4f} %), "
            if math.isfinite(settled):
                lines.append(line + f"within 1 % after {settled:.4g} s")
            else:
                unreached.append(tg.name)
                lines.append(line + f"NOT REACHED: not within 1 % of the target {tg.value:g} {tg.unit} by the end "
                                    f"of the simulated {args.t_end:g} s (simulate longer with --t-end)")
        for nm, info in res.info["input_ranges"].items():
            lines.append(f"  {nm} from {info['min']:.6g} to {info['max']:.6g}"
                         + (" - OUTSIDE its range" if info["exceeded"] else ""))
        lines.append(f"  largest increase of H_d{' + integrator energy' if ctrl.integral == 'passive' else ''} "
                     f"between samples: {res.max_increase('H_cl'):.3g} J")
        text += "\n" + "\n".join(lines)
    files: dict[str, str | bytes] = {}
    if args.report is not None:
        files["controller.txt"] = text + "\n"
        files["certificates.json"] = json.dumps(_finite_or_none(report.to_dict()), indent=1, allow_nan=False) + "\n"
        if res is not None:
            files["closed_loop.png"] = _png(res)
            buf = io.StringIO()
            header, data = res.table()
            np.savetxt(buf, data, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
            files["closed_loop.csv"] = buf.getvalue()
    sources = None
    if args.export_c is not None:
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            paths = ctrl.export_c(tmp)
            sources = {os.path.basename(p): open(p, encoding="utf-8").read() for p in paths}
    document = None
    if args.json:
        import phs

        document = {"command": "control", "model": args.model, "phs_version": phs.__version__,
                    "controller": ctrl.to_dict(), "certificates": report.to_dict()}
        if res is not None:
            document["closed_loop"] = {
                "t_end": float(res.t[-1]), "plant_params": plant_params,
                "final": {tg.name: float(res[tg.name][-1]) for tg in ctrl.targets},
                "settling_time_1pct": {tg.name: res.settling_time(0.01, tg.name) for tg in ctrl.targets},
                "reached": {tg.name: tg.name not in unreached for tg in ctrl.targets},
                "max_increase_H": res.max_increase("H_cl"), "inputs": res.info["input_ranges"]}
        document = json.dumps(_finite_or_none(document), indent=1, allow_nan=False) + "\n"
    outputs = {}  # every file of --report, --export-c and --json: all written, or none
    named = [("--json", args.json)] if document is not None else []
    for option, folder, contents in (("--report", args.report, files), ("--export-c", args.export_c, sources)):
        if folder is not None and contents is not None:
            for name, data in contents.items():
                outputs[os.path.join(folder, name)] = data
                named.append((option, os.path.join(folder, name)))
    if document is not None:
        outputs[args.json] = document
    _check_distinct(*named)
    check()  # an interrupt an integrator swallowed stops the command before anything is written
    print(text)
    _write_outputs(outputs, create=[d for d in (args.report, args.export_c) if d is not None])  # removed on failure
    return 0 if report.passed and not unreached else 1


_REPORT = ("controller.txt", "certificates.json", "closed_loop.png", "closed_loop.csv")  # --report DIR


def _plant_x0(ctrl, system, x0: dict, plant_params: dict | None = None) -> tuple[np.ndarray, str]:
    """Initial plant state of ``--t-end`` and the states a load moved, in words: the closed loop's own default
    start, :func:`codegen.idapbc.closed_loop.start_state` (``ctrl.simulate`` without ``x0`` starts there too)."""
    from codegen.idapbc.closed_loop import start_state

    return start_state(ctrl, system, x0 or None, plant_params or None)


def _png(res) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 7), constrained_layout=True)
    FigureCanvasAgg(fig)
    res.plot(fig=fig)
    fig.suptitle(f"{res.system.name}: closed loop under IDA-PBC")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()
