"""Results of a study on disk: one row per run, written as runs finish, resumable.

The output is a Parquet file (``.parquet``, through pyarrow) or a CSV file
(``.csv``) with the columns ``run``, the study's variables, the metrics'
columns, ``status`` (``ok`` or ``failed``) and ``error`` (the failure's
message, empty for a run that succeeded).

While a study runs, every finished chunk of runs is written at once to its own
part file in the directory ``OUT.parts`` (each written atomically: a part is
either complete or absent), and ``OUT`` itself is rewritten from everything
finished so far every few seconds and at the end, when the part directory is
removed.  ``OUT`` is written atomically into the part directory first
(``OUT.parts/results.EXT``) and renamed onto ``OUT``: every temporary file of
a study lives in its part directory, so that resuming can remove what a kill
left behind (``.tmp-*`` files of an unfinished atomic write, a staged results
file) without touching anything else in ``OUT``'s directory.

A study killed at any moment has lost at most the chunks that were still
running or whose part was not yet renamed into place; the dangerous moments
(after a part's data reached the disk, before and after the rename of a part,
before and after the rename of the results file) are each tested by a kill.
Resuming reads ``OUT`` and the parts, checks that they belong to the same study
(the identity stored with them: model, parameters, inputs, time grid, initial state, tolerances,
metrics and design, in the Parquet files' metadata or, for CSV, in ``OUT.study.json`` written
before the first part; then the variables and metric columns and the variable values of each run),
removes the leftover temporary files and runs only what is missing.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import shutil
import time as _time
import uuid

import numpy as np

from phs.errors import InputDataError
from phs.io import write_atomic

FORMATS = (".parquet", ".csv")


def results_format(path) -> str:
    """``"parquet"`` or ``"csv"`` from the file name's suffix.

    Raises
    ------
    InputDataError
        For another suffix.

    Examples
    --------
    >>> results_format("study.parquet"), results_format("study.CSV")
    ('parquet', 'csv')
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in FORMATS:
        raise InputDataError(f"results file {os.fspath(path)!r}: use a .parquet or .csv name")
    return ext[1:]


def _pyarrow():
    """``(pyarrow, pyarrow.parquet)``, or an error saying how to do without."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputDataError("Parquet files need pyarrow (pip install pyarrow); or use a .csv file") from None
    return pa, pq


def _is_part(name: str, fmt: str) -> bool:
    """Whether a file name in a part directory is a part (``part-<time>-<random>.<fmt>``)."""
    return name.startswith("part-") and name.endswith("." + fmt)


def _columns_of(numeric: list[str]) -> list[str]:
    return ["run", *numeric, "status", "error"]


# -- encoding ------------------------------------------------------------------------------------------
def encode(rows: list[dict], numeric: list[str], fmt: str, metadata: dict | None = None) -> bytes:
    """Rows (dicts) as the bytes of a Parquet or CSV file with the given numeric columns.

    Examples
    --------
    >>> rows = [{"run": 0, "k": 1.5, "status": "ok", "error": ""}]
    >>> decode(encode(rows, ["k"], "csv"), "csv", "<doc>")[0]
    {'run': 0, 'k': 1.5, 'status': 'ok', 'error': ''}
    """
    cols = _columns_of(numeric)
    if fmt == "parquet":
        pa, pq = _pyarrow()
        arrays = {"run": pa.array([int(r["run"]) for r in rows], type=pa.int64())}
        for c in numeric:
            arrays[c] = pa.array([float(r[c]) for r in rows], type=pa.float64())
        arrays["status"] = pa.array([str(r["status"]) for r in rows], type=pa.string())
        arrays["error"] = pa.array([str(r["error"]) for r in rows], type=pa.string())
        table = pa.table(arrays)
        if metadata:
            table = table.replace_schema_metadata({"phs_study": json.dumps(metadata)})
        sink = pa.BufferOutputStream()
        pq.write_table(table, sink)
        return sink.getvalue().to_pybytes()
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([int(r["run"])] + [repr(float(r[c])) for c in numeric] + [r["status"], r["error"]])
    return buf.getvalue().encode("utf-8")


def decode(data: bytes, fmt: str, source: str) -> list[dict]:
    """Rows of a results file (see :func:`encode`).

    Raises
    ------
    InputDataError
        Naming ``source`` (and the row, for CSV) when the content cannot be read.

    Examples
    --------
    >>> decode(b"run,k,status,error\\n3,nan,failed,boom\\n", "csv", "<doc>")[0]["error"]
    'boom'
    """
    if fmt == "parquet":
        pa, pq = _pyarrow()
        try:  # no pre-buffering and no threads: Arrow's thread pools can abort the interpreter at exit
            table = pq.ParquetFile(pa.BufferReader(data), pre_buffer=False).read(use_threads=False)
        except Exception as exc:  # noqa: BLE001 - any unreadable file is reported with its name
            raise InputDataError(f"{source}: not a readable Parquet file ({exc})") from None
        cols = table.to_pydict()
        names = list(cols)
        n = table.num_rows
        return [{c: cols[c][i] for c in names} for i in range(n)]
    text = data.decode("utf-8")
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise InputDataError(f"{source}: empty results file") from None
    for required in ("run", "status", "error"):
        if required not in header:
            raise InputDataError(f"{source}: no column {required!r} (not a study's results file)")
    rows = []
    for line, cells in enumerate(reader, start=2):
        if not cells:
            continue
        if len(cells) != len(header):
            raise InputDataError(f"{source}: row {line} has {len(cells)} cells, the header {len(header)}")
        row = {}
        for c, v in zip(header, cells):
            if c in ("status", "error"):
                row[c] = v
                continue
            try:
                row[c] = int(v) if c == "run" else float(v)
            except ValueError:
                raise InputDataError(f"{source}: row {line}, column {c!r}: {v!r} is not a number") from None
        rows.append(row)
    return rows


def read_rows(path) -> tuple[list[dict], dict]:
    """Rows and study metadata (Parquet only; ``{}`` for CSV) of a results file.

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = os.path.join(d, "r.csv")
    ...     write_atomic(p, encode([{"run": 1, "k": 2.0, "status": "ok", "error": ""}], ["k"], "csv"))
    ...     read_rows(p)[0][0]["k"]
    2.0
    """
    fmt = results_format(path)
    with open(path, "rb") as fh:
        data = fh.read()
    meta = {}
    if fmt == "parquet":
        pa, pq = _pyarrow()
        try:
            md = pq.ParquetFile(pa.BufferReader(data), pre_buffer=False).schema_arrow.metadata or {}
        except Exception:  # noqa: BLE001 - decode() reports unreadable files
            md = {}
        if b"phs_study" in md:
            meta = json.loads(md[b"phs_study"])
    return decode(data, fmt, os.fspath(path)), meta


# -- the store of a running study ------------------------------------------------------------------------
class ResultStore:
    """Rows of a study, persisted incrementally (see the module docstring).

    Parameters
    ----------
    path : str or None
        Results file (``.parquet`` or ``.csv``); ``None`` keeps the rows in memory only.
    numeric : list of str
        The variable and metric columns, in order.
    design : callable
        ``design(run) -> dict`` of the study's variable values of a run number (or None when out of range).
    variables : list of str
        The variable columns (checked against ``design`` on resume).
    resume : bool
        Continue a study whose results (or parts) exist; without it an existing file is an error.
    retry_failed : bool
        On resume, forget failed runs so they run again.
    metadata : dict
        Written into Parquet files, and for CSV into ``OUT.study.json`` beside it (model, variables,
        metrics, seed; under ``"identity"``, :meth:`Study.identity
        <phs.workflows.sweep.study.Study.identity>`, compared on resume: another study is refused,
        naming what differs).
    flush_seconds : float
        How often ``path`` is rewritten from the finished rows (0: after every part).

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = os.path.join(d, "s.csv")
    ...     store = ResultStore(path, ["k", "peak"], design=lambda r: {"k": float(r)}, variables=["k"])
    ...     store.add([{"run": 0, "k": 0.0, "peak": 1.0, "status": "ok", "error": ""}])
    ...     store.close()
    ...     sorted(ResultStore(path, ["k", "peak"], lambda r: {"k": float(r)}, ["k"], resume=True).done)
    [0]
    """

    def __init__(self, path, numeric: list[str], design, variables: list[str], resume: bool = False,
                 retry_failed: bool = False, metadata: dict | None = None, flush_seconds: float = 5.0):
        self.path = os.fspath(path) if path is not None else None
        self.numeric = list(numeric)
        self.variables = list(variables)
        self.design = design
        self.metadata = dict(metadata or {})
        self.flush_seconds = float(flush_seconds)
        self.rows: dict[int, dict] = {}
        self._last_flush = _time.monotonic()
        self._flush_cost = 0.0
        self._dirty = False
        if self.path is None:
            return
        self.fmt = results_format(self.path)
        if self.fmt == "parquet":
            _pyarrow()
        d = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(d):
            raise InputDataError(f"cannot write {self.path!r}: directory {d!r} does not exist")
        self.parts = self.path + ".parts"
        self.sidecar = self.path + ".study.json"  # the study a CSV file holds (Parquet files carry it inside)
        self._described = False
        existing = os.path.exists(self.path) or os.path.isdir(self.parts)
        if existing and not resume:
            raise InputDataError(f"{self.path!r} already holds results (or the parts of an interrupted study): "
                                 "resume it (resume=True, --resume) or choose another output file")
        if existing:
            self._load(retry_failed)

    # -- resume ----------------------------------------------------------------------------------------
    def _load(self, retry_failed: bool) -> None:
        sources = []
        if os.path.exists(self.path):
            sources.append(self.path)
        if os.path.isdir(self.parts):
            sources += sorted(os.path.join(self.parts, f) for f in os.listdir(self.parts) if _is_part(f, self.fmt))
        want = _columns_of(self.numeric)
        if self.fmt == "csv" and os.path.exists(self.sidecar):
            try:
                with open(self.sidecar, encoding="utf-8") as fh:
                    described = json.load(fh)
            except (OSError, ValueError) as exc:
                raise InputDataError(f"{self.sidecar}: cannot read the study it describes ({exc})") from None
            self._check_identity(described if isinstance(described, dict) else {})
        for src in sources:
            rows, meta = read_rows(src)
            self._check_identity(meta)
            if rows:
                have = list(rows[0])
                if sorted(have) != sorted(want):
                    missing = [c for c in want if c not in have]
                    extra = [c for c in have if c not in want]
                    raise InputDataError(f"{src}: its columns differ from this study's (missing: {missing or 'none'}; "
                                         f"extra: {extra or 'none'}); it holds another study")
            for row in rows:
                run = int(row["run"])
                expect = self.design(run)
                if expect is None:
                    raise InputDataError(f"{src}: run {run} is not part of this study (it has fewer runs); "
                                         "it holds another study")
                for v in self.variables:
                    a, b = float(row[v]), float(expect[v])
                    if not (a == b or (math.isnan(a) and math.isnan(b))):
                        raise InputDataError(f"{src}: run {run} has {v}={a!r} but this study gives {v}={b!r}; "
                                             "it holds another study (another design, seed or sample count)")
                if retry_failed and row["status"] != "ok":
                    continue
                self.rows[run] = {c: row[c] for c in want}
        if retry_failed:
            self._dirty = True
        self._remove_leftovers()

    def _check_identity(self, stored: dict) -> None:
        """Refuse to continue results of another study (:func:`~phs.workflows.sweep.study.identity_differences`)."""
        from phs.workflows.sweep.study import identity_differences

        have, want = (stored or {}).get("identity"), self.metadata.get("identity")
        if not isinstance(have, dict) or not want:
            return  # written before studies recorded their identity: the run-by-run design check remains
        diff = identity_differences(have, want)
        if diff:
            raise InputDataError(f"{self.path!r} holds another study ({'; '.join(diff)}): resume only the same "
                                 "study, or choose another output file")

    def _remove_leftovers(self) -> None:
        """Remove what a killed study left in its part directory besides its parts: the ``.tmp-*`` file of
        an atomic write that never reached its rename, a staged results file that was never renamed onto
        ``OUT`` (its rows are in the parts, which are removed only after ``OUT`` holds them)."""
        if not os.path.isdir(self.parts):
            return
        for name in os.listdir(self.parts):
            if _is_part(name, self.fmt):
                continue
            full = os.path.join(self.parts, name)
            if os.path.isdir(full) and not os.path.islink(full):
                shutil.rmtree(full, ignore_errors=True)
            else:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(full)

    @property
    def done(self) -> set[int]:
        """Run numbers with a recorded row."""
        return set(self.rows)

    # -- writing ---------------------------------------------------------------------------------------
    def add(self, rows: list[dict]) -> None:
        """Record finished runs: a part file at once, the results file every ``flush_seconds``."""
        if not rows:
            return
        for r in rows:
            self.rows[int(r["run"])] = r
        if self.path is None:
            return
        if self.fmt == "csv" and not self._described:  # before the first part: no row without its study
            write_atomic(self.sidecar, json.dumps(self.metadata, indent=1) + "\n")
            self._described = True
        os.makedirs(self.parts, exist_ok=True)
        # names sort in the order the parts were written: on resume a later row for a run wins
        name = f"part-{_time.time_ns():020d}-{uuid.uuid4().hex[:8]}.{self.fmt}"
        write_atomic(os.path.join(self.parts, name), encode(rows, self.numeric, self.fmt, self.metadata))
        self._dirty = True
        # rewriting a large file takes a while: at most a tenth of the time goes into it
        if self.flush_seconds <= 0 or _time.monotonic() - self._last_flush >= max(self.flush_seconds, 10 * self._flush_cost):
            self.flush()

    def flush(self) -> None:
        """Rewrite the results file from every finished run, in run order: written atomically into the
        part directory, then renamed onto the results file (see the module docstring)."""
        if self.path is None or not self._dirty:
            return
        start = _time.monotonic()
        rows = [self.rows[k] for k in sorted(self.rows)]
        os.makedirs(self.parts, exist_ok=True)
        staged = os.path.join(self.parts, "results." + self.fmt)
        write_atomic(staged, encode(rows, self.numeric, self.fmt, self.metadata))
        try:
            if os.path.exists(self.path):  # keep the mode of the file it replaces
                os.chmod(staged, os.stat(self.path).st_mode & 0o777)
            os.replace(staged, self.path)
        except OSError as exc:
            raise InputDataError(f"cannot write {self.path!r}: {exc.strerror or exc}") from None
        self._last_flush = _time.monotonic()
        self._flush_cost = self._last_flush - start
        self._dirty = False

    def close(self) -> None:
        """Final flush; then the part files are redundant and removed."""
        if self.path is None:
            return
        self._dirty = self._dirty or not os.path.exists(self.path)
        self.flush()
        if os.path.isdir(self.parts):
            shutil.rmtree(self.parts, ignore_errors=True)

    def table(self) -> dict[str, np.ndarray]:
        """Every recorded row as columns (run order)."""
        runs = sorted(self.rows)
        out = {"run": np.array(runs, dtype=np.int64)}
        for c in self.numeric:
            out[c] = np.array([float(self.rows[k][c]) for k in runs], dtype=float)
        out["status"] = np.array([str(self.rows[k]["status"]) for k in runs], dtype=object)
        out["error"] = np.array([str(self.rows[k]["error"]) for k in runs], dtype=object)
        return out
