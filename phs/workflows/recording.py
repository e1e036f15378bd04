"""Recordings: a time column and named signals, validated, with units and scales.

A :class:`Recording` maps columns of a CSV file (or arrays, or a pandas
DataFrame) to a model's inputs and measured outputs.  Every error names the
file, the column and the row (spreadsheet numbering: the header is row 1).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from phs.errors import InputDataError, UnitError
from phs.signals import Sampled
from phs.units import parse_unit
from phs.workflows.inputs import _column, _names_and_units, _read_rows, check_time

# SI multipliers of the unit names a recording may use (dimensions are checked separately)
_PREFIX = {"": 1.0, "k": 1e3, "M": 1e6, "m": 1e-3, "u": 1e-6, "µ": 1e-6, "n": 1e-9, "c": 1e-2}
_BASE_UNITS = ("m", "s", "V", "A", "N", "Ohm", "F", "C", "J", "W", "Pa", "rad", "g", "Hz")


def unit_factor(from_unit: str, to_unit: str) -> float:
    """Factor converting values in ``from_unit`` to ``to_unit`` (e.g. ``mm`` -> ``m`` is 1e-3).

    Raises
    ------
    InputDataError
        If a unit is unknown or the dimensions differ.

    Examples
    --------
    >>> unit_factor("mm", "m"), unit_factor("kV", "V"), unit_factor("deg", "rad") == np.pi / 180
    (0.001, 1000.0, True)
    """

    def si(u: str) -> float:
        u = u.strip()
        if u in ("1", ""):
            return 1.0
        if u == "deg":
            return np.pi / 180
        if u == "g":
            return 1e-3
        if u in _BASE_UNITS:
            return 1.0 if u != "g" else 1e-3
        for p, f in _PREFIX.items():
            if p and u.startswith(p) and u[len(p):] in _BASE_UNITS:
                return f * (1e-3 if u[len(p):] == "g" else 1.0)
        raise InputDataError(f"unknown unit {u!r}: use a prefix (k, m, u, n, c, M) and one of {', '.join(_BASE_UNITS)}")

    fu = from_unit.replace("deg", "rad") if from_unit == "deg" else from_unit
    try:
        same = parse_unit(_strip_prefix(fu)) == parse_unit(_strip_prefix(to_unit))
    except UnitError as exc:  # an unknown name, or text that is not a unit (read by phs.safe_parse)
        raise InputDataError(f"cannot convert {from_unit!r} to {to_unit!r}: {exc}") from None
    if not same:
        raise InputDataError(f"cannot convert {from_unit!r} to {to_unit!r}: different dimensions")
    return si(from_unit) / si(to_unit)


def _strip_prefix(u: str) -> str:
    u = u.strip()
    if u in _BASE_UNITS or u in ("1", "", "deg"):
        return "rad" if u == "deg" else (u or "1")
    for p in _PREFIX:
        if p and u.startswith(p) and u[len(p):] in _BASE_UNITS:
            return u[len(p):]
    return u


@dataclass(frozen=True)
class Recording:
    """Sampled signals on a strictly increasing time grid, named as the model's signals.

    Parameters
    ----------
    t : array
        Sample times [s].
    signals : dict of str -> array
        Values of each named signal (SI units of the model).
    source : str
        Where the data came from (file name), used in messages and reports.
    units : dict of str -> str
        Unit of each signal after conversion.

    Examples
    --------
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"U": np.ones(11), "v_C": np.linspace(0, 1, 11)})
    >>> rec.names, rec.dt
    (['U', 'v_C'], 0.1)
    """

    t: np.ndarray
    signals: dict
    source: str = "<arrays>"
    units: dict = field(default_factory=dict)
    between: dict = field(default_factory=dict)
    """Signals whose course between the samples is not the straight line through them, as their own
    ``(times, values)`` (linear between those): an input element's output in continuous time, e.g. a
    command delayed by a fraction of a sample, whose kinks lie between the recording's samples.  The
    samples in ``signals`` stay what every residual and plot reads; a simulation reads the course
    (:meth:`input_signal`)."""

    # -- construction ------------------------------------------------------------------
    @classmethod
    def from_arrays(cls, t, signals: dict, source: str = "<arrays>", units=None, min_samples: int = 3,
                    resample: float | None = None) -> Recording:
        """Validate arrays and build a recording (see :meth:`from_csv` for the checks)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        out = {}
        for name, v in signals.items():
            v = np.asarray(v, dtype=float).reshape(-1)
            if v.shape != t.shape:
                raise InputDataError(f"{source}: signal {name!r} has {v.size} samples but the time has {t.size}")
            bad = ~np.isfinite(v)
            if np.any(bad):
                k = int(np.argmax(bad))
                raise InputDataError(f"{source}: signal {name!r} is not finite at sample {k} (t={t[k]:g})")
            out[name] = v
        check_time(t, source, min_samples, lambda k: f"sample {k}")
        rec = cls(t, out, source, dict(units or {}))
        return rec._resampled(resample) if resample else rec._checked_uniform()

    @classmethod
    def from_csv(cls, path, time_column: str = "t", mapping: dict | None = None, scales: dict | None = None,
                 units: dict | None = None, resample: float | None = None, min_samples: int = 3,
                 columns=None) -> Recording:
        """Read a CSV file with a header row.

        A header cell ``name [unit]`` (as :meth:`codegen.results.SimulationResult.to_csv` writes
        them) names the column ``name``, and ``unit`` becomes the signal's unit unless the column
        is scaled or ``units`` says otherwise.

        Parameters
        ----------
        path : str or path-like
        time_column : str
            Name of the time column (strictly increasing, no duplicates).
        mapping : dict of str -> str
            ``{COLUMN: SIGNAL}``: renames columns to the model's signal names (default: same names).
        scales : dict of str -> float or (str, str)
            Per column: a factor, or ``(from_unit, to_unit)`` such as ``("mm", "m")``, ``("kV", "V")``.
        units : dict of str -> str
            Unit of each signal after conversion (for reports).
        resample : float, optional
            Resample onto a uniform grid of this step (linear interpolation).  Without it an
            irregularly sampled file is an error.
        min_samples : int
            Fewest data rows accepted.
        columns : sequence of str, optional
            Columns to read (default: every column).

        Raises
        ------
        InputDataError
            Naming file, column and row: missing file or column, a non-numeric or empty cell,
            NaN/inf, non-monotone or duplicated time, irregular sampling, too few rows.

        Examples
        --------
        >>> import os, tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     p = os.path.join(d, "r.csv")
        ...     _ = open(p, "w").write("time,pos_mm,volt_kV\\n0,0,0\\n0.001,1,5\\n0.002,2,5\\n")
        ...     rec = Recording.from_csv(p, time_column="time", mapping={"pos_mm": "tip", "volt_kV": "U"},
        ...                              scales={"pos_mm": ("mm", "m"), "volt_kV": ("kV", "V")})
        >>> rec["tip"].tolist(), rec["U"].tolist()
        ([0.0, 0.001, 0.002], [0.0, 5000.0, 5000.0])
        """
        path = os.fspath(path)
        header, rows = _read_rows(path)
        header, file_units = _names_and_units(header, path)
        if time_column not in header:
            raise InputDataError(f"{path}: no time column {time_column!r} (columns: {', '.join(header)})")
        mapping = dict(mapping or {})
        for c in mapping:
            if c not in header:
                raise InputDataError(f"{path}: no column {c!r} to map to {mapping[c]!r} (columns: {', '.join(header)})")
        wanted = list(columns) if columns is not None else [c for c in header if c != time_column]
        for c in wanted:
            if c not in header:
                raise InputDataError(f"{path}: no column {c!r} (columns: {', '.join(header)})")
        if len(rows) < min_samples:
            raise InputDataError(f"{path}: needs at least {min_samples} data rows, found {len(rows)}")
        t = _column(path, header, rows, time_column)
        check_time(t, path, min_samples, lambda k: f"row {rows[k][0]}", time_column)
        scales = dict(scales or {})
        signals = {}
        for c in wanted:
            v = _column(path, header, rows, c)
            sc = scales.get(c, 1.0)
            if isinstance(sc, (tuple, list)):
                sc = unit_factor(*sc)
            signals[mapping.get(c, c)] = v * float(sc)
        unknown_scales = [c for c in scales if c not in wanted]
        if unknown_scales:
            raise InputDataError(f"{path}: scales given for columns not read: {unknown_scales}")
        read_units = {mapping.get(c, c): file_units[c] for c in wanted if c in file_units and c not in scales}
        rec = cls(t, signals, path, {**read_units, **dict(units or {})})
        return rec._resampled(resample) if resample else rec._checked_uniform()

    @classmethod
    def from_dataframe(cls, df, time_column: str = "t", mapping=None, scales=None, **kw) -> Recording:
        """Build from a pandas DataFrame (columns as in :meth:`from_csv`)."""
        if time_column not in df.columns:
            raise InputDataError(f"DataFrame: no time column {time_column!r} (columns: {', '.join(map(str, df.columns))})")
        mapping, scales = dict(mapping or {}), dict(scales or {})
        sig = {}
        for c in df.columns:
            if c == time_column:
                continue
            try:
                v = df[c].to_numpy(dtype=float)
            except (TypeError, ValueError):
                raise InputDataError(f"DataFrame: column {c!r} is not numeric") from None
            sc = scales.get(c, 1.0)
            sig[mapping.get(c, c)] = v * float(unit_factor(*sc) if isinstance(sc, (tuple, list)) else sc)
        return cls.from_arrays(df[time_column].to_numpy(dtype=float), sig, source="DataFrame", **kw)

    # -- checks --------------------------------------------------------------------------
    def _checked_uniform(self) -> Recording:
        d = np.diff(self.t)
        if d.size and (d.max() - d.min()) > 1e-6 * d.mean():
            k = int(np.argmax(np.abs(d - np.median(d)))) + 1
            raise InputDataError(
                f"{self.source}: irregular sampling: step {d[k - 1]:g} s at t={self.t[k]:g} versus the median "
                f"{np.median(d):g} s; pass resample=DT to interpolate onto a uniform grid"
            )
        return self

    def _resampled(self, dt: float) -> Recording:
        if not dt > 0:
            raise InputDataError(f"{self.source}: resample step must be positive, got {dt}")
        tt = np.arange(self.t[0], self.t[-1] + dt * 1e-9, dt)
        return Recording(tt, {k: np.interp(tt, self.t, v) for k, v in self.signals.items()}, self.source, self.units)

    # -- access --------------------------------------------------------------------------
    @property
    def names(self) -> list[str]:
        return list(self.signals)

    @property
    def dt(self) -> float:
        return float(np.round(np.median(np.diff(self.t)), 15))

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.signals:
            raise KeyError(f"{self.source}: no signal {name!r}; signals: {', '.join(self.signals)}")
        return self.signals[name]

    def __len__(self) -> int:
        return len(self.t)

    def input_signal(self, name: str) -> Sampled:
        """The signal ``name`` as a simulation reads it: a :class:`~phs.signals.Sampled` through its course
        (:attr:`between`) or, by default, through its samples.

        Examples
        --------
        >>> rec = Recording.from_arrays(np.array([0.0, 1.0, 2.0]), {"U": np.array([0.0, 0.0, 1.0])})
        >>> float(rec.input_signal("U")(1.5))
        0.5
        >>> late = Recording(rec.t, rec.signals, between={"U": (np.array([0.0, 1.25, 2.25]), np.array([0.0, 0.0, 1.0]))})
        >>> float(late.input_signal("U")(1.5)), float(late["U"][2])    # the course delayed by 0.25; the samples kept
        (0.25, 1.0)
        """
        times, values = self.between[name] if name in self.between else (self.t, self[name])
        return Sampled(tuple(np.asarray(times, float)), tuple(np.asarray(values, float)))

    def window(self, t0: float, t1: float) -> Recording:
        """The samples with ``t0 <= t <= t1`` (times kept), and the courses between samples over it."""
        sel = (self.t >= t0 - 1e-12) & (self.t <= t1 + 1e-12)
        if sel.sum() < 3:
            raise InputDataError(f"{self.source}: window [{t0}, {t1}] holds fewer than 3 samples")
        between = {}
        for k, (times, values) in self.between.items():  # from the last point at or before t0 to the first at or after t1
            a = max(int(np.searchsorted(times, t0, side="right")) - 1, 0)
            b = min(int(np.searchsorted(times, t1, side="left")) + 1, len(times))
            between[k] = (times[a:b], values[a:b])
        return Recording(self.t[sel], {k: v[sel] for k, v in self.signals.items()}, self.source, self.units, between)

    def split(self, at: float) -> tuple[Recording, Recording]:
        """Train/validation split by time: ``[t0, at]`` and ``[at, t_end]``.

        Examples
        --------
        >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"y": np.zeros(11)})
        >>> [len(r) for r in rec.split(0.5)]
        [6, 6]
        """
        return self.window(self.t[0], at), self.window(at, self.t[-1])

    def check_for(self, system, outputs=None) -> tuple[list[str], list[str]]:
        """Which model inputs and measured outputs the recording provides; errors name what is missing."""
        missing = [u for u in system.input_names if u not in self.signals]
        if missing:
            raise InputDataError(f"{self.source}: no signal for input(s) {missing} of {system.name!r} "
                                 f"(signals: {', '.join(self.signals)}; map columns with mapping=/--map)")
        known = system.measured_names + system.output_names + system.state_names
        outs = list(outputs) if outputs is not None else [m for m in known if m in self.signals]
        bad = [o for o in outs if o not in known]
        if bad:
            raise InputDataError(f"{system.name!r} has no measured output {bad}; measured: {system.measured_names}")
        absent = [o for o in outs if o not in self.signals]
        if absent:
            raise InputDataError(f"{self.source}: no signal for output(s) {absent}")
        if not outs:
            raise InputDataError(f"{self.source}: none of the signals {self.names} is a measured output of "
                                 f"{system.name!r} ({', '.join(system.measured_names)})")
        return system.input_names, outs

