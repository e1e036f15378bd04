"""Recordings: a time column and named signals, validated, with units and scales.

A :class:`Recording` maps columns of a CSV file (or arrays, or a pandas
DataFrame) to a model's inputs and measured outputs.  Every error names the
file, the column and the row (spreadsheet numbering: the header is row 1).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from phs.errors import InputDataError, InputHoldWarning
from phs.kinks import held_between_samples
from phs.signals import Sampled, Signal
from phs.workflows.between import check_law, header_annotations, hold_of
from phs.workflows.conversion import column_factor, model_units, unit_factor
from phs.workflows.inputs import _column, _names_and_units, _read_rows, check_time, check_uniform


def _unit_after_scale(column: str, scales: dict, file_units: dict) -> str | None:
    """Unit of a column's values after its scale: a pair's target, none after a factor, else the header's."""
    if column in scales:
        sc = scales[column]
        return str(sc[1]) if isinstance(sc, (tuple, list)) else None
    return file_units.get(column)


@dataclass(frozen=True, repr=False)
class Recording:
    """Sampled signals on a strictly increasing time grid, named as the model's signals.

    Parameters
    ----------
    t : array
        Sample times [s].
    signals : dict of str -> array
        Values of each named signal, in :attr:`units` (a signal without a unit is taken as in the
        model's unit).
    source : str
        Where the data came from (file name), used in messages and reports.
    units : dict of str -> str
        Unit of each signal's values: read from the header ``name [unit]``, the target unit of a
        ``scales=`` pair, or given by ``units=``; :meth:`in_units_of` converts them to a model's.
    between : dict
        See below.
    columns : dict of str -> str
        The column of the source each signal was read from, where its name differs (``mapping=``,
        ``--map``), for messages.

    Examples
    --------
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"U": np.ones(11), "v_C": np.linspace(0, 1, 11)},
    ...                             units={"U": "V"})
    >>> rec.names, rec.dt
    (['U', 'v_C'], 0.1)
    >>> rec
    Recording('<arrays>', 11 samples, t=0..1 s, dt=0.1 s; signals U [V], v_C)
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
    columns: dict = field(default_factory=dict)
    holds: dict = field(default_factory=dict)
    """How each input behaves between its samples, where declared: ``"zoh"`` (held by a DAC from each sample to
    the next), ``"linear"`` (a continuous signal sampled by a sensor) or a :class:`~phs.signals.Signal`, the law the
    samples were taken from (a header annotation ``U [V] {square(1500, 3)}``, as ``phs simulate --out`` writes it:
    the run replays exactly, edges between the samples included).  An input not declared is read as a continuous
    signal (:meth:`input_signal`); :meth:`check_for` warns (:class:`~phs.errors.InputHoldWarning`) when its samples
    look held (:func:`phs.kinks.held_between_samples`)."""

    # -- construction ------------------------------------------------------------------
    @classmethod
    def from_arrays(cls, t, signals: dict, source: str = "<arrays>", units=None, min_samples: int = 3,
                    resample: float | None = None, holds: dict | None = None) -> Recording:
        """Validate arrays and build a recording (see :meth:`from_csv` for the checks).

        Parameters
        ----------
        t : array
            Time stamps [s], finite and strictly increasing; uniform but for jitter (see :meth:`from_csv`).
        signals : dict of str -> array
            Values of each signal, one per time stamp.
        source : str
            Named in messages.
        units : dict of str -> str, optional
            Unit of each signal's values (converted to a model's by :meth:`in_units_of`).
        min_samples : int
            Fewest samples accepted.
        resample : float, optional
            Interpolate onto a uniform grid of this step.

        Examples
        --------
        >>> t = 1234.5 + 0.001 * np.arange(5) + [0.0, 3e-8, -2e-8, 1e-8, 0.0]    # jitter: 3e-5 of a step
        >>> rec = Recording.from_arrays(t, {"y": np.arange(5.0)})
        >>> float(rec.t[0]), round(rec.dt, 6), bool(np.ptp(np.diff(rec.t)) < 1e-9 * rec.dt)
        (1234.5, 0.001, True)
        """
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
        rec = rec._resampled(resample) if resample else rec._checked_uniform(lambda k: f"sample {k}")
        return rec.with_holds(holds or {}, lambda k: f"sample {k}")

    @classmethod
    def from_csv(cls, path, time_column: str = "t", mapping: dict | None = None, scales: dict | None = None,
                 units: dict | None = None, resample: float | None = None, min_samples: int = 3,
                 columns=None, holds: dict | None = None) -> Recording:
        """Read a CSV file with a header row.

        A header cell ``name [unit]`` (as :meth:`codegen.results.SimulationResult.to_csv` writes
        them) names the column ``name``, and ``unit`` becomes the signal's unit unless the column
        is scaled or ``units`` says otherwise; :meth:`in_units_of` (called by ``identify`` and
        ``diagnose``) converts it to the model's unit.  A time column's unit (``t [ms]``) is
        converted to seconds here.

        Time stamps need not start at zero.  Stamps with jitter count as uniform when each lies
        within :data:`~phs.workflows.inputs.JITTER` (1 %) of a step from the least-squares uniform
        grid through them; the recording then carries that grid ``t0 + k*dt`` from the first stamp
        ``t0`` (:func:`~phs.workflows.inputs.uniform_grid`).  A missing sample, a repeated or
        decreasing stamp is refused, naming the row.

        Parameters
        ----------
        path : str or path-like
        time_column : str
            Name of the time column (strictly increasing, no duplicates).
        mapping : dict of str -> str
            ``{COLUMN: SIGNAL}``: renames columns to the model's signal names (default: same names).
        scales : dict of str -> float or (str, str)
            Per column: a factor, or ``(from_unit, to_unit)`` such as ``("mm", "m")``, ``("kV", "V")``.
            A scale takes precedence over the header's unit: a factor leaves the column without a
            unit (taken as in the model's), a pair gives it ``to_unit``.
        units : dict of str -> str
            Unit of each signal's values (after ``scales``), overriding the header.
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
            NaN/inf, non-monotone or duplicated time, irregular sampling, too few rows, a time
            column in a unit that is not a time.

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
        raw_header = header
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
        if time_column in file_units:
            t = t * column_factor(path, time_column, file_units[time_column], "s", "time")
        where = lambda k: f"row {rows[k][0]}"  # noqa: E731
        check_time(t, path, min_samples, where, time_column)
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
        read_units = {mapping.get(c, c): u for c in wanted if (u := _unit_after_scale(c, scales, file_units))}
        columns_of = {mapping[c]: c for c in wanted if mapping.get(c, c) != c}
        rec = cls(t, signals, path, {**read_units, **dict(units or {})}, columns=columns_of)
        rec = rec._resampled(resample) if resample else rec._checked_uniform(where, time_column)
        noted = {mapping.get(c, c): text for c, text in header_annotations(raw_header, header).items() if c in wanted}
        factors = {mapping.get(c, c): float(unit_factor(*sc) if isinstance(sc, (tuple, list)) else sc) for c, sc in scales.items()}
        return rec.with_holds({**noted, **dict(holds or {})}, where, factors)

    @classmethod
    def from_dataframe(cls, df, time_column: str = "t", mapping=None, scales=None, **kw) -> Recording:
        """Build from a pandas DataFrame (columns as in :meth:`from_csv`, ``name [unit]`` labels too;
        other keywords as :meth:`from_arrays`).

        Examples
        --------
        >>> import pytest; pd = pytest.importorskip("pandas")   # pandas is optional
        >>> df = pd.DataFrame({"t [ms]": [0.0, 1.0, 2.0], "U [kV]": [0.0, 1.0, 2.0]})
        >>> rec = Recording.from_dataframe(df)
        >>> rec.t.tolist(), rec.units
        ([0.0, 0.001, 0.002], {'U': 'kV'})
        """
        labels = list(df.columns)
        names, file_units = _names_and_units([str(c) for c in labels], "DataFrame")
        if time_column not in names:
            raise InputDataError(f"DataFrame: no time column {time_column!r} (columns: {', '.join(names)})")
        mapping, scales = dict(mapping or {}), dict(scales or {})
        sig, units, columns_of, t = {}, {}, {}, None
        for label, c in zip(labels, names):
            try:
                v = df[label].to_numpy(dtype=float)
            except (TypeError, ValueError):
                raise InputDataError(f"DataFrame: column {c!r} is not numeric") from None
            if c == time_column:
                t = v * (column_factor("DataFrame", c, file_units[c], "s", "time") if c in file_units else 1.0)
                continue
            sc = scales.get(c, 1.0)
            name = mapping.get(c, c)
            sig[name] = v * float(unit_factor(*sc) if isinstance(sc, (tuple, list)) else sc)
            if unit := _unit_after_scale(c, scales, file_units):
                units[name] = unit
            if name != c:
                columns_of[name] = c
        kw["units"] = {**units, **dict(kw.get("units") or {})}
        rec = cls.from_arrays(t, sig, source="DataFrame", **kw)
        return replace(rec, columns=columns_of) if columns_of else rec

    # -- checks --------------------------------------------------------------------------
    def _checked_uniform(self, where=lambda k: f"sample {k}", column: str = "t") -> Recording:
        """This recording on the uniform grid of its time stamps (:func:`~phs.workflows.inputs.check_uniform`:
        jitter within 1 % of a step), or an InputDataError naming ``where(k)`` the sampling is irregular."""
        t = check_uniform(self.t, self.source, where, column, "; pass resample=DT to interpolate onto a uniform grid")
        return self if t is self.t else replace(self, t=t)

    def _resampled(self, dt: float) -> Recording:
        if not dt > 0:
            raise InputDataError(f"{self.source}: resample step must be positive, got {dt}")
        tt = self.t[0] + dt * np.arange(int(np.floor((self.t[-1] - self.t[0]) / dt * (1 + 1e-12))) + 1)
        return replace(self, t=tt, signals={k: np.interp(tt, self.t, v) for k, v in self.signals.items()})

    # -- units ---------------------------------------------------------------------------
    def in_units_of(self, system) -> Recording:
        """This recording with every signal of ``system`` in the model's unit, or an InputDataError.

        The model's unit of a signal is that of its input, port output, measured output or state
        (:func:`model_units`).  A signal whose unit (:attr:`units`) differs is multiplied by
        :func:`unit_factor` (``kV`` -> ``V``, ``mm`` -> ``m``, ``deg`` -> ``rad``), its course
        (:attr:`between`) too; a signal without a unit is taken as already in the model's unit; a
        signal the model does not name is left as it is.  A unit that cannot be converted (another
        dimension, an unknown name) is refused in one line naming the source, the column and both
        units.  So is a dimensionless unit (``1``, ``rad``, ``deg``) against a dimensioned model
        unit: a header that states a unit is taken at its word, and a plain number where the model
        expects metres is more likely a normalised or mislabelled column than metres; leave the unit
        out of the header, or give a scale, to read the values as they are.
        :func:`~phs.workflows.identify.identify` and :func:`~phs.workflows.diagnose.diagnose` call it
        on entry (and ``phs fit``, ``phs diagnose``, ``phs sweep --data`` on reading).

        Parameters
        ----------
        system : PHSystem

        Returns
        -------
        Recording
            ``self`` when every unit is already the model's.

        Raises
        ------
        InputDataError
            Naming the source, the column and both units.

        Examples
        --------
        >>> from systems.examples import mass_spring_damper
        >>> rec = Recording.from_arrays([0.0, 0.1, 0.2], {"F": [0.0, 1.0, 2.0], "position": [0.0, 5.0, 10.0]},
        ...                             units={"F": "kN", "position": "mm"})
        >>> si = rec.in_units_of(mass_spring_damper())
        >>> si["F"].tolist(), si["position"].tolist(), si.units
        ([0.0, 1000.0, 2000.0], [0.0, 0.005, 0.01], {'F': 'N', 'position': 'm'})
        >>> Recording.from_arrays([0.0, 0.1, 0.2], {"position": [0.0, 1.0, 2.0]}, source="r.csv",
        ...                       units={"position": "s"}).in_units_of(mass_spring_damper())  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        phs.errors.InputDataError: r.csv: column 'position' is in 's', which cannot be converted to 'm', the model's ...
        """
        model = model_units(system)
        factors, units = {}, dict(self.units)
        for name, unit in self.units.items():
            if name not in model or name not in self.signals or "".join(unit.split()) == "".join(model[name].split()):
                continue
            f = column_factor(self.source, self.columns.get(name, name), unit, model[name], name)
            if f != 1.0:
                factors[name] = f
            units[name] = model[name]
        if units == self.units:
            return self
        signals = {k: v * factors[k] if k in factors else v for k, v in self.signals.items()}
        between = {k: (tv[0], np.asarray(tv[1], float) * factors[k]) if k in factors else tv
                   for k, tv in self.between.items()}
        holds = {k: factors[k] * h if k in factors and isinstance(h, Signal) else h for k, h in self.holds.items()}
        return replace(self, signals=signals, units=units, between=between, holds=holds)

    def with_holds(self, holds: dict, row=None, factors=None) -> Recording:
        """This recording with ``holds`` declaring how inputs behave between samples (:attr:`holds`): by signal
        name, ``"zoh"``, ``"linear"``, ``"auto"`` or a law (a :class:`~phs.signals.Signal`, or its text in the
        vocabulary of ``--input``, read by :func:`phs.workflows.between.hold_of`).  A law is checked against the
        samples (:func:`phs.workflows.between.check_law`; ``row(k)`` names sample ``k`` in the message) and
        multiplied by ``factors[name]`` where the values were scaled on reading.

        Raises
        ------
        InputDataError
            Naming the source and the signal: an unknown signal, a reading that is not one, samples that do not
            follow their declared law.

        Examples
        --------
        >>> t = np.arange(0.0, 1.0, 0.01)
        >>> rec = Recording.from_arrays(t, {"U": np.where(t < 0.5, 0.0, 1.0)}).with_holds({"U": "step(1.0, 0.5)"})
        >>> float(rec.input_signal("U")(0.499))
        0.0
        """
        if not holds:
            return self
        row = row or (lambda k: f"sample {k}")
        out = dict(self.holds)
        for name, text in holds.items():
            if name not in self.signals:
                raise InputDataError(f"{self.source}: a reading between samples is given for {name!r}, which is not a "
                                     f"signal of the recording (signals: {', '.join(self.signals)})")
            column = self.columns.get(name, name)
            hold = hold_of(text, self.source, column)
            if isinstance(hold, Signal):
                f = (factors or {}).get(name, 1.0)
                check_law(hold, str(text), self.t, self.signals[name] / f, self.source, column, row)
                hold = hold if f == 1.0 else f * hold
            out[name] = hold
        return replace(self, holds=out)

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

    def __repr__(self) -> str:
        """One line: the source, the time grid and the signals (at most eight named), never the samples."""
        sigs = [f"{n} [{self.units[n]}]" if self.units.get(n) else n for n in self.signals]
        shown = ", ".join(sigs[:8]) + (f", ... ({len(sigs) - 8} more)" if len(sigs) > 8 else "")
        grid = f"t={self.t[0]:g}..{self.t[-1]:g} s, dt={self.dt:g} s" if len(self.t) > 1 else f"t={self.t[0]:g} s" if len(self.t) else ""
        return f"Recording({self.source!r}, {len(self.t)} samples, {grid}; signals {shown or 'none'})"

    def input_signal(self, name: str) -> Signal:
        """The signal ``name`` as a simulation reads it: its course between the samples (:attr:`between`), its
        declared law, or its samples (:class:`~phs.signals.Sampled`) held or interpolated as declared in
        :attr:`holds`, by default interpolated as a continuous signal (:meth:`check_for` warns when such samples
        look held).

        Examples
        --------
        >>> rec = Recording.from_arrays(np.array([0.0, 1.0, 2.0, 3.0]), {"U": np.array([0.0, 0.5, 1.0, 0.0])})
        >>> float(rec.input_signal("U")(1.5))
        0.75
        >>> late = Recording(rec.t, rec.signals, between={"U": (np.array([0.0, 1.25, 2.25]), np.array([0.0, 0.0, 1.0]))})
        >>> float(late.input_signal("U")(1.5)), float(late["U"][2])    # the course delayed by 0.25; the samples kept
        (0.25, 1.0)
        >>> steps = Recording.from_arrays(np.arange(40) * 0.1, {"U": np.repeat([0.0, 1.0], 20)}, holds={"U": "zoh"})
        >>> steps.input_signal("U").hold, float(steps.input_signal("U")(1.95))   # held: the step at t = 2.0 exactly
        ('zoh', 0.0)
        """
        if name in self.between:
            times, values = self.between[name]
            return Sampled(tuple(np.asarray(times, float)), tuple(np.asarray(values, float)))
        hold = self.holds.get(name, "linear")
        if isinstance(hold, Signal):
            return hold
        return Sampled(tuple(self.t), tuple(self[name]), hold=hold)

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
        return replace(self, t=self.t[sel], signals={k: v[sel] for k, v in self.signals.items()}, between=between)

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
        for u in system.input_names:  # read as continuous unless declared: say so where the samples look held
            if u not in self.holds and u not in self.between and held_between_samples(self.signals[u])[0]:
                c = self.columns.get(u, u)
                warnings.warn(f"{self.source}: input {c!r} changes in isolated jumps between flat stretches, as a command "
                              "held by a DAC does; it is read as a continuous signal (straight lines between samples); "
                              f"if a DAC held it, declare it: holds={{{u!r}: 'zoh'}}, --hold {c}=zoh or a header "
                              f"'{c} [unit] {{zoh}}'", InputHoldWarning, stacklevel=2)
        return system.input_names, outs

