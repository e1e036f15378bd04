"""Metrics of a study: numbers computed from each run's simulation result.

A :class:`Metric` is a named function of a :class:`~codegen.results.SimulationResult`
returning one number (or several, one per declared column).  The built-in
ones: :func:`peak`, :func:`final`, :func:`rise_time`, :func:`energy`,
:func:`passivity_margin`, :func:`fit` (NRMSE fit % against a recording) and
:func:`values_at` (a signal at chosen times, for Monte Carlo bands); any
function of the result is a metric too.  :func:`metric` reads the command
line's ``KIND:SIGNAL`` specifications.

Metrics declare the signals they read, so the batch evaluator computes those
for a whole chunk at once, and whether they need the energy accounts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from phs.errors import InputDataError

RESERVED = ("run", "status", "error")


@dataclass(frozen=True)
class Metric:
    """A named number (or several) computed from a run's :class:`~codegen.results.SimulationResult`.

    Parameters
    ----------
    name : str
        Column name in the results (and default for ``columns``).
    function : callable
        ``function(result) -> float`` (or a sequence of floats, one per column).
    columns : tuple of str, optional
        Column names when the function returns several values (default ``(name,)``).
    reads : tuple of str
        Signals the function reads (``res[name]``), so a batch can evaluate them for all runs at once.
    energy : bool
        The function needs the energy accounts (``res.quadratures``) of the integrator.
    unit, description : str
        For tables and plots.
    grid : array, optional
        The time grid the metric requires (a recording's), checked when the study is defined.
    unit_of : str
        Without ``unit``: the signal whose unit the metric has (a peak or a final value of it).

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from systems.examples import rc_circuit
    >>> res = simulate(rc_circuit(), np.linspace(0, 5e-3, 51), u={"U": 1.0})
    >>> overshoot = Metric("overshoot", lambda r: float(r["v_C"].max() - r["v_C"][-1]), reads=("v_C",))
    >>> overshoot(res)
    (0.0,)
    >>> peak("v_C")(res)   # doctest: +ELLIPSIS
    (0.99326...,)
    """

    name: str
    function: Callable
    columns: tuple = ()
    reads: tuple = ()
    energy: bool = False
    unit: str = ""
    description: str = ""
    grid: np.ndarray | None = None
    unit_of: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise InputDataError(f"a metric needs a non-empty name, got {self.name!r}")
        if not callable(self.function):
            raise InputDataError(f"metric {self.name!r}: function {self.function!r} is not callable")
        object.__setattr__(self, "columns", tuple(self.columns) or (self.name,))
        object.__setattr__(self, "reads", tuple(self.reads))

    def __call__(self, result) -> tuple[float, ...]:
        """Evaluate on one result; returns one float per column (NaN allowed).

        Raises
        ------
        InputDataError
            When the function returns something that is not one number per column.
        """
        value = self.function(result)
        arr = np.asarray(value, dtype=float).reshape(-1) if not isinstance(value, (int, float)) else np.array([value], float)
        if arr.size != len(self.columns):
            raise InputDataError(f"metric {self.name!r} returned {arr.size} value(s) for {len(self.columns)} column(s)")
        return tuple(float(v) for v in arr)


def _signal(res, name: str) -> np.ndarray:
    return np.asarray(res[name], dtype=float)


def peak(signal: str, absolute: bool = False, name: str | None = None) -> Metric:
    """Largest value of ``signal`` over the run (of ``|signal|`` with ``absolute``).

    Examples
    --------
    >>> peak("tip").name, peak("tip", absolute=True).name
    ('peak_tip', 'peak_abs_tip')
    """
    label = name or (f"peak_abs_{signal}" if absolute else f"peak_{signal}")

    def f(res):
        y = _signal(res, signal)
        return float(np.max(np.abs(y)) if absolute else np.max(y))

    return Metric(label, f, reads=(signal,), unit_of=signal, description=f"peak of {'|' + signal + '|' if absolute else signal}")


def final(signal: str, name: str | None = None) -> Metric:
    """Value of ``signal`` at the end of the run (a stroke, a settled position).

    Examples
    --------
    >>> final("displacement").name
    'final_displacement'
    """
    return Metric(name or f"final_{signal}", lambda res: float(_signal(res, signal)[-1]), reads=(signal,), unit_of=signal,
                  description=f"{signal} at the final time")


def rise_time_of(t, y, low: float = 0.1, high: float = 0.9) -> float:
    """Time ``y`` takes from ``low`` to ``high`` of its change ``y[-1] - y[0]`` (first crossings, linear interpolation).

    NaN when ``y`` does not change or never reaches a level.

    Examples
    --------
    >>> t = np.linspace(0, 20, 20001)
    >>> round(rise_time_of(t, 1 - np.exp(-t)), 4)   # ln(9) for a first-order step response
    2.1972
    """
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    d = y[-1] - y[0]
    if not (np.isfinite(d) and d != 0):
        return float("nan")
    s = (y - y[0]) / d

    def cross(level):
        above = np.nonzero(s >= level)[0]
        if len(above) == 0:
            return float("nan")
        i = int(above[0])
        if i == 0:
            return float(t[0])
        return float(t[i - 1] + (level - s[i - 1]) / (s[i] - s[i - 1]) * (t[i] - t[i - 1]))

    return cross(high) - cross(low)


def rise_time(signal: str, low: float = 0.1, high: float = 0.9, start: float | None = None, end: float | None = None,
              name: str | None = None) -> Metric:
    """Rise time of ``signal`` from ``low`` to ``high`` (fractions) of its change over ``[start, end]``.

    The change is from the value at ``start`` to the value at ``end`` (default: the whole run), so
    for a step response the reference is the settled value; see :func:`rise_time_of`.

    Examples
    --------
    >>> rise_time("tip", start=0.0, end=0.25).name
    'rise_time_tip'
    """
    if not 0 <= low < high <= 1:
        raise InputDataError(f"rise_time: need 0 <= low < high <= 1, got low={low}, high={high}")

    def f(res):
        t = res.t
        sel = np.ones(len(t), dtype=bool)
        if start is not None:
            sel &= t >= start
        if end is not None:
            sel &= t <= end
        if sel.sum() < 2:
            return float("nan")
        return rise_time_of(t[sel], _signal(res, signal)[sel], low, high)

    window = "" if start is None and end is None else f" in [{start if start is not None else ''}, {end if end is not None else ''}]"
    return Metric(name or f"rise_time_{signal}", f, reads=(signal,), unit="s",
                  description=f"{low:.0%}-{high:.0%} rise time of {signal}{window}")


def energy(name: str = "energy") -> Metric:
    """Energy supplied through the input ports over the run, ``int y^T u dt`` [J].

    Taken from the integrator's energy quadrature (exact to the tolerance even across the
    sub-microsecond charging spikes at input edges); the study integrates it when this metric is
    asked for.  Without quadratures, the trapezoidal rule on the grid is used.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from systems.examples import rc_circuit
    >>> res = simulate(rc_circuit(), np.linspace(0, 0.02, 201), u={"U": 1.0})
    >>> round(energy()(res)[0] / 1e-6, 4)   # C U^2 = 1e-6 J once charged
    1.0
    """

    def f(res):
        q = getattr(res, "quadratures", None) or {}
        if "E_supplied" in q:
            return float(q["E_supplied"][-1])
        return float(np.trapezoid(res.supplied, res.t))

    return Metric(name, f, energy=True, unit="J", description="energy supplied through the input ports")


def passivity_margin(box=None, samples: int | None = None, seed: int = 0, name: str = "passivity_margin") -> Metric:
    """Smallest eigenvalue of the dissipation matrix ``R`` over a sampled state box, for the run's parameters.

    Computed by :func:`codegen.passivity.dissipation_margin` (positive: strictly dissipative over
    the box; negative: the model creates energy somewhere).  Depends on the parameters only, not on
    the trajectory.

    Examples
    --------
    >>> passivity_margin(samples=64).name
    'passivity_margin'
    """

    def f(res):
        from codegen.passivity import dissipation_margin

        kw = {"params": dict(zip(res.system.param_names, np.asarray(res.p, dtype=float).tolist())), "box": box,
              "seed": seed}
        if samples is not None:
            kw["samples"] = samples
        return float(dissipation_margin(res.system, **kw))

    return Metric(name, f, description="minimum eigenvalue of R over the sampled state box")


def fit(recording, channel: str, name: str | None = None) -> Metric:
    """NRMSE fit % of ``channel`` against ``recording`` (see :func:`phs.workflows.identify.nrmse_fit`).

    The study must run on the recording's time grid (and normally with its inputs: give the
    recording as the study's ``u``).

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.recording import Recording
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"U": np.ones(11), "v_C": np.linspace(0, 1, 11)})
    >>> fit(rec, "v_C").name
    'fit_v_C'
    """
    if channel not in recording.names:
        raise InputDataError(f"fit metric: recording {recording.source!r} has no signal {channel!r} "
                             f"(it has {', '.join(recording.names)})")
    y = np.asarray(recording[channel], dtype=float)

    def f(res):
        from phs.workflows.identify.scoring import nrmse_fit

        return nrmse_fit(y, _signal(res, channel))

    return Metric(name or f"fit_{channel}", f, reads=(channel,), unit="%", grid=np.asarray(recording.t, dtype=float),
                  description=f"NRMSE fit of {channel} against {recording.source}")


def values_at(signal: str, times: Sequence[float], name: str | None = None) -> Metric:
    """``signal`` at chosen times (linear interpolation on the grid): one column per time.

    Quantiles of these columns over a Monte Carlo study are confidence bands of the trajectory.

    Examples
    --------
    >>> values_at("tip", [0.1, 0.5]).columns
    ('tip@0.1', 'tip@0.5')
    """
    times = [float(x) for x in times]
    if not times:
        raise InputDataError(f"values_at {signal!r}: give at least one time")

    def f(res):
        return np.interp(times, res.t, _signal(res, signal))

    return Metric(name or f"{signal}@", f, columns=tuple(f"{signal}@{x:g}" for x in times), reads=(signal,),
                  unit_of=signal, description=f"{signal} at given times")


_KINDS = {"peak": peak, "peak_abs": lambda s: peak(s, absolute=True), "final": final, "rise_time": rise_time}


def metric(spec, recording=None) -> Metric:
    """A :class:`Metric` from a command-line specification (or a Metric, returned as is).

    ``peak:SIGNAL``, ``peak_abs:SIGNAL``, ``final:SIGNAL``, ``rise_time:SIGNAL`` (optionally
    ``rise_time:SIGNAL:START:END``), ``energy``, ``passivity_margin``, ``fit:SIGNAL`` (needs
    ``recording``).

    Raises
    ------
    InputDataError
        Naming the specification when it cannot be read.

    Examples
    --------
    >>> [metric(s).name for s in ("peak:tip", "energy", "rise_time:tip:0:0.25")]
    ['peak_tip', 'energy', 'rise_time_tip']
    """
    if isinstance(spec, Metric):
        return spec
    text = str(spec).strip()
    kind, _, rest = text.partition(":")
    kind = kind.strip()
    if kind == "energy" and not rest:
        return energy()
    if kind == "passivity_margin" and not rest:
        return passivity_margin()
    if kind == "fit":
        if recording is None:
            raise InputDataError(f"metric {text!r}: a fit needs a recording (--data DATA)")
        return fit(recording, rest.strip())
    if kind in _KINDS and rest.strip():
        parts = [p.strip() for p in rest.split(":")]
        if kind == "rise_time" and len(parts) in (1, 3):
            try:
                window = [float(v) if v else None for v in parts[1:]] or [None, None]
            except ValueError:
                raise InputDataError(f"metric {text!r}: expected rise_time:SIGNAL:START:END with numbers") from None
            return rise_time(parts[0], start=window[0], end=window[1])
        if len(parts) == 1 and parts[0]:
            return _KINDS[kind](parts[0])
    raise InputDataError(f"metric {text!r}: expected one of peak:SIGNAL, peak_abs:SIGNAL, final:SIGNAL, "
                         f"rise_time:SIGNAL[:START:END], energy, passivity_margin, fit:SIGNAL")


def as_metrics(metrics, recording=None, default_reads: tuple = ()) -> list[Metric]:
    """Metrics from a sequence (Metric, specification string, or named function) or a dict name -> those.

    A plain function is assumed to read the signals ``default_reads`` (a study passes the measured
    outputs, which are then evaluated for whole chunks at once).

    Raises
    ------
    InputDataError
        For an unnamed function (a lambda: give it a name in a dict), clashing column names or a
        reserved column name (``run``, ``status``, ``error``).

    Examples
    --------
    >>> [m.name for m in as_metrics({"stroke": "final:x", "top": lambda res: 1.0})]
    ['stroke', 'top']
    """
    out = []
    items = metrics.items() if isinstance(metrics, dict) else [(None, m) for m in (metrics or ())]
    for name, m in items:
        if isinstance(m, Metric):
            mm = m if name is None or name == m.name else replace(
                m, name=name, columns=() if len(m.columns) == 1 else m.columns)
        elif isinstance(m, str):
            mm = metric(m, recording)
            if name is not None:
                mm = replace(mm, name=name, columns=() if len(mm.columns) == 1 else mm.columns)
        elif callable(m):
            label = name or getattr(m, "__name__", "")
            if not label or label == "<lambda>":
                raise InputDataError("a metric function needs a name: pass metrics as a dict {name: function}")
            mm = Metric(label, m, reads=tuple(default_reads))
        else:
            raise InputDataError(f"metric {m!r}: give a Metric, a specification such as 'peak:tip' or a function")
        out.append(mm)
    seen: dict = {}
    for m in out:
        for c in m.columns:
            if c in RESERVED:
                raise InputDataError(f"metric {m.name!r}: column name {c!r} is reserved")
            if c in seen:
                raise InputDataError(f"metrics {seen[c]!r} and {m.name!r} both write a column {c!r}")
            seen[c] = m.name
    return out


def column_units(system, metrics, variables) -> dict[str, str]:
    """Units of a study's columns by name: parameters' declared units, metrics' units (or the unit of
    the signal they read); columns of unknown unit are left out.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> column_units(rc_circuit(), [peak("v_C"), energy()], ["R.R", "V"])
    {'R.R': 'Ohm', 'peak_v_C': 'V', 'energy': 'J'}
    """
    s = system
    signals = {p.name: p.unit for p in s.params}
    signals.update({x.name: x.unit for x in s.states})
    signals.update({i.name: i.unit for i in s.inputs})
    signals.update({i.output: i.output_unit for i in s.inputs})
    signals.update({m.name: m.unit for m in s.measured})
    out = {v: signals[v] for v in variables if signals.get(v)}
    for m in metrics:
        unit = m.unit or signals.get(m.unit_of, "")
        if unit:
            out.update({c: unit for c in m.columns})
    return out
