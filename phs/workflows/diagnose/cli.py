"""The ``phs diagnose`` subcommand."""

from __future__ import annotations

import argparse
import os
import sys

from phs.errors import InputDataError


def add_subcommand(sub) -> None:
    """Add ``phs diagnose`` to the subparsers ``sub``.

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> args = build_parser().parse_args(["diagnose", "systems.examples:rc_circuit", "data.csv", "--free", "R.R"])
    >>> args.free, args.max_effects, args.discover
    ('R.R', 2, None)
    >>> build_parser().parse_args(["diagnose", "m:f", "d.csv", "--no-discover"]).discover
    False
    """
    from phs.workflows.cli_options import _positive
    from phs.workflows.cli_recordings import add_recording_options
    from phs.workflows.cli_vocabulary import _add_model_options, add_option

    p = sub.add_parser(
        "diagnose", help="find where a model misses a recording, which physics is missing, and the fixed model",
        description="Fit MODEL to DATA, locate where the residual concentrates, fit every candidate effect of the "
                    "library attached to the model, and say which physics the model left out (or none), with the "
                    "fit before and after.  Writes a JSON (--json) and an HTML report (--report DIR).")
    _add_model_options(p)
    p.add_argument("data", metavar="DATA", nargs="+",
                   help="CSV recording: a time column, the model's inputs and measured outputs; several files or a "
                        "folder of them: trials diagnosed one by one, then which effects recur across them")
    add_option(p, "--free", detail="the nominal parameters refitted with every hypothesis (default: those with a "
                                   "declared range, at most 8)")
    add_recording_options(p)
    add_option(p, "--report", detail="index.html, figures, diagnosis.json and summary.txt")
    p.add_argument("--effects", metavar="NAME,NAME", help="only these candidate effects (default: the whole library)")
    p.add_argument("--max-effects", type=_positive("--max-effects", integer=True), default=2, metavar="N",
                   help="accept at most N effects one after the other (default 2)")
    p.add_argument("--jobs", type=_positive("--jobs", integer=True), metavar="N",
                   help="processes fitting hypotheses (with several recordings: diagnosing trials) in parallel "
                        "(default: CPUs, at most 4)")
    p.add_argument("--discover", dest="discover", action="store_true", default=None,
                   help="always look for a passive correction outside the library (default: when the residual stays structured)")
    p.add_argument("--no-discover", dest="discover", action="store_false", help="never look outside the library")
    p.add_argument("--discover-out", metavar="FILE",
                   help="write the discovered correction as Python source of a candidate class (nothing is written when none is found)")
    add_option(p, "--scheduler", detail="the hypotheses' fits (one recording) or the trials (several) run on its "
                                        "workers, with the same verdicts as here")
    p.add_argument("--shared", metavar="NAME,NAME",
                   help="several recordings: nominal parameters with one value for every trial, fitted jointly on all "
                        "of them first and then held in each trial's diagnosis")
    add_option(p, "--out", detail="several recordings: FILE is a directory holding trials/NAME.json (each trial's "
                                  "diagnosis, written as it finishes), summary.csv, summary.json and shared.json")
    add_option(p, "--resume", detail="several recordings: the trials already there (same model, options and data) "
                                     "are read back, only the missing ones run; one of other options is refused")
    add_option(p, "--plot", detail="several recordings: how often each effect came, and its parameters by trial")
    add_option(p, "--quiet")
    p.set_defaults(run=run_diagnose)


def run_diagnose(args: argparse.Namespace) -> int:
    """Run ``phs diagnose``; returns 0, or :data:`EXIT_REFUSED` when the nominal model cannot describe the
    recording.  Every destination is checked (writable, no two options on one file) before any work, and
    every output is prepared in memory and written all or nothing (the report's directory included)."""
    from phs.workflows.cli_options import _check_distinct, _check_writable, _write_outputs
    from phs.workflows.cli_recordings import model_and_recordings

    if len(args.data) > 1 or os.path.isdir(args.data[0]):
        return run_trials(args)
    for option, given in (("--shared", args.shared), ("--out", args.out), ("--resume", args.resume), ("--plot", args.plot)):
        if given:
            raise InputDataError(f"{option} is for several recordings (DATA DATA... or a folder of trials)")
    args.data = args.data[0]
    report = [os.path.join(args.report, n) for n in _REPORT] if args.report else []
    _check_distinct(("--json", args.json), ("--discover-out", args.discover_out), ("--report", args.report),
                    *(("--report", f) for f in report))
    _check_writable(args.json)
    if args.discover_out is not None:
        if args.discover is False:
            raise InputDataError("--discover-out needs discovery: drop --no-discover")
        _check_writable(args.discover_out)
    if args.report is not None:
        if os.path.exists(args.report) and not os.path.isdir(args.report):
            raise InputDataError(f"--report {args.report!r} exists and is not a directory")
        _check_writable(os.path.join(args.report, "index.html") if os.path.isdir(args.report) else args.report)
    candidates = _candidates(args.effects)
    system, rec, val, free, outputs, x0 = model_and_recordings(args)

    from phs.workflows.diagnose import diagnose
    from phs.workflows.diagnose.pool import on_cluster
    from phs.workflows.terminal import wanted

    with on_cluster(args.scheduler):
        d = diagnose(system, rec, validation=val, free=free or None, outputs=outputs, candidates=candidates,
                     x0=x0 or None, max_effects=args.max_effects, n_jobs=args.jobs, progress=wanted(args),
                     discover=args.discover)
    text = d.summary()
    files: dict[str, str | bytes] = {}  # every output of --report, --json and --discover-out: all written, or none
    if args.report is not None:
        from phs.workflows.diagnose.report import _report_files

        files.update({os.path.join(args.report, n): data for n, data in _report_files(d).items()})
    if args.json is not None:
        from phs.workflows.diagnose.report import to_json

        files[args.json] = to_json(d)
    if args.discover_out is not None and d.discovery is not None and d.discovery.found:
        emitted = d.discovered_source()
        compile(emitted, args.discover_out, "exec")  # the emitted class is valid Python before anything is written
        files[args.discover_out] = emitted
    from phs.workflows.interrupts import check

    check()  # an interrupt an integrator swallowed stops the command before anything is written
    print(text)
    _write_outputs(files, create=[args.report] if args.report is not None else [])
    if d.refused:  # the JSON and the report are written with the figures; the exit code says no verdict was reached
        from phs.workflows.diagnose.refusal import headline

        print(f"phs diagnose: {headline(d.verdict, args.data)}", file=sys.stderr)
        return EXIT_REFUSED
    return 0


EXIT_REFUSED = 1
"""Exit code of ``phs diagnose`` when the nominal model cannot describe the recording (no effect named; one
line on stderr says which channel and what to check).  A convention, not a measurement."""

_REPORT = ("index.html", "fits.png", "hypotheses.png", "locate.png", "diagnosis.json", "summary.txt")  # --report DIR


def _candidates(effects: str | None):
    """The candidates of ``--effects`` (None: the whole library); an unknown name is refused, naming the known."""
    from components.candidates import LIBRARY
    from phs.workflows.cli_options import _name_list

    names = _name_list(effects, "--effects")
    known = [c.effect for c in LIBRARY]
    bad = [n for n in names if n not in known]
    if bad:
        raise InputDataError(f"--effects: unknown effect {bad[0]!r}; known: {', '.join(known)}")
    return [c for c in LIBRARY if c.effect in names] if names else None


def trial_files(data: list[str]) -> dict[str, str]:
    """Trials of ``DATA...`` by name (the file name without ``.csv``): each file, and every ``*.csv`` of each folder
    (sorted).

    Raises
    ------
    InputDataError
        A path that does not exist, a folder without CSV files, two trials of one name.

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     for n in ("b.csv", "a.csv", "notes.txt"):
    ...         open(os.path.join(d, n), "w").close()
    ...     sorted(trial_files([d]))
    ['a', 'b']
    """
    files: dict[str, str] = {}
    for item in data:
        if os.path.isdir(item):
            found = sorted(os.path.join(item, f) for f in os.listdir(item) if f.lower().endswith(".csv"))
            if not found:
                raise InputDataError(f"DATA {item!r}: the folder holds no .csv file")
        elif os.path.exists(item):
            found = [item]
        else:
            raise InputDataError(f"DATA {item!r}: no such file or folder")
        for path in found:
            name = os.path.splitext(os.path.basename(path))[0]
            if name in files:
                raise InputDataError(f"two trials are named {name!r} ({files[name]} and {path}): give them distinct file names")
            files[name] = path
    return files


def run_trials(args: argparse.Namespace) -> int:
    """``phs diagnose`` with several recordings: each trial diagnosed (:func:`~phs.workflows.diagnose.trials.diagnose_trials`),
    the recurring effects printed and written (``--out DIR``, ``--json``, ``--plot``)."""
    from phs.workflows.cli_options import _check_distinct, _check_writable, _name_list, _write_outputs
    from phs.workflows.cli_recordings import model_and_recordings
    from phs.workflows.diagnose.trials import diagnose_trials
    from phs.workflows.terminal import wanted

    for option, given in (("--report", args.report), ("--discover-out", args.discover_out), ("--validate", args.validate)):
        if given is not None:
            raise InputDataError(f"{option} is for one recording; with several, --out DIR keeps each trial's diagnosis")
    if args.resume and args.out is None:
        raise InputDataError("--resume needs --out DIR (the directory of the trials to continue)")
    summary = [os.path.join(args.out, n) for n in ("summary.json", "summary.csv")] if args.out else []
    _check_distinct(("--json", args.json), ("--plot", args.plot), *(("--out", f) for f in summary))
    _check_writable(args.json, args.plot)
    if args.out is not None:
        if os.path.exists(args.out) and not os.path.isdir(args.out):
            raise InputDataError(f"--out {args.out!r} exists and is not a directory")
        _check_writable(os.path.join(args.out, "summary.json") if os.path.isdir(args.out) else args.out)
    candidates = _candidates(args.effects)
    shared = _name_list(args.shared, "--shared")
    recordings, system, channels, free, x0 = {}, None, {}, [], {}
    for name, path in trial_files(args.data).items():  # every file read and checked before any work
        one = argparse.Namespace(**{**vars(args), "data": path, "validate": None})
        loaded, recordings[name], _, free, channels[name], x0 = model_and_recordings(one)
        system = system or loaded
    if len({tuple(c) for c in channels.values()}) > 1:
        raise InputDataError("the recordings fit different channels (" + "; ".join(f"{n}: {','.join(c)}" for n, c in
                             channels.items()) + "): name them with --outputs")
    res = diagnose_trials(system, recordings, shared=shared, free=free or None, outputs=next(iter(channels.values())),
                          candidates=candidates, x0=x0 or None, max_effects=args.max_effects, discover=args.discover,
                          out=args.out, resume=args.resume, scheduler=args.scheduler, n_jobs=args.jobs,
                          progress=wanted(args))
    files: dict[str, str | bytes] = {}
    if args.json is not None:
        files[args.json] = res.to_json()
    if args.plot is not None:
        from phs.workflows.diagnose.report import _png

        files[args.plot] = _png(res.plot())
    print(res.summary())
    _write_outputs(files)
    bad = [r for r in res.records if r.get("status") != "ok"]
    for r in bad:
        said = r.get("error") or "the nominal model cannot describe it (see its summary in --out)"
        print(f"phs diagnose: trial {r['trial']}: {said}", file=sys.stderr)
    return EXIT_REFUSED if bad else 0
