"""Input signals from the command line: CSV recordings, expressions and ``NAME=VALUE`` options.

Rows of a CSV file are numbered as in a spreadsheet: the header is row 1,
the first data row is row 2.  Every error names the file, the column and the
row.
"""

from __future__ import annotations

import csv
import math
import os
import re
import warnings
from collections.abc import Iterable, Sequence

import numpy as np

from phs.errors import InputDataError
from phs.signals import Sampled, Signal, parse_expression
from phs.workflows.between import check_law, header_annotations, hold_of, split_annotation
from phs.workflows.conversion import column_factor

_HEADER_UNIT = re.compile(r"(.*\S)\s*\[([^\[\]]+)\]")
_ASSIGN = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)\s*=(?!=)(.*)$", re.S)


def parse_assignments(items: Iterable[str] | None, option: str = "--param", numeric: bool = False) -> dict:
    """Parse ``NAME=VALUE`` strings (from ``--param``, ``--map``, ``--x0``) into a dict.

    Parameters
    ----------
    items : iterable of str
        The option's values, each ``NAME=VALUE``.
    option : str
        The option's name, used in error messages.
    numeric : bool
        Convert values to finite floats.

    Raises
    ------
    InputDataError
        Naming the option and the item: no ``=``, empty name or value, a name
        given twice, or a value that is not a finite number.

    Examples
    --------
    >>> parse_assignments(["R.R=2e3", "C.C = 1e-6"], numeric=True)
    {'R.R': 2000.0, 'C.C': 1e-06}
    >>> parse_assignments(["volts=U"], option="--map")
    {'volts': 'U'}
    >>> parse_assignments(["R.R"])
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: --param 'R.R': expected NAME=VALUE
    """
    out: dict = {}
    for item in items or ():
        name, sep, value = str(item).partition("=")
        name, value = name.strip(), value.strip()
        if not sep:
            raise InputDataError(f"{option} {item!r}: expected NAME=VALUE")
        if not name:
            raise InputDataError(f"{option} {item!r}: the name before '=' is empty")
        if not value:
            raise InputDataError(f"{option} {item!r}: the value after '=' is empty")
        if name in out:
            raise InputDataError(f"{option}: {name!r} is given twice")
        if numeric:
            try:
                number = float(value)
            except ValueError:
                raise InputDataError(f"{option} {name}: value {value!r} is not a number") from None
            if not math.isfinite(number):
                raise InputDataError(f"{option} {name}: value {value!r} is not finite")
            value = number
        out[name] = value
    return out


def read_input_csv(path, system, time_column: str = "t", mapping: dict | None = None,
                   skip: Iterable[str] = ()) -> tuple[np.ndarray, dict[str, Signal]]:
    """Read the inputs of ``system`` from a CSV file with a header row.

    Parameters
    ----------
    path : str or path-like
        CSV file: a header row of column names, then one row per sample.  A
        header cell ``name [unit]`` (as ``phs simulate --out`` writes them)
        names the column ``name``, and its values are converted from ``unit``
        to the model's unit of that input (``s`` for time; see
        :func:`phs.workflows.conversion.unit_factor`).  A column without a unit
        is taken as already in the model's unit.  Time stamps with jitter
        (within :data:`JITTER` of a step of a uniform grid) are replaced by
        that grid (:func:`uniform_grid`); otherwise the stamps are the
        input's knots, as they are.
    system : PHSystem
        The model whose inputs are read.
    time_column : str
        Name of the time column (strictly increasing, at least 2 rows).
    mapping : dict of str -> str, optional
        ``{COLUMN: SIGNAL}`` from ``--map``; an input not mapped is read from
        the column of its own name.  Entries naming a measured output are
        ignored here (they serve the fitting workflows).
    skip : iterable of str
        Inputs given another way (not read from the file).

    Returns
    -------
    t : ndarray
        Times of the rows.
    signals : dict of str -> Signal
        One signal per input: its declared law, or its samples held or interpolated as the header's annotation
        says (:mod:`phs.workflows.between`), else interpolated as a continuous signal.

    Raises
    ------
    InputDataError
        Naming the file, and the column and row where relevant: missing file,
        missing time or input column, a column whose stated unit cannot be
        converted to the model's (naming both units), a cell that is not a number, NaN or infinite values, time not
        strictly increasing, fewer than 2 rows.

    Examples
    --------
    >>> import os, tempfile
    >>> from systems.examples import rc_circuit
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = os.path.join(d, "u.csv")
    ...     _ = open(path, "w").write("t,volts\\n0,0\\n1,2\\n")
    ...     t, u = read_input_csv(path, rc_circuit(), mapping={"volts": "U"})
    >>> t.tolist(), float(u["U"](0.5))
    ([0.0, 1.0], 1.0)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = os.path.join(d, "u.csv")
    ...     _ = open(path, "w").write("t [ms],U [kV]\\n0,0\\n1000,2\\n")
    ...     t, u = read_input_csv(path, rc_circuit())
    >>> t.tolist(), float(u["U"](0.5))
    ([0.0, 1.0], 1000.0)
    """
    path = os.fspath(path)
    inputs = system.input_names
    mapping = dict(mapping or {})
    column_of: dict[str, str] = {}
    for column, signal in mapping.items():
        if signal in inputs:
            if signal in column_of:
                raise InputDataError(f"--map: input {signal!r} is mapped from two columns "
                                     f"({column_of[signal]!r} and {column!r})")
            column_of[signal] = column
        elif signal not in system.measured_names:
            known = ", ".join(inputs + system.measured_names) or "none"
            raise InputDataError(f"--map {column}={signal}: system {system.name!r} has no input or measured output "
                                 f"{signal!r} (known: {known})")
    skip = set(skip)
    wanted = {u: column_of.get(u, u) for u in inputs if u not in skip}

    raw_header, rows = _read_rows(path)
    header, file_units = _names_and_units(raw_header, path)
    missing = [c for c in [time_column, *wanted.values()] if c not in header]
    if missing:
        c = missing[0]
        what = "time column" if c == time_column else f"column for input {_input_of(wanted, c)!r}"
        raise InputDataError(f"{path}: no {what} {c!r} (columns: {', '.join(header)})")
    model_units = {time_column: ("s", "time"), **{wanted[i.name]: (i.unit, i.name) for i in system.inputs
                                                  if i.name in wanted}}
    factor = {c: column_factor(path, c, file_units[c], unit, signal) for c, (unit, signal) in model_units.items()
              if c in file_units}
    if len(rows) < 2:
        raise InputDataError(f"{path}: needs at least 2 data rows, found {len(rows)}")
    t = _column(path, header, rows, time_column) * factor.get(time_column, 1.0)
    check_time(t, path, 2, lambda k: f"row {rows[k][0]}", time_column)
    grid = uniform_grid(t)  # stamps with jitter: their uniform grid; irregular stamps are the input's knots
    t = t if grid is None else grid
    notes = header_annotations(raw_header, header)
    signals = {}
    for u, c in wanted.items():  # as the header says the input behaves between samples, else as its samples look
        v = _column(path, header, rows, c)
        hold = hold_of(notes.get(c, "linear"), path, c)
        if isinstance(hold, Signal):
            check_law(hold, notes[c], t, v, path, c, lambda k: f"row {rows[k][0]}")
            signals[u] = hold if factor.get(c, 1.0) == 1.0 else factor[c] * hold
        else:
            signals[u] = Sampled(tuple(t), tuple(v * factor.get(c, 1.0)), hold=hold)
    return t, signals


def check_time(t, source: str, min_samples: int, where, column: str = "t") -> None:
    """Raise InputDataError unless ``t`` has enough finite, strictly increasing samples.

    ``where(k)`` names sample ``k`` in messages (``"row 4"`` for a file, ``"sample 3"`` for arrays).

    Examples
    --------
    >>> check_time(np.array([0.0, 0.1, 0.1]), "u.csv", 2, lambda k: f"row {k + 2}")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: u.csv: time column 't' is not strictly increasing at row 4 (t=0.1 after t=0.1: duplicated time)
    """
    if t.size < min_samples:
        raise InputDataError(f"{source}: needs at least {min_samples} samples, found {t.size}")
    bad = ~np.isfinite(t)
    if np.any(bad):
        raise InputDataError(f"{source}: time column {column!r} is not finite at {where(int(np.argmax(bad)))}")
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0)) + 1
        kind = "duplicated" if d[k - 1] == 0 else "decreasing"
        raise InputDataError(f"{source}: time column {column!r} is not strictly increasing at {where(k)} "
                             f"(t={t[k]:g} after t={t[k - 1]:g}: {kind} time)")


JITTER = 0.01
"""Largest distance, as a share of the step, of a time stamp from the least-squares uniform grid through the
stamps for them to count as uniformly sampled (:func:`uniform_grid`).

Why 1 %: a DAQ clock's jitter is far smaller (the EMPS recordings: 3e-5 of a step), while a real
irregularity is far larger (a missing sample moves the stamps after it by a whole step from the grid
through the others: 100 times the tolerance); and carrying a sample 1 % of a step away from its stamp
changes its value by at most 1 % of the signal's change over one step, less than linear interpolation
between samples, which every simulation of a recording already assumes, leaves out for any signal whose
slope changes by more than 8 % within a step."""


def uniform_grid(t: np.ndarray) -> np.ndarray | None:
    """The uniform grid ``t[0] + k*dt`` carried instead of time stamps with jitter, or None if ``t`` is not uniform.

    ``dt`` is the slope of the least-squares line through the stamps ``(k, t[k])``; the stamps count as
    uniform when each lies within :data:`JITTER` (1 %) of a step from that line.  The grid keeps the
    first stamp (time need not start at zero); stamps that already form a uniform grid to rounding
    (within 1e-9 of a step) are returned as they are.

    Parameters
    ----------
    t : array
        Finite, strictly increasing time stamps (see :func:`check_time`).

    Returns
    -------
    ndarray or None

    Examples
    --------
    >>> grid = uniform_grid(np.array([10.0, 10.00100003, 10.00199998, 10.003]))     # jitter: 3e-5 of a step
    >>> float(grid[0]), round(float(grid[1] - grid[0]), 6), bool(np.ptp(np.diff(grid)) < 1e-12)
    (10.0, 0.001, True)
    >>> uniform_grid(np.array([0.0, 0.001, 0.003, 0.004])) is None      # a missing sample
    True
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    if n < 3:
        return t
    k = np.arange(n, dtype=float)
    s = t - t[0]  # from the first stamp: no cancellation when time starts far from zero
    kc = k - k.mean()
    dt = float(kc @ (s - s.mean()) / (kc @ kc))
    off = s - dt * k
    if not dt > 0 or np.max(np.abs(off - off.mean())) > JITTER * dt:  # the least-squares line misses a stamp by more
        return None
    if np.max(np.abs(off)) <= 1e-9 * dt:
        return t
    return t[0] + dt * k


def check_uniform(t: np.ndarray, source: str, where, column: str = "t", advice: str = "") -> np.ndarray:
    """The uniform grid of :func:`uniform_grid`, or an InputDataError naming where the sampling is irregular.

    The row named is that of the step farthest from the median step (a missing sample, a burst), or, when
    no step stands out (a clock drifting), the stamp farthest from the grid.  ``where(k)`` names sample ``k``
    (``"row 5"``); ``advice`` ends the message.

    Examples
    --------
    >>> check_uniform(np.array([0.0, 0.001, 0.002, 0.004, 0.005]), "r.csv", lambda k: f"row {k + 2}")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: r.csv: irregular sampling at row 5 of time column 't': step 0.002 s (t=0.004 after t=0.002) ...
    """
    grid = uniform_grid(t)
    if grid is not None:
        return grid
    d = np.diff(t)
    med = float(np.median(d))
    dev = np.abs(d - med)
    k = int(np.argmax(dev)) + 1
    if dev[k - 1] > 2 * JITTER * med:
        what = f"step {d[k - 1]:g} s (t={t[k]:g} after t={t[k - 1]:g}) where the others are {med:g} s"
    else:  # every step is close to the median: the stamps drift away from a uniform grid
        n = np.arange(t.size)
        off = (t - t[0]) - n * (t[-1] - t[0]) / (t.size - 1)
        k = int(np.argmax(np.abs(off)))
        what = f"t={t[k]:g} lies {abs(off[k]) / med:.2g} steps off the uniform grid from t={t[0]:g} to t={t[-1]:g}"
    tol = f"{100 * JITTER:g} %"
    raise InputDataError(f"{source}: irregular sampling at {where(k)} of time column {column!r}: {what} "
                         f"(time stamps may leave a uniform grid by at most {tol} of a step){advice}")


def _input_of(wanted: dict, column: str) -> str:
    return next(u for u, c in wanted.items() if c == column)


class _Table:
    """The data rows of a CSV file read as numbers in one pass (:func:`_read_rows`): ``table[k][0]`` is row
    ``k``'s spreadsheet row number, :func:`_column` takes a column out as a float array."""

    def __init__(self, data: np.ndarray, first_line: int):
        self.data, self.first_line = data, first_line

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, k: int) -> tuple[int, None]:
        return (self.first_line + range(len(self.data))[k], None)


def _fast_rows(path: str):
    """Header and :class:`_Table` of a CSV file whose data rows are all numbers, finite, of the header's width
    and without blank lines between them, read by numpy's C parser (10⁶ rows of 3 columns, 33 MB, read into
    columns in 0.8 s and 49 MB of peak memory where the cell-by-cell reading takes 7.8 s and 399 MB); None for
    any other file (or one that cannot be read), which :func:`_read_rows` then reads cell by cell and names its
    row and column in errors."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = next((c for c in reader if c and any(x.strip() for x in c)), None)
            if header is None:
                return None
            first = reader.line_num + 1
            header = [c.strip() for c in header]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # an empty body: refused below (too few rows) as the slow path does
                data = np.loadtxt(fh, delimiter=",", dtype=float, comments=None, quotechar='"', ndmin=2)
        with open(path, "rb") as fb:
            newlines = sum(chunk.count(b"\n") for chunk in iter(lambda: fb.read(1 << 22), b""))
            fb.seek(-1, os.SEEK_END)
            unterminated = fb.read(1) != b"\n"
    except (OSError, UnicodeDecodeError, csv.Error, ValueError):
        return None
    # every line after the header a data row (no blank line: the row numbers are counted), every cell finite
    if (data.shape[1] != len(header) or newlines + unterminated - (first - 1) != len(data)
            or len(set(header)) != len(header) or not np.all(np.isfinite(data))):
        return None
    return header, _Table(data, first)


def _read_rows(path: str) -> tuple[list[str], list[tuple[int, list[str]]] | _Table]:
    """Header and the data rows as ``(spreadsheet row number, cells)``; blank lines are skipped.  A file of
    finite numbers only is read by numpy in one pass (:func:`_fast_rows`: a :class:`_Table`)."""
    fast = _fast_rows(path) if os.path.isfile(path) else None
    if fast is not None:
        return fast
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = None
            rows = []
            for cells in reader:
                if not cells or all(not c.strip() for c in cells):
                    continue
                if header is None:
                    header = [c.strip() for c in cells]
                    dup = sorted({c for c in header if header.count(c) > 1})
                    if dup:
                        raise InputDataError(f"{path}: column {dup[0]!r} appears twice in the header")
                    continue
                if len(cells) != len(header):
                    raise InputDataError(f"{path}: row {reader.line_num} has {len(cells)} cells but the header "
                                         f"has {len(header)} columns")
                rows.append((reader.line_num, cells))
    except FileNotFoundError:
        raise InputDataError(f"input file {path!r} does not exist") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputDataError(f"cannot read input file {path!r}: {exc}") from None
    if header is None:
        raise InputDataError(f"{path}: the file is empty (expected a header row naming the columns)")
    return header, rows


def _names_and_units(header: list[str], path: str) -> tuple[list[str], dict[str, str]]:
    """Column names without a trailing `` [unit]`` (as ``phs simulate`` writes them), and those units.

    Examples
    --------
    >>> _names_and_units(["t [s]", "C.Q [C]", "volts", "U [kV] {zoh}"], "r.csv")
    (['t', 'C.Q', 'volts', 'U'], {'t': 's', 'C.Q': 'C', 'U': 'kV'})
    """
    names, units = [], {}
    for cell in header:
        cell = split_annotation(cell)[0]  # how the column behaves between samples: phs.workflows.between
        m = _HEADER_UNIT.fullmatch(cell)
        name = m.group(1).strip() if m else cell
        if m:
            units[name] = m.group(2).strip()
        if name in names:
            raise InputDataError(f"{path}: column {name!r} appears twice in the header")
        names.append(name)
    return names, units


def _column(path: str, header: Sequence[str], rows, name: str) -> np.ndarray:
    j = header.index(name)
    if isinstance(rows, _Table):
        return rows.data[:, j].copy()
    out = np.empty(len(rows))
    for k, (line, cells) in enumerate(rows):
        cell = cells[j].strip()
        try:
            v = float(cell)
        except ValueError:
            what = "is empty" if not cell else f"{cell!r} is not a number"
            raise InputDataError(f"{path}: row {line}, column {name!r}: {what}") from None
        if not math.isfinite(v):
            raise InputDataError(f"{path}: row {line}, column {name!r}: value {cell!r} is not finite")
        out[k] = v
    return out


def input_signals(system, specs: Iterable[str] | None, time_column: str = "t", mapping: dict | None = None,
                  span: tuple[float, float] | None = None) -> dict[str, Signal]:
    """Input signals from ``--input`` values: a CSV file, ``NAME=EXPR`` or a bare ``EXPR``.

    A bare expression is allowed when the system has exactly one input.
    Inputs given neither way are left out (the simulator makes them zero).

    Parameters
    ----------
    system : PHSystem
        The model whose inputs are given.
    specs : iterable of str
        The ``--input`` values.
    time_column, mapping
        As for :func:`read_input_csv`.
    span : (float, float), optional
        Simulated time interval, which a CSV file must cover.

    Returns
    -------
    dict of str -> Signal

    Raises
    ------
    InputDataError
        Naming the value: unknown input, an input given twice, a bare
        expression for a system with several inputs, an unreadable
        expression or CSV file, a CSV file not covering ``span``.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> sig = input_signals(rc_circuit(), ["U=step(2.0)"])
    >>> float(sig["U"](1.0))
    2.0
    """
    names = system.input_names
    signals: dict[str, Signal] = {}
    csv_files = []
    for spec in specs or ():
        spec = str(spec).strip()
        if spec.lower().endswith(".csv"):
            csv_files.append(spec)
            continue
        m = _ASSIGN.match(spec)
        if m:
            name, text = m.group(1), m.group(2).strip()
            if name not in names:
                raise InputDataError(f"--input {spec!r}: system {system.name!r} has no input {name!r} "
                                     f"(inputs: {', '.join(names) or 'none'})")
        elif len(names) == 1:
            name, text = names[0], spec
        else:
            raise InputDataError(f"--input {spec!r}: write NAME=EXPR; system {system.name!r} has "
                                 f"{len(names)} inputs ({', '.join(names) or 'none'})")
        if name in signals:
            raise InputDataError(f"--input: input {name!r} is given twice")
        if not text:
            raise InputDataError(f"--input {spec!r}: the expression is empty")
        try:
            signals[name] = parse_expression(text)
        except InputDataError as exc:
            raise InputDataError(f"--input {name}: {exc}") from None
    if mapping and not csv_files:
        raise InputDataError("--map needs an input CSV file (--input FILE.csv)")
    if len(csv_files) > 1:
        raise InputDataError(f"--input: give at most one CSV file (got {', '.join(csv_files)})")
    if csv_files:
        path = csv_files[0]
        t, read = read_input_csv(path, system, time_column, mapping, skip=signals)
        if span is not None:
            tol = 1e-9 * max(abs(span[1] - span[0]), 1e-300)  # and the jitter a uniform grid forgives at either end
            if t[0] > span[0] + tol + JITTER * (t[1] - t[0]) or t[-1] < span[1] - tol - JITTER * (t[-1] - t[-2]):
                raise InputDataError(f"{path}: column {time_column!r} covers t = {t[0]:g} .. {t[-1]:g} but the "
                                     f"simulation runs over {span[0]:g} .. {span[1]:g}")
        signals.update(read)
    return signals


def between_notes(system, specs, signals: dict) -> dict:
    """How each input of a run behaved between the samples, as ``phs simulate --out`` writes it in the header
    (:mod:`phs.workflows.between`): the text of an input given as an expression (its law), ``zoh`` or ``linear``
    for one read from samples; an input read as a law from a file, or not given, gets no note.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> specs = ["U=square(1.0, 50)"]
    >>> between_notes(rc_circuit(), specs, input_signals(rc_circuit(), specs))
    {'U': 'square(1.0, 50)'}
    """
    notes = {}
    names = system.input_names
    for spec in specs or ():
        spec = str(spec).strip()
        if spec.lower().endswith(".csv"):
            continue
        m = _ASSIGN.match(spec)
        name, text = (m.group(1), m.group(2).strip()) if m else (names[0], spec)
        notes[name] = text
    for name, sig in signals.items():
        if name not in notes and isinstance(sig, Sampled):
            notes[name] = sig.hold
    return notes
