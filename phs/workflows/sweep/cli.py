"""``phs sweep``: a design study from the command line (see :mod:`phs.workflows.sweep`).

::

    phs sweep MODEL --range NAME=LO:HI:N ... [--param NAME=VALUE ...] [--samples N]
              --metric SPEC ... --t-end T --dt DT [--input EXPR ...] --out results.parquet
              [--scheduler ADDRESS | --processes N] [--resume] [--plot FILE] [--json FILE] [--max-failed SHARE]

``--range`` takes ``NAME=LO:HI:N`` (a grid axis of N values, ``NAME=LO:HI:N:log`` geometric),
``NAME=V1,V2,...`` (listed values) or ``NAME=LO:HI`` (``:log``) for a variable drawn
``--samples`` times (Latin hypercube); grid axes and samples combine.  A variable that is not a
parameter of the model may be used by name in ``--input`` expressions (``--range V=1:5:5
--input "V=step(1000*V, 0.05)"`` sweeps a step amplitude in kV).  ``--from-fit FIT.json`` (the
``--json`` of ``phs fit``) draws the fitted parameters from their estimated covariance.
Failed runs are rows of the results like the others (status ``failed`` and their error); when every
run failed, or more than ``--max-failed`` of them (default half), the command still writes its
outputs and then exits with an error naming the first failure.

Examples
--------
>>> from phs.workflows.cli import build_parser
>>> args = build_parser().parse_args(["sweep", "systems.examples:rc_circuit", "--range", "R.R=1e3:2e3:3",
...                                   "--metric", "final:v_C", "--t-end", "1e-3", "--dt", "1e-4",
...                                   "--out", "r.csv"])
>>> args.range, args.metric, args.resume
(['R.R=1e3:2e3:3'], ['final:v_C'], False)
"""

from __future__ import annotations

import argparse
import ast
import json
import math

import numpy as np

from phs.errors import InputDataError, ParameterError, SimulationError
from phs.workflows.cli_options import (
    _check_distinct,
    _check_writable,
    _finite_or_none,
    _positive,
    _time_grid,
    _write_outputs,
)
from phs.workflows.cli_vocabulary import _add_model_options, add_option
from phs.workflows.inputs import input_signals, parse_assignments
from phs.workflows.loader import load_model
from phs.workflows.sweep.design import LogUniform, Uniform, from_fit
from phs.workflows.sweep.metrics import metric
from phs.workflows.sweep.run import sweep
from phs.workflows.sweep.study import Study
from phs.workflows.terminal import wanted

#: Default of ``--max-failed``: a study in which more than half of the runs failed exits with an error.
MAX_FAILED = 0.5


def add_subcommand(sub) -> None:
    """Add the ``sweep`` subcommand to the ``phs`` parser (``sub`` is its subparsers object).

    Examples
    --------
    >>> import argparse
    >>> sub = argparse.ArgumentParser(prog="phs").add_subparsers()
    >>> add_subcommand(sub)
    >>> sorted(sub.choices)
    ['sweep']
    """
    p = sub.add_parser(
        "sweep", help="evaluate a model over a grid or samples of parameters (metrics per run)",
        description="Simulate MODEL for every combination of the --range grid axes (and --samples drawn "
                    "from the sampled ranges), compute the --metric values of each run and write one row per "
                    "run to --out (Parquet or CSV) as runs finish; --resume continues an interrupted study.")
    _add_model_options(p)
    p.add_argument("--range", action="append", default=[], metavar="NAME=LO:HI:N",
                   help="grid axis (LO:HI:N, LO:HI:N:log, or V1,V2,...) or sampled range (LO:HI, LO:HI:log)")
    p.add_argument("--samples", type=_positive("--samples", integer=True), metavar="N",
                   help="number of samples of the sampled ranges (and --from-fit)")
    p.add_argument("--sampling", choices=("lhs", "random"), default="lhs", help="Latin hypercube (default) or random")
    add_option(p, "--seed")
    p.add_argument("--from-fit", metavar="FIT.json", help="sample the fitted parameters of a 'phs fit --json' file")
    p.add_argument("--metric", action="append", default=[], metavar="SPEC",
                   help="peak:SIGNAL, peak_abs:SIGNAL, final:SIGNAL, rise_time:SIGNAL[:START:END], energy, "
                        "passivity_margin, fit:SIGNAL (with --data)")
    add_option(p, "--t-end")
    add_option(p, "--dt")
    p.add_argument("--data", metavar="DATA", help="CSV recording: its time grid and inputs drive every run "
                                                   "(and fit:SIGNAL metrics compare with it)")
    add_option(p, "--input", detail="expressions may use the non-parameter variables of --range")
    for name in ("--x0", "--rtol", "--atol"):
        add_option(p, name)
    add_option(p, "--out", required=True, detail=".parquet or .csv, one row per run")
    p.add_argument("--resume", action="store_true", help="continue the study in --out: only missing runs run")
    p.add_argument("--retry-failed", action="store_true", help="with --resume, run the failed runs again")
    p.add_argument("--threads", type=_positive("--threads", integer=True), metavar="N",
                   help="threads of the evaluation (default: all processors; per task with Dask)")
    p.add_argument("--processes", type=_positive("--processes", integer=True), metavar="N",
                   help="evaluate on a local Dask cluster of N worker processes")
    p.add_argument("--scheduler", metavar="ADDRESS", help="evaluate on the Dask cluster at ADDRESS (tcp://host:8786)")
    p.add_argument("--chunk", type=_positive("--chunk", integer=True), metavar="N", help="runs per chunk / Dask task")
    add_option(p, "--plot", detail="every metric against every variable")
    p.add_argument("--max-failed", type=_share, default=MAX_FAILED, metavar="SHARE",
                   help=f"exit with an error when more than this share of the runs failed (default {MAX_FAILED}); "
                        "a study whose every run failed is always an error")
    add_option(p, "--quiet", detail="no progress bar")
    p.set_defaults(run=run_sweep)


# -- option parsing -------------------------------------------------------------------------------------
def _share(text: str) -> float:
    """argparse type of ``--max-failed``: a number from 0 to 1."""
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0.0 <= v <= 1.0:
        raise argparse.ArgumentTypeError(f"--max-failed must be a share from 0 to 1, got {text!r}")
    return v


def check_failures(result, max_failed: float = MAX_FAILED) -> None:
    r"""Raise when every run of a study failed, or more than the share ``max_failed`` of them.

    The results are written before: the error only makes the command fail, naming how many runs
    failed and the first failure (lowest run number) in one line.

    Raises
    ------
    SimulationError
        Naming the count, the share allowed and the first failed run's error.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.sweep import StudyResult
    >>> cols = {"run": np.arange(4), "status": np.array(["ok", "failed", "failed", "failed"], dtype=object),
    ...         "error": np.array(["", "boom\nat t=1", "boom", "boom"], dtype=object)}
    >>> check_failures(StudyResult(cols, [], []), max_failed=0.75)
    >>> check_failures(StudyResult(cols, [], []))
    Traceback (most recent call last):
    ...
    phs.errors.SimulationError: 3 of 4 runs failed (more than --max-failed 0.5); first failure, run 1: boom at t=1
    """
    failed, n = result.failed, len(result)
    if not failed or (len(failed) < n and len(failed) <= max_failed * n):
        return
    run, error = failed[0]
    why = "every run failed" if len(failed) == n else f"{len(failed)} of {n} runs failed (more than --max-failed {max_failed:g})"
    raise SimulationError(f"{why}; first failure, run {run}: {' '.join(error.split())}")


def parse_range(item: str) -> tuple[str, list[float] | Uniform | LogUniform]:
    """Parse one ``--range`` value into ``(name, values)`` (a grid axis) or ``(name, distribution)``.

    Raises
    ------
    InputDataError
        Naming the item when it is malformed (bounds, count, numbers).

    Examples
    --------
    >>> parse_range("K_b=0.02:0.06:3")
    ('K_b', [0.02, 0.04, 0.06])
    >>> parse_range("R=1e3:1e5:3:log")
    ('R', [1000.0, 10000.0, 100000.0])
    >>> parse_range("V=1,2.5")
    ('V', [1.0, 2.5])
    >>> parse_range("b=0.5:2")
    ('b', Uniform(low=0.5, high=2.0))
    """
    [(name, spec)] = parse_assignments([item], "--range").items()

    def number(text):
        try:
            v = float(text)
        except ValueError:
            raise InputDataError(f"--range {item!r}: {text.strip()!r} is not a number") from None
        if not math.isfinite(v):
            raise InputDataError(f"--range {item!r}: {text.strip()!r} is not finite")
        return v

    if "," in spec:
        return name, [number(v) for v in spec.split(",")]
    parts = [s.strip() for s in spec.split(":")]
    log = parts[-1].lower() == "log"
    if log:
        parts = parts[:-1]
    if len(parts) not in (2, 3):
        raise InputDataError(f"--range {item!r}: expected NAME=LO:HI:N, NAME=LO:HI (sampled) or NAME=V1,V2,...")
    lo, hi = number(parts[0]), number(parts[1])
    if not lo < hi:
        raise InputDataError(f"--range {item!r}: LO must be below HI")
    if log and lo <= 0:
        raise InputDataError(f"--range {item!r}: a log range needs LO > 0")
    if len(parts) == 2:
        return name, (LogUniform(lo, hi) if log else Uniform(lo, hi))
    try:
        n = int(parts[2])
    except ValueError:
        raise InputDataError(f"--range {item!r}: the count {parts[2]!r} is not an integer") from None
    if n < 2:
        raise InputDataError(f"--range {item!r}: a grid axis needs N >= 2 values (use --param for one value)")
    values = np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)
    return name, [float(f"{v:.15g}") for v in values]  # 0.04, not 0.039999999999999994


def _expression_names(text: str) -> set[str]:
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        return set()  # parse_expression reports it
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}


def _substituted(text: str, values: dict) -> str:
    """The expression ``text`` with the named variables replaced by their values."""
    class Sub(ast.NodeTransformer):
        def visit_Name(self, node):  # noqa: N802 - ast API
            if node.id in values:
                return ast.copy_location(ast.Constant(float(values[node.id])), node)
            return node

    return ast.unparse(Sub().visit(ast.parse(text.strip(), mode="eval")))


class _InputsOf:
    """``u_for`` of a study whose ``--input`` expressions use variables: substitute, then parse."""

    def __init__(self, system, specs, variables):
        self.system, self.specs, self.variables = system, list(specs), list(variables)

    def __repr__(self) -> str:
        return "; ".join(self.specs)

    def __call__(self, values: dict) -> dict:
        subs = {k: values[k] for k in self.variables}
        texts = []
        for spec in self.specs:
            name, sep, expr = spec.partition("=")
            texts.append(f"{name}={_substituted(expr, subs)}" if sep and name.strip() in self.system.input_names
                         else _substituted(spec, subs))
        return input_signals(self.system, texts)


def run_sweep(args) -> int:
    """Run ``phs sweep`` with parsed arguments; returns the exit code.

    The study is checked completely (model, ranges, metrics, inputs, files: writable, no two outputs
    on the same file) before the first run; rows are then written to ``--out`` as runs finish, and
    the figure and JSON summary at the end, both or neither.  SIGINT/SIGTERM keep the finished rows
    (for ``--resume``) and write nothing else.
    """
    sidecar = args.out + ".study.json" if args.out.lower().endswith(".csv") else None  # the CSV's study, beside it
    _check_distinct(("--out", args.out), ("--out", sidecar), ("--plot", args.plot), ("--json", args.json))
    _check_writable(args.out, args.plot, args.json)
    if args.scheduler is not None and args.processes is not None:
        raise InputDataError("give either --processes (a local Dask cluster) or --scheduler ADDRESS, not both")
    if args.retry_failed and not args.resume:
        raise InputDataError("--retry-failed needs --resume")
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    system = load_model(args.model, params)
    grid, dists = {}, {}
    for item in args.range:
        name, spec = parse_range(item)
        if name in grid or name in dists:
            raise InputDataError(f"--range: {name!r} is given twice")
        if name in params:
            raise InputDataError(f"--range {name}: also fixed by --param; give it one way")
        (grid if isinstance(spec, list) else dists)[name] = spec
    if args.from_fit:
        try:
            with open(args.from_fit) as fh:
                doc = json.load(fh)
        except (OSError, ValueError) as exc:
            raise InputDataError(f"--from-fit {args.from_fit!r}: cannot read it as JSON ({exc})") from None
        for key in ("free", "values", "std_errors", "correlation"):
            if key not in doc:
                raise InputDataError(f"--from-fit {args.from_fit!r}: no {key!r} (write it with 'phs fit --json')")
        clash = [k for k in doc["free"] if k in grid or k in dists or k in params]
        if clash:
            raise InputDataError(f"--from-fit: {clash[0]!r} is also given by --range or --param")
        dists.update(from_fit(doc))
    if dists and not args.samples:
        raise InputDataError("sampled ranges (LO:HI) and --from-fit need --samples N")
    if args.samples and not dists:
        raise InputDataError("--samples needs a sampled range (NAME=LO:HI) or --from-fit")
    if not args.metric:
        raise InputDataError("give at least one --metric (e.g. --metric peak:tip)")
    if x0:
        unknown = [k for k in x0 if k not in system.state_names]
        if unknown:
            raise InputDataError(f"--x0: system {system.name!r} has no state {unknown[0]!r} "
                                 f"(states: {', '.join(system.state_names)})")
    # variables that are not parameters are input-expression variables
    names = list(grid) + [n for key in dists for n in ((key,) if isinstance(key, str) else key)]
    extra = [n for n in names if n not in system.param_names]
    used = set().union(*[_expression_names(s.partition("=")[2] if "=" in s else s) for s in args.input]) \
        if args.input else set()
    unused = [n for n in extra if n not in used]
    if unused:
        raise ParameterError(f"--range {unused[0]}: {unused[0]!r} is not a parameter of {system.name!r} and no "
                             f"--input uses it (parameters: {', '.join(system.param_names)})")
    recording = None
    if args.data is not None:
        if args.t_end is not None or args.dt is not None or args.input:
            raise InputDataError("--data gives the time grid and inputs: do not combine it with --t-end, --dt, --input")
        from phs.workflows.recording import Recording

        recording = Recording.from_csv(args.data, time_column=args.time, mapping=mapping).in_units_of(system)
        t = None
    else:
        if args.t_end is None:
            raise InputDataError("give the time grid with --t-end (and --dt) or a recording with --data")
        t = _time_grid(args.t_end, args.dt)
    metrics = [metric(m, recording) for m in args.metric]
    u, u_for = None, None
    if recording is not None:
        u = recording
    elif extra:
        u_for = _InputsOf(system, args.input, extra)
        u_for({n: 1.0 for n in extra})  # a malformed expression fails now, naming it
    else:
        u = input_signals(system, args.input, time_column=args.time, mapping=mapping, span=(t[0], t[-1]))
    study = Study(system, t, u=u, u_for=u_for, x0=x0 or None, grid=grid, distributions=dists,
                  samples=args.samples or 0, sampling=args.sampling, seed=args.seed, metrics=metrics,
                  rtol=args.rtol, atol=args.atol)
    result = sweep(study, args.out, resume=args.resume, retry_failed=args.retry_failed, threads=args.threads,
                   processes=args.processes, scheduler=args.scheduler, chunk_size=args.chunk, progress=wanted(args))
    files = {}
    if args.plot is not None:
        files[args.plot] = result.plot  # rendered into a temporary file beside --plot, renamed with the others
    if args.json is not None:
        import phs

        doc = {"command": "sweep", "model": args.model, "system": system.name, "model_hash": system.model_hash(),
               "phs_version": phs.__version__, "out": args.out, "runs": len(result), "ok": int(result.ok.sum()),
               "failed": len(result.failed), "new_runs": result.new_runs, "seconds": result.seconds,
               "runs_per_second": result.new_runs / result.seconds if result.seconds > 0 else None,
               "variables": result.variables, "metrics": result.metrics, "seed": args.seed,
               "sampling": args.sampling, "params": params,
               "metric_ranges": {c: _range(result[c][result.ok]) for c in result.metrics},
               "failures": [{"run": r, "error": e} for r, e in result.failed[:50]]}
        files[args.json] = json.dumps(_finite_or_none(doc), indent=1, allow_nan=False) + "\n"
    _write_outputs(files)
    print(result.summary())
    check_failures(result, args.max_failed)
    return 0


def _range(v) -> dict:
    v = v[np.isfinite(v)]
    if not len(v):
        return {"min": None, "median": None, "max": None}
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}
