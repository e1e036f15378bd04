"""Large outputs of the ``phs`` command line: their size said before the work, and written with a progress bar.

A CSV of ``phs simulate --out`` holds one row per output time and one column per signal, each number
written with 17 significant digits (``%.17g``, so a file replays its run exactly): about
:data:`BYTES_PER_CELL` bytes a cell.  :func:`csv_size_estimate` says what a grid will write before the
simulation starts, and :func:`size_warning` words a warning above :data:`LARGE_OUTPUT` bytes;
:func:`write_csv` writes the table in blocks of rows, the same bytes as
:meth:`codegen.results.SimulationResult.to_csv`, advancing a progress bar.

Examples
--------
>>> csv_size_estimate(10_000_001, 8)  # phs simulate --t-end 1000 --dt 1e-4 of an RC circuit: 8 columns
1600000160
>>> size_warning("--out", "huge.csv", 10_000_001, 8)
'--out huge.csv will hold 10000001 rows x 8 columns, about 1.6 GB; a coarser --dt or a shorter --t-end writes less'
"""

from __future__ import annotations

import csv

import numpy as np

#: Bytes a CSV cell takes on average with its separator: a ``%.17g`` number is 17 digits, a point, often a
#: sign and an exponent (``-9.5162581651312438e-08,`` is 23), a whole number far fewer.  Measured: 19.4 for the
#: RC circuit under a square wave, 17.6 for normally distributed signals (tests/workflows/test_cli_output.py).
BYTES_PER_CELL = 20.0

#: Outputs estimated above this many bytes get a warning before the work starts.
LARGE_OUTPUT = 200e6

_ROWS_PER_BLOCK = 20_000


def table_columns(system) -> int:
    """Columns of a simulation's table: time, states, inputs, port outputs, measured outputs, H, dissipated and
    supplied power (as :meth:`codegen.results.SimulationResult.table`).

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> table_columns(rc_circuit())
    8
    """
    return 1 + len(system.states) + len(system.inputs) + len(system.output_names) + len(system.measured_names) + 3


def csv_size_estimate(rows: int, columns: int) -> int:
    """Bytes of a CSV table of ``rows`` by ``columns`` numbers (:data:`BYTES_PER_CELL` a cell, the header left
    out): within a factor 1.5 of the file for tables of general numbers; a table of mostly zeros or whole
    numbers is smaller.

    Examples
    --------
    >>> csv_size_estimate(1000, 5)
    100000
    """
    return int(round(rows * columns * BYTES_PER_CELL))


def _human(n: float) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} bytes"


def size_warning(option: str, path: str, rows: int, columns: int, limit: float | None = None) -> str | None:
    """The warning for an output estimated above ``limit`` bytes (default :data:`LARGE_OUTPUT`;
    :func:`csv_size_estimate`), or None.

    Examples
    --------
    >>> size_warning("--out", "r.csv", 1001, 8) is None
    True
    """
    size = csv_size_estimate(rows, columns)
    if size <= (LARGE_OUTPUT if limit is None else limit):
        return None
    return (f"{option} {path} will hold {rows} rows x {columns} columns, about {_human(size)}; a coarser --dt or a "
            "shorter --t-end writes less")


def write_csv(path: str, header: list[str], data: np.ndarray, bar=None) -> None:
    """Write ``header`` and the rows of ``data`` (``%.17g``, as :func:`codegen.results.write_csv_atomic`) to
    ``path`` in blocks of rows, advancing ``bar`` (:class:`phs.workflows.terminal.Bar`) by the rows written.

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_csv(os.path.join(d, "r.csv"), ["t [s]", "U [V] {square(1, 5)}"], np.array([[0.0, 1.0], [0.1, -1.0]]))
    ...     print(open(os.path.join(d, "r.csv")).read(), end="")
    t [s],"U [V] {square(1, 5)}"
    0,1
    0.10000000000000001,-1
    """
    data = np.asarray(data, dtype=float)
    row = ",".join(["%.17g"] * data.shape[1]) + "\n"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        csv.writer(fh, lineterminator="\n").writerow(header)  # a cell with a comma (a law in braces) is quoted
        for k in range(0, len(data), _ROWS_PER_BLOCK):
            block = data[k:k + _ROWS_PER_BLOCK]
            fh.write((row * len(block)) % tuple(block.ravel().tolist()))
            if bar is not None:
                bar.update(len(block))
