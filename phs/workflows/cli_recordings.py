"""The model and the recordings of the subcommands that fit a model to a recording (``fit``, ``diagnose``)."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from phs.errors import InputDataError
from phs.workflows.between import HOLD_WORDS
from phs.workflows.cli_options import _name_list
from phs.workflows.cli_vocabulary import add_option
from phs.workflows.inputs import _ASSIGN, _names_and_units, input_signals, parse_assignments
from phs.workflows.loader import load_model

if TYPE_CHECKING:
    from phs.signals import Signal
    from phs.system import PHSystem
    from phs.workflows.recording import Recording

_INPUT_DETAIL = ("here the inputs come from the recordings, and only NAME=EXPR is taken: it fills an input a "
                 "recording lacks (every recording, DATA and DATA2, without a column for NAME reads EXPR as a function "
                 "of its time, as that law); a recording with the column keeps its recorded signal")


def add_recording_options(p: argparse.ArgumentParser) -> None:
    """Options of the subcommands that fit a model to a recording (``fit``, ``diagnose``)."""
    for name in ("--x0", "--scale", "--resample", "--outputs", "--validate", "--hold", "--strict-ranges"):
        add_option(p, name)
    add_option(p, "--input", detail=_INPUT_DETAIL)


def missing_input_laws(system, items) -> dict[str, Signal]:
    """The laws of ``--input NAME=EXPR`` values of ``phs fit`` and ``phs diagnose``: inputs that a recording
    without a column for them reads as these laws (:func:`fill_inputs`).  The expressions are read as by
    ``phs simulate --input`` (:func:`phs.workflows.inputs.input_signals`, the whitelist parser).

    Raises
    ------
    InputDataError
        Naming the option: a CSV file or a bare expression (only ``NAME=EXPR`` says which input a recording
        lacks), a name that is not an input of the model (naming the inputs), an input given twice, an
        expression that cannot be read.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> law = missing_input_laws(mass_spring_damper(), ["F=square(1.0, 50)"])["F"]
    >>> float(law(0.001)), float(law(0.011))
    (1.0, -1.0)
    >>> missing_input_laws(mass_spring_damper(), ["G=0"])
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --input 'G=0': system 'msd' has no input 'G' (inputs: F)
    >>> missing_input_laws(mass_spring_damper(), ["u.csv"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --input 'u.csv': a CSV file of inputs is for phs simulate; ...
    """
    for item in items or ():
        spec = str(item).strip()
        if spec.lower().endswith(".csv"):
            raise InputDataError(f"--input {spec!r}: a CSV file of inputs is for phs simulate; here the inputs come "
                                 "from the recordings, and --input NAME=EXPR fills an input a recording has no column for")
        if not _ASSIGN.match(spec):
            raise InputDataError(f"--input {spec!r}: write NAME=EXPR, naming the input a recording lacks (inputs of "
                                 f"{system.name!r}: {', '.join(system.input_names) or 'none'})")
    return input_signals(system, items)


def fill_inputs(rec: Recording, system, laws: dict) -> Recording:
    """``rec`` with every input of ``laws`` that it has no signal for: the law's values on the recording's own
    time grid as the samples, and the law itself as how the input behaves between them (:attr:`Recording.holds`:
    a simulation replays the law, edges between the samples included), in the model's unit.  An input the
    recording has keeps its recorded signal.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.signals import parse_expression
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import mass_spring_damper
    >>> rec = Recording.from_arrays(np.arange(5) * 0.01, {"position": np.zeros(5)}, source="r.csv")
    >>> full = fill_inputs(rec, mass_spring_damper(), {"F": parse_expression("step(2.0, 0.015)")})
    >>> full["F"].tolist(), float(full.input_signal("F")(0.016)), full.units, full.source
    ([0.0, 0.0, 2.0, 2.0, 2.0], 2.0, {'F': 'N'}, 'r.csv')
    """
    from dataclasses import replace

    import numpy as np

    missing = {name: law for name, law in laws.items() if name not in rec.signals}
    if not missing:
        return rec
    unit = {u.name: u.unit for u in system.inputs}
    signals = dict(rec.signals)
    units = dict(rec.units)
    for name, law in missing.items():
        signals[name] = np.broadcast_to(np.asarray(law(rec.t), dtype=float), rec.t.shape).copy()
        if unit.get(name):
            units[name] = unit[name]
    return replace(rec, signals=signals, units=units).with_holds(missing)


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
    phs.errors.InputDataError: --scale pos=mm:V: cannot convert 'mm' to 'V': different dimensions (m and kg*m**2/(s**3*A))
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
    """Column names of a CSV file (without a trailing `` [unit]``, as ``phs simulate --out`` writes them),
    or None when it cannot be read (the recording reader then says why)."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for cells in csv.reader(fh):
                if cells and any(c.strip() for c in cells):
                    return _names_and_units([c.strip() for c in cells], path)[0]
    except (OSError, UnicodeDecodeError, csv.Error, InputDataError):
        return None
    return None


def _default_outputs(system, present) -> list[str]:
    """The channels fitted without ``--outputs``: the measured outputs among the signals ``present``; only when
    there is none, the port outputs and states among them (a file of ``phs simulate --out`` carries all three,
    and a measured output that is a state would otherwise count twice).

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> _default_outputs(mass_spring_damper(), ["F", "k.l", "m.p", "F.v", "position"])
    ['position']
    >>> _default_outputs(mass_spring_damper(), ["F", "k.l"])
    ['k.l']
    """
    measured = [m for m in system.measured_names if m in present]
    if measured:
        return measured
    return [m for m in system.output_names + system.state_names if m in present]


def _read_recording(path: str, system, args, mapping: dict, scales: dict, outputs: list[str], laws: dict):
    """Read the columns of ``path`` that the fit needs (inputs and fitted outputs) as a Recording; the inputs
    of ``laws`` (``--input``) that the file has no column for are filled from their laws (:func:`fill_inputs`)."""
    from phs.workflows.recording import Recording

    column_of = {sig: col for col, sig in mapping.items()}
    header = _csv_header(path)
    columns = None
    if header is not None:
        if outputs:
            wanted = system.input_names + outputs
        else:
            present = [mapping.get(c, c) for c in header if c != args.time]
            wanted = system.input_names + _default_outputs(system, present)
        columns = list(dict.fromkeys(column_of.get(sig, sig) for sig in wanted))
        absent = {column_of.get(u, u) for u in laws if column_of.get(u, u) not in header}
        columns = [c for c in columns if c not in absent]
        columns += [c for c in scales if c in header and c not in columns and c != args.time]
    holds = {}
    for column, reading in parse_assignments(getattr(args, "hold", None), "--hold").items():
        if header is not None and column not in header:
            if mapping.get(column, column) in laws:  # filled from --input here: read as its law
                continue
            raise InputDataError(f"--hold {column}={reading}: {path} has no column {column!r} (columns: {', '.join(header)})")
        if reading.strip().lower() not in HOLD_WORDS:
            raise InputDataError(f"--hold {column}={reading}: say zoh (held between samples) or linear (a continuous "
                                 "signal); a law goes in the column's header, as phs simulate --out writes it")
        holds[mapping.get(column, column)] = reading
    try:
        rec = Recording.from_csv(path, time_column=args.time, mapping=mapping, scales=scales,
                                 resample=args.resample, columns=columns, holds=holds)
    except InputDataError as exc:  # say it with the command line's option names
        raise InputDataError(str(exc).replace("pass resample=DT", "pass --resample DT")) from None
    return fill_inputs(rec, system, laws)


def model_and_recordings(args: argparse.Namespace) -> tuple[PHSystem, Recording, Recording | None, list[str], list[str], dict]:
    """Load the model and the recordings of a fitting subcommand (``fit``, ``diagnose``), checking every
    name given on the command line first, with every signal in the model's units (a header ``U [kV]``
    converted, ``--scale`` first) and the inputs a recording lacks filled from ``--input NAME=EXPR``.
    Returns ``(system, recording, validation or None, free, fitted outputs, x0)``."""
    params = parse_assignments(args.param, "--param", numeric=True)
    x0 = parse_assignments(args.x0, "--x0", numeric=True)
    mapping = parse_assignments(args.map, "--map")
    scales = parse_scales(args.scale)
    free = _name_list(args.free, "--free")
    outputs = _name_list(args.outputs, "--outputs")
    system = load_model(args.model, params)
    laws = missing_input_laws(system, getattr(args, "input", None))
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
    rec = _read_recording(args.data, system, args, mapping, scales, outputs, laws).in_units_of(system)
    _, fitted_outputs = rec.check_for(system, outputs or _default_outputs(system, list(rec.signals)) or None)
    val = None
    if args.validate is not None:
        val = _read_recording(args.validate, system, args, mapping, scales, fitted_outputs, laws).in_units_of(system)
        val.check_for(system, fitted_outputs)
    for r in (rec, val):
        if r is not None:
            say_input_ranges(system, r, getattr(args, "strict_ranges", False))
    return system, rec, val, free, fitted_outputs, x0


def say_input_ranges(system, rec, strict: bool = False) -> list[str]:
    """Say once, on stderr, which recorded inputs of ``rec`` lie outside their declared ranges
    (:mod:`phs.workflows.ranges`); with ``strict`` (``--strict-ranges``) refuse the first.  Returns the sentences.

    Raises
    ------
    InputDataError
        With ``strict``, naming the recording, the input, the value reached and the range.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.recording import Recording
    >>> from systems.msd_hasel import msd_hasel
    >>> rec = Recording.from_arrays(np.arange(3) * 0.01, {"V": np.array([0.0, 3e4, 3e4]), "F_load": np.zeros(3),
    ...                                                   "displacement": np.zeros(3)}, source="r.csv")
    >>> say_input_ranges(msd_hasel(), rec, strict=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: r.csv: input 'V' of 'msd_hasel' reaches 30000 V, outside its declared range 0 to 6000 V ...
    """
    import sys

    from phs.workflows.ranges import input_report, range_messages

    report = input_report(system, rec.t, {u: rec[u] for u in system.input_names if u in rec.signals})
    found = [f"{rec.source}: {m}" for m in range_messages({"inputs": report}, system.name)]
    if found and strict:
        raise InputDataError(found[0] + " (--strict-ranges)")
    if found:
        print("phs: warning: " + "; ".join(found) + " (--strict-ranges makes this an error)", file=sys.stderr, flush=True)
    return found
