"""Identification from summary statistics: runs known only by a few numbers of their measured channels.

A table of a paper often reports, for each of several experiments, one number per channel: the mean of
a signal over the run, its range ``max - min``, its final value.  Each such experiment is a
:class:`Summary`: the recording of the run's inputs on its time grid, the measured statistics written
``STAT(CHANNEL)`` (``range(tip)``, ``mean(v_C)``), and the parameter values the run had where they differ
from the model's (a setting of the rig, an operating amplitude).  :func:`phs.identify` fits the free
parameters to the statistics of every summary at once (``identify(system, [Summary, ...], free)``) with the
same residual, exact CVODES sensitivities, coordinates, bounds and trust-region solver as a fit to a
recording: each run is simulated on its own (from the same initial state), each statistic and its gradient
is taken of the simulated channel and of its sensitivities, and each row of the least squares is one
statistic of one run, weighted by ``1 / |measured value|`` by default (relative errors) or by a weight per
statistic.  The 95 % intervals use Student's t with (rows − identified directions) degrees of freedom: a
fit to a handful of numbers has few.

Statistics (:data:`STATISTICS`): ``mean`` (of the samples), ``range`` (``max - min``), ``max``, ``min``,
``final`` (the last sample) and ``rms``.  ``range``, ``max`` and ``min`` differentiate through the samples
where the extremes are attained (exact where each extreme is attained at one sample, as on any run not
flat at its extreme).
"""

from __future__ import annotations

import dataclasses
import re
import time as _time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.optimize
import scipy.stats

from codegen.simulator import Simulator
from phs.errors import InputDataError, ParameterError, PHSError, SimulationError
from phs.workflows.identify.coordinates import _bounds, _log_scaled
from phs.workflows.identify.identifiability import analyse, rank_tolerance
from phs.workflows.identify.result import IdentificationResult, _relative_scale, _uncertainty, relative_factor
from phs.workflows.identify.scoring import nrmse_fit
from phs.workflows.identify.sensitivities import _Problem
from phs.workflows.inputs import check_uniform

if TYPE_CHECKING:
    from matplotlib.figure import Figure

STATISTICS = ("mean", "range", "max", "min", "final", "rms")
"""The statistics of a channel a :class:`Summary` may state, as ``STAT(CHANNEL)``."""
_LABEL = re.compile(r"^(" + "|".join(STATISTICS) + r")\(([A-Za-z_][A-Za-z0-9_.]*)\)$")


def _parse(label: str, where: str) -> tuple[str, str]:
    """``(statistic, channel)`` of a label ``STAT(CHANNEL)``, or a one-line InputDataError naming ``where``."""
    m = _LABEL.match(label.replace(" ", "")) if isinstance(label, str) else None
    if m is None:
        raise InputDataError(f"{where}: {label!r} is not a statistic of a channel; write STAT(CHANNEL) with STAT one "
                             f"of {', '.join(STATISTICS)} (e.g. 'range(tip)')")
    return m.group(1), m.group(2)


def statistic(kind: str, y) -> tuple[float, np.ndarray]:
    """Value of the statistic ``kind`` of the samples ``y`` and its gradient with respect to them.

    Examples
    --------
    >>> value, grad = statistic("range", np.array([0.0, 3.0, -1.0, 2.0]))
    >>> value, grad.tolist()
    (4.0, [0.0, 1.0, -1.0, 0.0])
    >>> statistic("mean", np.array([1.0, 2.0, 6.0]))[0]
    3.0
    """
    y = np.asarray(y, dtype=float)
    a = np.zeros(len(y))
    if kind == "mean":
        a[:] = 1.0 / len(y)
    elif kind in ("range", "max"):
        a[int(np.argmax(y))] += 1.0
        if kind == "range":
            a[int(np.argmin(y))] -= 1.0
    elif kind == "min":
        a[int(np.argmin(y))] = 1.0
    elif kind == "final":
        a[-1] = 1.0
    elif kind == "rms":
        rms = float(np.sqrt(np.mean(y**2)))
        return rms, (y / (len(y) * rms) if rms > 0 else a)
    else:
        raise InputDataError(f"unknown statistic {kind!r}; known: {', '.join(STATISTICS)}")
    return float(a @ y), a


@dataclass(frozen=True)
class Summary:
    """One run known by statistics of its channels.

    Parameters
    ----------
    recording : Recording
        The run's inputs on its time grid (uniform; holds as declared); other signals are ignored.
    measured : dict of str -> float
        Measured statistics by label ``STAT(CHANNEL)`` (:data:`STATISTICS`), in the channel's model units.
    params : dict of str -> float, optional
        Parameter values of this run where they differ from the model's (not the fitted ones).
    name : str, optional
        Names the run in messages and results (default ``run{k}`` by position).

    Examples
    --------
    >>> from phs.workflows.recording import Recording
    >>> rec = Recording.from_arrays(np.linspace(0, 1, 11), {"U": np.ones(11)})
    >>> Summary(rec, {"mean(v_C)": 0.7}).labels
    [('mean', 'v_C')]
    >>> Summary(rec, {"average(v_C)": 0.7})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: summary '': 'average(v_C)' is not a statistic of a channel; write STAT(CHANNEL) with ...
    """

    recording: object
    measured: dict
    params: dict = field(default_factory=dict)
    name: str = ""

    def __post_init__(self):
        where = f"summary {self.name!r}"
        if not isinstance(self.measured, dict) or not self.measured:
            raise InputDataError(f"{where}: measured must be a non-empty dict STAT(CHANNEL) -> value")
        for label, v in self.measured.items():
            _parse(label, where)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not np.isfinite(v):
                raise InputDataError(f"{where}: the measured {label} is {v!r}, not a finite number")
        if not hasattr(self.recording, "t") or not hasattr(self.recording, "input_signal"):
            raise InputDataError(f"{where}: recording must be a Recording of the run's inputs, got {type(self.recording).__name__}")

    @property
    def labels(self) -> list[tuple[str, str]]:
        """``(statistic, channel)`` of each measured statistic, in order."""
        return [_parse(k, f"summary {self.name!r}") for k in self.measured]


def is_summaries(data) -> bool:
    """Whether ``data`` is a :class:`Summary` or a non-empty sequence of them (what :func:`phs.identify` fits
    by statistics)."""
    if isinstance(data, Summary):
        return True
    return isinstance(data, (list, tuple)) and len(data) > 0 and all(isinstance(s, Summary) for s in data)


@dataclass(repr=False)
class SummaryFit(IdentificationResult):
    """:class:`IdentificationResult` of a fit to summary statistics: one row per statistic of a run.

    ``rows`` lists ``(run, label)``; ``measured`` and ``modelled`` the statistics (model units); ``residuals``
    are per label over the runs, and so is ``fit_percent`` (NRMSE fit %) for the labels measured on two runs or
    more; :attr:`relative_errors` is ``modelled / measured - 1``.
    Intervals use Student's t with ``dof`` degrees of freedom.
    """

    rows: list = field(default_factory=list)
    measured: np.ndarray | None = None
    modelled: np.ndarray | None = None
    dof: int = 0

    @property
    def relative_errors(self) -> np.ndarray:
        """``modelled / measured - 1`` per row."""
        return self.modelled / self.measured - 1.0

    def summary(self) -> str:
        rel = self.relative_errors
        lines = [super().summary(), f"  95 % intervals: Student's t, {self.dof} degrees of freedom",
                 f"  RMS of the relative errors: {100 * float(np.sqrt(np.mean(rel**2))):.2f} % over {len(rel)} statistics"]
        for (run, label), m, y in zip(self.rows, self.measured, self.modelled, strict=True):
            lines.append(f"  {run} {label}: measured {m:.6g}, model {y:.6g} ({100 * (y / m - 1) if m else np.nan:+.1f} %)")
        return "\n".join(lines)

    __str__ = summary

    def validate(self, recording) -> dict:
        raise ParameterError("SummaryFit.validate: a fit to summary statistics is validated on other summaries: "
                             "compare summary_statistics(fit.fitted_system, summaries) with their measured values")

    def sensitivity_table(self, recording=None, steps=(-0.10, -0.05, 0.0, 0.05, 0.10), channel=None) -> dict:
        raise ParameterError("SummaryFit.sensitivity_table: the ±5/±10 % table scores a recording's channels; "
                             "a fit to summary statistics has none")

    def plot(self, path=None, recording=None, *, ax=None) -> Figure:
        """Measured and modelled statistics side by side, one bar pair per row (``recording`` is not used)."""
        from phs._results import finish, panels

        fig, grid = panels(ax, 1, figsize=(max(5.0, 0.7 * len(self.rows)), 3.2), what="SummaryFit.plot")
        a, k = grid[0, 0], np.arange(len(self.rows))
        a.bar(k - 0.2, self.measured, 0.4, label="measured", color="0.3")
        a.bar(k + 0.2, self.modelled, 0.4, label="model")
        a.set_xticks(k, [f"{run}\n{label}" for run, label in self.rows], fontsize=7)
        a.legend(fontsize=8)
        return finish(fig, path, dpi=90)


def summary_statistics(system, summaries, x0=None, rtol: float = 1e-8) -> np.ndarray:
    """The statistics of ``summaries`` that ``system`` gives (rows in order, each run from ``x0``).

    Examples
    --------
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.01, 201)
    >>> rec = Recording.from_arrays(t, {"U": np.ones(201)})
    >>> np.round(summary_statistics(rc_circuit(), [Summary(rec, {"final(v_C)": 1.0, "mean(v_C)": 0.9})]), 4)
    array([1.   , 0.898])

    (``1 - mean(exp(-t/RC))`` over the 201 samples: 0.8980.)
    """
    summaries = [summaries] if isinstance(summaries, Summary) else list(summaries)
    sim = Simulator(system, rtol=rtol, energy=False)
    out = []
    for s in summaries:
        rec = s.recording.in_units_of(system)
        res = sim.run(rec.t, u={n: rec.input_signal(n) for n in system.input_names}, x0=x0,
                      params=dict(s.params))
        out += [statistic(kind, res[ch])[0] for kind, ch in s.labels]
    return np.array(out)


def identify_summaries(system, summaries, free, *, bounds=None, x0=None, weights=None, log_scale=None, initial=None,
                       rtol: float = 1e-8, atol: float | None = None, max_iter: int = 100, ftol: float = 1e-8,
                       compile: bool | None = None) -> SummaryFit:
    """What :func:`phs.identify` runs when given summaries (see the module's text); its options as there, and
    ``weights`` a dict label -> weight (per unit of the channel) for the statistics not fitted relative.

    Examples
    --------
    The time constant of an RC circuit from the mean of its capacitor voltage after a step:

    >>> from codegen import simulate
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.01, 201); u = np.where(t >= 0.002, 1.0, 0.0)
    >>> rec = Recording.from_arrays(t, {"U": u}, holds={"U": "zoh"})
    >>> mean = float(np.mean(simulate(rc_circuit(R=2e3), t, u={"U": rec.input_signal("U")})["v_C"]))
    >>> fit = identify_summaries(rc_circuit(), [Summary(rec, {"mean(v_C)": mean})], ["R.R"])
    >>> round(fit.values["R.R"]), fit.dof
    (2000, 0)
    """
    wall = _time.perf_counter()
    summaries = [summaries] if isinstance(summaries, Summary) else list(summaries)
    if not is_summaries(summaries):
        raise InputDataError("identify: summaries must be Summary objects")
    names = [s.name or f"run{k + 1}" for k, s in enumerate(summaries)]
    if len(set(names)) != len(names):
        raise InputDataError(f"identify: summaries need distinct names, got {names}")
    free = list(free)
    if not free:
        raise ParameterError("identify: give at least one free parameter")
    for k in free:
        system.param(k)  # ParameterError naming it
    code, system = system, system.with_params(initial) if initial else system
    log_scaled = _log_scaled(system, free, log_scale)
    x0v = Simulator(code, rtol=rtol, atol=atol).initial_state(x0)
    probs, rows, measured, w = [], [], [], []
    for name, s in zip(names, summaries, strict=True):
        set_free = [k for k in s.params if k in free]
        if set_free:
            raise ParameterError(f"identify: summary {name!r} sets the free parameter(s) {set_free}")
        rec = s.recording.in_units_of(system)
        channels = list(dict.fromkeys(ch for _, ch in s.labels))
        rec = dataclasses.replace(rec, signals={**rec.signals, **{ch: np.zeros(len(rec.t)) for ch in channels}})
        rec.check_for(system, channels)
        check_uniform(rec.t, rec.source, lambda k: f"sample {k}", "t", "; identification needs uniform sampling")
        args = (code, rec, free, log_scaled, channels, dict.fromkeys(channels, 1.0), x0v, [], rtol, atol)
        pv = system.param_vector(s.params)
        try:
            prob = _Problem(*args, compile=compile, params=pv)
        except SimulationError:
            if compile is not None:
                raise
            prob = _Problem(*args, compile=False, params=pv)
        for label, (kind, ch) in zip(s.measured, s.labels, strict=True):
            value = float(s.measured[label])
            if label in (weights or {}):
                wk = float(weights[label])
            elif value != 0:
                wk = 1.0 / abs(value)
            else:
                raise ParameterError(f"identify: summary {name!r} measures {label} = 0, which cannot be fitted as a "
                                     f"relative error; give weights={{{label!r}: ...}}")
            rows.append((name, label, len(probs), channels.index(ch), kind))
            measured.append(value)
            w.append(wk)
        probs.append(prob)
    measured, w = np.array(measured), np.array(w)
    n_theta = len(free)
    nominal = probs[0].nominal
    lo, hi = _bounds(system, free, log_scaled, nominal, bounds, (), None)
    z0 = np.clip([0.0 if k in log_scaled else 1.0 for k in free], np.array(lo) + 1e-12, np.array(hi) - 1e-12)

    def stats(z, with_jac: bool):
        vals, J = np.empty(len(rows)), np.empty((len(rows), n_theta))
        for i, (_, _, j, c, kind) in enumerate(rows):
            prob = probs[j]
            if with_jac:
                r, Jp = prob.jac(z)
            else:
                r = prob.res(z)
            y = np.asarray(r).reshape(-1)[c * prob.N:(c + 1) * prob.N]
            vals[i], a = statistic(kind, y)
            if with_jac:
                J[i] = a @ np.asarray(Jp)[c * prob.N:(c + 1) * prob.N, :n_theta]
        return vals, J

    def fun(z):
        try:
            return w * (stats(z, False)[0] - measured)
        except RuntimeError:  # the simulation failed at this trial point: a large residual rejects it
            return np.full(len(rows), 1e6)

    def jac(z):
        try:
            return w[:, None] * stats(z, True)[1]
        except RuntimeError as exc:
            raise PHSError(f"identify {system.name!r}: the sensitivity simulation failed at parameter values the fit "
                           f"tried ({str(exc).splitlines()[-1]})") from None

    sol = scipy.optimize.least_squares(fun, z0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", ftol=ftol,
                                       xtol=1e-10, gtol=1e-10, max_nfev=max_iter)
    modelled, J = stats(sol.x, True)
    r, J = w * (modelled - measured), w[:, None] * J
    values = probs[0].values(sol.x, log_scaled, free)
    units = {k: system.param(k).unit for k in free}
    std, _, corr, flagged, ident, unident = _uncertainty(r, J, values, nominal, free, log_scaled, 1, rtol, units)
    rank = analyse(J, _relative_scale(n_theta, values, nominal, free, log_scaled), rank_tolerance(rtol))[2]
    dof = len(rows) - rank
    q = float(scipy.stats.t.ppf(0.975, dof)) if dof > 0 else np.inf
    intervals = {}
    for k in free:
        v, s = values[k], std[k]
        if not np.isfinite(s) or not np.isfinite(q):
            intervals[k] = (0.0, np.inf) if k in log_scaled else (-np.inf, np.inf)
        elif k in log_scaled:
            spread = float(np.exp(min(q * s / abs(v), 700.0)))
            intervals[k] = (v / spread, v * spread)
        else:
            intervals[k] = (v - q * s, v + q * s)
    labels = list(dict.fromkeys(label for _, label, *_ in rows))
    by = {lab: np.array([i for i, row in enumerate(rows) if row[1] == lab]) for lab in labels}
    return SummaryFit(
        system=system, free=free, values=values, initial={k: float(system.param(k).value) for k in free},
        std_errors=std, intervals=intervals, correlation=corr, flagged_pairs=flagged,
        fit_percent={lab: nrmse_fit(measured[i], modelled[i]) for lab, i in by.items() if len(i) > 1}, validation_fit_percent={},
        residuals={lab: measured[i] - modelled[i] for lab, i in by.items()}, cost=float(sol.cost),
        iterations=int(sol.nfev), seconds=_time.perf_counter() - wall, x0=x0v, outputs=labels,
        weights={f"{run}:{label}": float(wk) for (run, label, *_), wk in zip(rows, w, strict=True)},
        log_scaled=log_scaled, message=str(sol.message), compiled=all(p.compiled for p in probs),
        identifiable=ident, unidentifiable=unident, factor=relative_factor(J, values, nominal, free, log_scaled),
        rtol=rtol, rows=[(run, label) for run, label, *_ in rows], measured=measured, modelled=modelled, dof=int(dof))


__all__ = ["Summary", "SummaryFit", "STATISTICS", "statistic", "summary_statistics", "identify_summaries", "is_summaries"]
