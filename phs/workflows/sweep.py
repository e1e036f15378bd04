"""Design-space sweeps and ensembles: many simulations of one model, one row of metrics per run.

A :class:`Study` is a system, a time grid, inputs, the runs' variables (a
full-factorial ``grid`` of values, ``samples`` drawn from ``distributions`` by
Latin hypercube or plain random sampling, or both: every grid point combined
with every sample) and :mod:`metrics <phs.workflows.sweep_metrics>`.
:func:`sweep` evaluates it:

* on one machine (default) in chunks through :class:`codegen.batch.BatchSimulator`:
  CasADi ``map`` over the generated integrators in threads, results straight
  into numpy, with a progress bar;
* on Dask (``dask.distributed``): a local cluster of worker processes
  (``processes=N``) or any scheduler (``scheduler="tcp://host:8786"`` or a
  ``Client``).  Each task runs a chunk of many simulations; the batch evaluator
  is sent once to every worker with the model's generated functions in
  CasADi's serialization, so workers never re-derive the model symbolically.

Results go to a Parquet or CSV file as runs finish, one row per run
(variables, metric columns, ``status``, ``error``); an interrupted study
resumes where it stopped (:mod:`phs.workflows.sweep_store`), and a run that
fails (integrator failure, validity domain left, a metric raising) is recorded
with its error without stopping the study.

Examples
--------
>>> import numpy as np
>>> from systems.examples import rc_circuit
>>> study = Study(rc_circuit(), np.linspace(0, 0.04, 4001), u={"U": 1.0},
...               grid={"R.R": [500.0, 1000.0, 2000.0]}, metrics=["rise_time:v_C"])
>>> res = sweep(study, threads=2, progress=False)
>>> np.round(res["rise_time_v_C"] / res["R.R"] / 1e-6, 3)   # ln(9) R C
array([2.197, 2.197, 2.197])
"""

from __future__ import annotations

import itertools
import math
import os
import re
import time as _time
from collections.abc import Callable, Sequence

import numpy as np

from phs.errors import InputDataError, ParameterError, PHSError
from phs.workflows.sweep_design import (
    LogNormal,
    LogUniform,
    MultivariateNormal,
    Normal,
    Uniform,
    _unit_samples,
    from_fit,
)
from phs.workflows.sweep_metrics import Metric, as_metrics
from phs.workflows.sweep_store import ResultStore, read_rows

__all__ = ["Study", "StudyResult", "sweep", "Uniform", "LogUniform", "Normal", "LogNormal", "MultivariateNormal",
           "from_fit"]

_MEMORY_PER_CHUNK = 128e6  # bytes of trajectories held per chunk (the chunk size follows from it)


# -- the study -----------------------------------------------------------------------------------------
class Study:
    """A design study: one system, runs differing in parameters (and inputs or initial states), metrics.

    Parameters
    ----------
    system : PHSystem
    t : array, optional
        Output times of every run (default: the recording's when ``u`` is a Recording).
    u : input specification or Recording, optional
        Inputs of every run, as for :meth:`codegen.simulator.Simulator.run`; a
        :class:`~phs.workflows.recording.Recording` gives its sampled inputs (and its grid).
    u_for : callable, optional
        ``u_for(values) -> inputs`` of a run from its variable values (a dict), for studies varying an
        input (amplitude, frequency); instead of ``u``.
    x0, x0_for
        Initial state of every run, or ``x0_for(values) -> x0`` of each run.
    params : dict, optional
        Fixed parameter overrides.
    grid : dict of str -> sequence of float, optional
        Full-factorial grid: every combination of these values (the first name varies slowest).
    distributions : dict, optional
        ``{name: distribution}`` (:class:`Uniform`, :class:`LogUniform`, :class:`Normal`,
        :class:`LogNormal`) and ``{(name, ...): MultivariateNormal}`` (e.g. :func:`from_fit`).
    samples : int
        Number of samples drawn from ``distributions`` (each combined with every grid point).
    sampling : {"lhs", "random"}
        Latin hypercube (default) or plain random sampling.
    seed : int
        Seed of the sampling (the design is reproducible).
    metrics : sequence or dict
        :class:`~phs.workflows.sweep_metrics.Metric` objects, specifications such as ``"peak:tip"``,
        ``"rise_time:tip"``, ``"energy"``, ``"passivity_margin"``, or named functions of the result
        (a dict ``{name: function}``).
    rtol, atol, max_steps, compile
        Integrator settings (:class:`codegen.simulator.Simulator`).
    energy : bool, optional
        Integrate the energy accounts (default: when a metric needs them).

    Variables are parameters of the system or, with ``u_for``/``x0_for``, any other name those
    functions read.

    Raises
    ------
    ParameterError
        Naming a variable that is neither a parameter nor read by ``u_for``/``x0_for``.
    InputDataError
        For an invalid grid, distribution, metric, signal name or time grid (naming it).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import mass_spring_damper
    >>> study = Study(mass_spring_damper(), np.linspace(0, 5, 201), u={"F": 1.0},
    ...               grid={"k.K": [1.0, 2.0]}, distributions={"b.b": Uniform(0.2, 0.4)}, samples=3,
    ...               metrics=["peak:position", "energy"])
    >>> study.n_runs, study.variables, study.columns
    (6, ['k.K', 'b.b'], ['k.K', 'b.b', 'peak_position', 'energy'])
    """

    def __init__(self, system, t=None, *, u=None, u_for: Callable | None = None, x0=None, x0_for: Callable | None = None,
                 params: dict | None = None, grid: dict | None = None, distributions: dict | None = None,
                 samples: int = 0, sampling: str = "lhs", seed: int = 0, metrics=(), rtol: float = 1e-8,
                 atol: float | None = None, max_steps: int = 20000, compile: bool = False, energy: bool | None = None):
        from phs.system import PHSystem
        from phs.workflows.recording import Recording

        if not isinstance(system, PHSystem):
            raise InputDataError(f"Study needs a PHSystem, got {type(system).__name__}")
        self.system = system
        if u is not None and u_for is not None:
            raise InputDataError("give the inputs either as u (all runs) or as u_for (per run), not both")
        if x0 is not None and x0_for is not None:
            raise InputDataError("give the initial state either as x0 (all runs) or as x0_for (per run), not both")
        for name, fn in (("u_for", u_for), ("x0_for", x0_for)):
            if fn is not None and not callable(fn):
                raise InputDataError(f"{name} must be a function of the run's variable values")
        recording = None
        if isinstance(u, Recording):
            from phs.signals import Sampled

            recording = u
            missing = [n for n in system.input_names if n not in u.names]
            if missing:
                raise InputDataError(f"recording {u.source!r} has no input {missing[0]!r} of {system.name!r}")
            t = u.t if t is None else t
            u = {n: Sampled(tuple(recording.t), tuple(recording[n])) for n in system.input_names}
        if isinstance(u, (list, tuple)):
            u = np.asarray(u, dtype=float)
        if t is None:
            raise InputDataError("Study needs a time grid t (or a Recording as u)")
        t = np.array(t, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise InputDataError("the study's time grid t must be a finite, strictly increasing 1-D array of >= 2 times")
        if recording is not None and not np.array_equal(t, recording.t):
            raise InputDataError(f"the study's grid differs from the recording {recording.source!r}'s")
        t.setflags(write=False)
        self.t = t
        self.u, self.u_for, self.x0, self.x0_for = u, u_for, x0, x0_for
        self.params = {k: float(v) for k, v in dict(params or {}).items()}
        system.param_vector(self.params)  # ParameterError naming an unknown or non-finite one
        self.recording = recording

        # -- variables ---------------------------------------------------------------------------------
        grid = dict(grid or {})
        axes = {}
        for name, values in grid.items():
            arr = np.asarray(values, dtype=float).reshape(-1)
            if arr.size == 0 or not np.all(np.isfinite(arr)):
                raise InputDataError(f"grid {name!r}: give at least one finite value")
            axes[str(name)] = arr
        marginals = []  # (names, distribution)
        for key, dist in dict(distributions or {}).items():
            names = (key,) if isinstance(key, str) else tuple(key)
            if not hasattr(dist, "transform") or getattr(dist, "dim", None) != len(names):
                raise InputDataError(f"distribution of {', '.join(names)}: expected a distribution of {len(names)} "
                                     f"variable(s), got {dist!r}")
            marginals.append((names, dist))
        sampled = [n for names, _ in marginals for n in names]
        self.variables = list(axes) + sampled
        dup = sorted({v for v in self.variables if self.variables.count(v) > 1})
        if dup:
            raise InputDataError(f"variable {dup[0]!r} is given twice (grid and distributions)")
        for v in self.variables:
            if v in self.params:
                raise InputDataError(f"variable {v!r} is also fixed by params; give it one way")
            if v not in system.param_names and u_for is None and x0_for is None:
                raise ParameterError(f"study variable {v!r} is not a parameter of {system.name!r} (known: "
                                     f"{', '.join(system.param_names)}); other variables need u_for or x0_for")
        if not isinstance(samples, (int, np.integer)) or samples < 0:
            raise InputDataError(f"samples must be a non-negative integer, got {samples!r}")
        if marginals and samples == 0:
            raise InputDataError("distributions are given but samples is 0: say how many samples to draw")
        if samples and not marginals:
            raise InputDataError(f"samples={samples} but no distributions to draw them from")
        if sampling not in ("lhs", "random"):
            raise InputDataError(f"sampling must be 'lhs' or 'random', got {sampling!r}")
        self.samples, self.sampling, self.seed = int(samples), sampling, int(seed)
        self.grid, self.distributions = axes, marginals
        self.design = self._design()
        self.n_runs = len(next(iter(self.design.values()))) if self.design else 1

        # -- metrics -----------------------------------------------------------------------------------
        self.metrics: list[Metric] = as_metrics(metrics, recording, default_reads=tuple(system.measured_names))
        if not self.metrics:
            raise InputDataError("a study needs at least one metric")
        for m in self.metrics:
            for c in m.columns:
                if c in self.variables:
                    raise InputDataError(f"metric column {c!r} has the name of a variable")
            if m.grid is not None and not np.array_equal(np.asarray(m.grid), t):
                raise InputDataError(f"metric {m.name!r} needs the recording's time grid; run the study on it "
                                     f"(give the recording as u)")
        kinds = list(dict.fromkeys(k for m in self.metrics for s in m.reads for k in [_signal_kind(system, s, m.name)] if k))
        measured = [k for k in kinds if k in system.measured_names]
        if measured and len(measured) == len(system.measured_names):  # every measured output: one function
            kinds = ["measured"] + [k for k in kinds if k not in system.measured_names]
        self.batch_signals = tuple(kinds)
        self.columns = self.variables + [c for m in self.metrics for c in m.columns]
        self.options = {"rtol": rtol, "atol": atol, "max_steps": max_steps, "compile": compile,
                        "energy": bool(energy) if energy is not None else any(m.energy for m in self.metrics)}

    def _design(self) -> dict[str, np.ndarray]:
        names = list(self.grid)
        points = list(itertools.product(*self.grid.values())) if names else [()]
        dim = sum(d.dim for _, d in self.distributions)
        if self.samples:
            q = _unit_samples(self.samples, dim, self.sampling, self.seed)
            cols, k = [], 0
            for _, d in self.distributions:
                cols.append(d.transform(q[:, k:k + d.dim]))
                k += d.dim
            S = np.hstack(cols)
        else:
            S = np.zeros((1, 0))
        n = len(points) * len(S)
        out = {}
        for i, name in enumerate(names):
            out[name] = np.repeat(np.array([p[i] for p in points], dtype=float), len(S))
        for j, name in enumerate(n for names_, _ in self.distributions for n in names_):
            out[name] = np.tile(S[:, j], len(points))
        for name, v in out.items():
            if not np.all(np.isfinite(v)):
                raise InputDataError(f"the sampled values of {name!r} are not all finite")
        assert all(len(v) == n for v in out.values())
        return out

    def values(self, run: int) -> dict[str, float]:
        """Variable values of run number ``run``.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> Study(rc_circuit(), [0, 1e-3], grid={"R.R": [1e3, 2e3]}, metrics=["final:v_C"]).values(1)
        {'R.R': 2000.0}
        """
        return {k: float(v[run]) for k, v in self.design.items()}

    def __repr__(self) -> str:
        return (f"Study({self.system.name!r}, {self.n_runs} runs, variables {self.variables}, "
                f"metrics {[m.name for m in self.metrics]})")


def _signal_kind(system, name: str, metric: str) -> str | None:
    """The batch signal that holds ``name`` (None: states, inputs and per-element signals computed on demand)."""
    if name in system.state_names or name in system.input_names:
        return None
    if name in system.measured_names:
        return name  # evaluated alone for whole chunks
    if name in system.output_names:
        return "output"
    if name == "H":
        return "hamiltonian"
    if name in ("supplied", "dissipated", "dHdt"):
        return "power"
    if name in [t.label for t in system.energy_terms] or name in [label for label, _ in system.dissipators]:
        return None
    known = system.state_names + system.input_names + system.output_names + system.measured_names
    raise InputDataError(f"metric {metric!r} reads {name!r}, which is not a signal of {system.name!r} "
                         f"(signals: {', '.join(known + ['H', 'supplied', 'dissipated'])})")


# -- evaluation of chunks (in this process or on Dask workers) ------------------------------------------
class _Evaluator:
    """Evaluates chunks of runs of a study: batch simulation, then metrics; picklable for Dask workers."""

    def __init__(self, study: Study, threads: int | None):
        from codegen.batch import BatchSimulator

        self.system = study.system
        self.u, self.u_for, self.x0, self.x0_for = study.u, study.u_for, study.x0, study.x0_for
        self.params = study.params
        self.param_names = set(study.system.param_names)
        self.metrics = study.metrics
        self.signals = study.batch_signals
        self.batch = BatchSimulator(study.system, study.t, threads=threads, **study.options)

    def __call__(self, runs: Sequence[tuple[int, dict]]) -> list[dict]:
        from codegen.batch import LOCK

        with LOCK:  # the metrics may build CasADi functions too (signals computed on demand)
            return self._evaluate(runs)

    def _evaluate(self, runs: Sequence[tuple[int, dict]]) -> list[dict]:
        rows: dict[int, dict] = {}
        todo, params, us, x0s = [], [], [], []
        for run, values in runs:
            try:
                u = self.u_for(values) if self.u_for is not None else self.u
                x0 = self.x0_for(values) if self.x0_for is not None else self.x0
            except Exception as exc:  # a user's function: its failure is this run's
                rows[run] = self._failed(run, values, f"preparing the run's inputs failed: {_describe(exc)}")
                continue
            todo.append((run, values))
            params.append({**self.params, **{k: v for k, v in values.items() if k in self.param_names}})
            us.append(u)
            x0s.append(x0)
        if todo:
            res = self.batch.run(params, u=us if self.u_for is not None else self.u,
                                 x0=x0s if self.x0_for is not None else self.x0, signals=self.signals, n=len(todo))
            for pos, (run, values) in enumerate(todo):
                err = res.errors[pos]
                rows[run] = self._failed(run, values, _describe(err)) if err is not None else \
                    self._measure(run, values, res[pos])
        return [rows[run] for run, _ in runs]

    def _failed(self, run, values, message) -> dict:
        row = {"run": int(run), **values}
        for m in self.metrics:
            row.update(dict.fromkeys(m.columns, float("nan")))
        row.update(status="failed", error=message)
        return row

    def _measure(self, run, values, result) -> dict:
        row = {"run": int(run), **values}
        errors = []
        for m in self.metrics:
            try:
                with np.errstate(all="ignore"):
                    row.update(zip(m.columns, m(result)))
            except Exception as exc:  # a metric (possibly the user's) failing is recorded for this run
                row.update(dict.fromkeys(m.columns, float("nan")))
                errors.append(f"metric {m.name!r}: {_describe(exc)}")
        row.update(status="failed" if errors else "ok", error="; ".join(errors))
        return row


def _describe(exc: BaseException) -> str:
    text = str(exc).replace("\n  - ", "; ").replace("\n", " ")
    return text if isinstance(exc, PHSError) else f"{type(exc).__name__}: {text}"


def _evaluate_chunk(evaluator: _Evaluator, runs) -> list[dict]:
    """Task function of the Dask executor (module level, so workers import it by name)."""
    return evaluator(runs)


# -- results ---------------------------------------------------------------------------------------------
class StudyResult:
    """The rows of a study: one per run, as columns.

    Attributes
    ----------
    columns : dict of str -> array
        ``run``, the variables, the metric columns, ``status`` and ``error``.
    variables, metrics : list of str
        Variable columns and metric columns.
    path : str or None
        The results file.
    seconds : float
        Wall time of the evaluation that produced the new rows.
    new_runs : int
        Runs evaluated by that evaluation (the others came from a resumed file).

    ``result[name]`` is a column; ``len(result)`` the number of runs.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> study = Study(rc_circuit(), np.linspace(0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": [1e3, 2e3]},
    ...               metrics=["final:v_C"])
    >>> res = sweep(study, threads=1, progress=False)
    >>> len(res), res.ok.tolist(), [round(float(v), 4) for v in res["final_v_C"]]
    (2, [True, True], [0.6321, 0.3935])
    """

    def __init__(self, columns: dict, variables: list[str], metrics: list[str], path=None, seconds: float = 0.0,
                 new_runs: int = 0, system_name: str = ""):
        self.columns = columns
        self.variables = list(variables)
        self.metrics = list(metrics)
        self.path = path
        self.seconds = float(seconds)
        self.new_runs = int(new_runs)
        self.system_name = system_name

    @classmethod
    def read(cls, path) -> StudyResult:
        """Read a results file written by :func:`sweep` (Parquet files carry the variables' names;
        for CSV every numeric column is listed as a metric).

        Examples
        --------
        >>> import os, tempfile
        >>> from systems.examples import rc_circuit
        >>> study = Study(rc_circuit(), [0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3]}, metrics=["final:v_C"])
        >>> with tempfile.TemporaryDirectory() as d:
        ...     _ = sweep(study, out=os.path.join(d, "r.parquet"), progress=False)
        ...     StudyResult.read(os.path.join(d, "r.parquet")).variables
        ['R.R']
        """
        rows, meta = read_rows(path)
        names = list(rows[0]) if rows else ["run", "status", "error"]
        numeric = [c for c in names if c not in ("run", "status", "error")]
        variables = [v for v in meta.get("variables", []) if v in numeric]
        metrics = [c for c in numeric if c not in variables]
        rows.sort(key=lambda r: int(r["run"]))
        cols = {"run": np.array([int(r["run"]) for r in rows], dtype=np.int64)}
        for c in numeric:
            cols[c] = np.array([float(r[c]) for r in rows], dtype=float)
        cols["status"] = np.array([r["status"] for r in rows], dtype=object)
        cols["error"] = np.array([r["error"] for r in rows], dtype=object)
        return cls(cols, variables, metrics, path=os.fspath(path), system_name=meta.get("system", ""))

    def __len__(self) -> int:
        return len(self.columns["run"])

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns)}") from None

    @property
    def ok(self) -> np.ndarray:
        """Boolean array: runs whose simulation and metrics succeeded."""
        return self.columns["status"] == "ok"

    @property
    def failed(self) -> list[tuple[int, str]]:
        """``(run, error)`` of every failed run."""
        bad = ~self.ok
        return [(int(r), str(e)) for r, e in zip(self.columns["run"][bad], self.columns["error"][bad])]

    def to_pandas(self):
        """The rows as a pandas DataFrame (needs pandas)."""
        import pandas as pd

        return pd.DataFrame(self.columns)

    def summary(self) -> str:
        """Counts, throughput and the range of each metric over the successful runs."""
        n, ok = len(self), int(self.ok.sum())
        lines = [f"Study of {self.system_name or 'a model'}: {n} runs, {ok} ok, {n - ok} failed"
                 + (f"; {self.new_runs} evaluated in {self.seconds:.2f} s ({self.new_runs / self.seconds:.1f} runs/s)"
                    if self.new_runs and self.seconds > 0 else "")]
        many = len(self.metrics) > 12
        for i, c in enumerate(self.metrics[:5] + self.metrics[-5:] if many else self.metrics):
            if many and i == 5:
                lines.append(f"  ... {len(self.metrics) - 10} more metric columns")
            v = self.columns[c][self.ok]
            v = v[np.isfinite(v)]
            if len(v):
                lines.append(f"  {c:<24} min {v.min():<12.6g} median {np.median(v):<12.6g} max {v.max():.6g}")
            else:
                lines.append(f"  {c:<24} no finite value")
        kinds: dict[str, int] = {}
        for _, e in self.failed:  # failures grouped by their message without numbers and state
            key = re.sub(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?", "#", e.split("; state")[0].split("; last state")[0])
            kinds[key] = kinds.get(key, 0) + 1
        for e, k in sorted(kinds.items(), key=lambda kv: -kv[1])[:5]:
            lines.append(f"  failed ({k} runs): {e[:160]}")
        return "\n".join(lines)

    __str__ = summary

    def plot(self, path=None, metrics: Sequence[str] | None = None, variables: Sequence[str] | None = None):
        """Each metric against each variable (failed runs as red crosses on the lower edge).

        With two or more variables, points are coloured by the next variable.  Returns the
        matplotlib figure (saved to ``path`` when given).
        """
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        metrics = list(metrics or self.metrics)
        variables = list(variables or self.variables)
        unknown = [c for c in metrics + variables if c not in self.columns]
        if unknown:
            raise InputDataError(f"plot: no column {unknown[0]!r}")
        if not metrics or not variables:
            raise InputDataError("plot: need at least one metric and one variable column")
        fig = Figure(figsize=(3.4 * len(variables) + 0.8, 2.6 * len(metrics)), constrained_layout=True)
        FigureCanvasAgg(fig)
        axes = fig.subplots(len(metrics), len(variables), squeeze=False)
        ok = self.ok
        for i, m in enumerate(metrics):
            y = self.columns[m]
            good = ok & np.isfinite(y)
            lo = np.min(y[good]) if good.any() else 0.0
            for j, v in enumerate(variables):
                ax = axes[i, j]
                x = self.columns[v]
                other = variables[(j + 1) % len(variables)] if len(variables) > 1 else None
                if other is not None and good.any():
                    sc = ax.scatter(x[good], y[good], c=self.columns[other][good], s=12, cmap="viridis")
                    if i == 0:
                        fig.colorbar(sc, ax=ax, label=other)
                else:
                    ax.scatter(x[good], y[good], s=12)
                if (~ok).any():
                    ax.scatter(x[~ok], np.full(int((~ok).sum()), lo), marker="x", color="red", s=18,
                               label="failed" if (i, j) == (0, 0) else None)
                if i == len(metrics) - 1:
                    ax.set_xlabel(v)
                if j == 0:
                    ax.set_ylabel(m)
                ax.grid(True, alpha=0.3)
        if (~ok).any():
            axes[0, 0].legend(fontsize="small")
        fig.suptitle(f"{self.system_name}: {len(self)} runs ({int((~ok).sum())} failed)")
        if path is not None:
            fig.savefig(path, dpi=100)
        return fig

    def __repr__(self) -> str:
        return f"StudyResult({len(self)} runs, {int(self.ok.sum())} ok, columns {list(self.columns)})"


# -- running a study ---------------------------------------------------------------------------------------
def _chunk_size(study: Study, n_todo: int, workers: int) -> int:
    s = study.system
    nq = 2 + len(s.dissipators) if study.options["energy"] else 0
    width = 2 * len(s.states) + nq + 2 * len(s.inputs) + len(s.conditions) + len(s.measured) + len(s.inputs) + 3
    per_run = 8.0 * len(study.t) * width
    by_memory = max(1, int(_MEMORY_PER_CHUNK // per_run))
    balance = max(1, math.ceil(n_todo / (4 * workers)))  # several chunks per worker: progress and balance
    return max(1, min(by_memory, balance, 256))


def _chunks(todo: list, size: int, exact: bool = False) -> list[list]:
    """Split the runs into chunks of ``size``, or of a slightly smaller size that divides their number
    (every chunk size builds its own mapped functions and work memory once)."""
    if not exact:
        for s in range(size, max(1, math.ceil(0.6 * size)) - 1, -1):
            if len(todo) % s == 0:
                size = s
                break
    return [todo[i:i + size] for i in range(0, len(todo), size)]


class _Progress:
    """A tqdm progress bar over runs counting the failed ones (nothing when disabled or tqdm is missing)."""

    def __init__(self, total: int, enabled: bool, name: str):
        self.bar, self.failed = None, 0
        if enabled and total:
            try:
                from tqdm.auto import tqdm
            except ImportError:  # the study runs without a bar
                return
            self.bar = tqdm(total=total, unit="run", desc=f"sweep {name}", smoothing=0.1)

    def update(self, rows) -> None:
        if self.bar is None:
            return
        self.failed += sum(r["status"] != "ok" for r in rows)
        if self.failed:
            self.bar.set_postfix(failed=self.failed, refresh=False)
        self.bar.update(len(rows))

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def sweep(study: Study, out=None, *, resume: bool = False, retry_failed: bool = False, threads: int | None = None,
          processes: int | None = None, scheduler=None, chunk_size: int | None = None, progress: bool = True,
          flush_seconds: float = 5.0) -> StudyResult:
    """Evaluate every run of ``study``; write the rows to ``out`` as they finish.

    Parameters
    ----------
    study : Study
    out : str, optional
        Results file, ``.parquet`` or ``.csv``; without it the rows stay in memory.
    resume : bool
        Continue a study whose file (or the parts of an interrupted run) exists: finished runs are
        kept, only missing ones run.  Without it an existing file is an error (nothing is overwritten).
    retry_failed : bool
        With ``resume``, run the failed runs again.
    threads : int, optional
        Threads of the batched evaluation (default: the processors available; 1 runs the runs one
        after the other through the same functions).  With Dask: threads per task (default 1).
    processes : int, optional
        Evaluate on a local Dask cluster of this many worker processes (one thread each).
    scheduler : str or distributed.Client, optional
        Evaluate on a Dask cluster: its scheduler's address (``"tcp://host:8786"``) or a client.
    chunk_size : int, optional
        Runs per chunk (per Dask task); default from the memory a run's trajectories take.
    progress : bool
        Show a progress bar (on stderr).
    flush_seconds : float
        How often the results file is rewritten from the finished runs (parts are written at once).

    Returns
    -------
    StudyResult
        Every run of the study (including those found in a resumed file).

    Raises
    ------
    InputDataError
        When ``out`` exists without ``resume``, holds another study, has an unknown suffix, or the
        Dask scheduler cannot be reached.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> study = Study(rc_circuit(), np.linspace(0, 2e-3, 21), u={"U": 1.0},
    ...               distributions={"C.C": LogUniform(5e-7, 2e-6)}, samples=4, metrics=["energy"])
    >>> res = sweep(study, progress=False)
    >>> bool(np.allclose(res["energy"], res["C.C"] * (1 - np.exp(-2e-3 / (1e3 * res["C.C"])))))
    True
    """
    if not isinstance(study, Study):
        raise InputDataError(f"sweep needs a Study, got {type(study).__name__}")
    if scheduler is not None and processes is not None:
        raise InputDataError("give either processes (a local Dask cluster) or scheduler (an existing one), not both")
    for name, v in (("threads", threads), ("processes", processes), ("chunk_size", chunk_size)):
        if v is not None and (not isinstance(v, (int, np.integer)) or v < 1):
            raise InputDataError(f"{name} must be a positive integer, got {v!r}")
    numeric = study.columns
    import casadi

    import phs

    meta = {"system": study.system.name, "model_hash": study.system.model_hash(), "phs_version": phs.__version__,
            "casadi_version": casadi.__version__, "variables": study.variables,
            "metrics": [c for m in study.metrics for c in m.columns], "n_runs": study.n_runs, "seed": study.seed,
            "sampling": study.sampling, "samples": study.samples}

    def design(run):
        return study.values(run) if 0 <= run < study.n_runs else None

    store = ResultStore(out, numeric, design, study.variables, resume=resume, retry_failed=retry_failed,
                        metadata=meta, flush_seconds=flush_seconds)
    todo = [k for k in range(study.n_runs) if k not in store.done]
    distributed = scheduler is not None or processes is not None
    wall = _time.perf_counter()
    bar = _Progress(len(todo), progress, study.system.name)
    try:
        if todo:
            if distributed:
                _run_dask(study, todo, store, bar, scheduler, processes, threads or 1, chunk_size)
            else:
                from codegen.batch import default_threads

                n_threads = threads or default_threads()
                size = chunk_size or _chunk_size(study, len(todo), n_threads)
                ev = _Evaluator(study, n_threads)
                for chunk in _chunks(todo, size, exact=chunk_size is not None):
                    rows = ev([(k, study.values(k)) for k in chunk])
                    store.add(rows)
                    bar.update(rows)
    finally:
        bar.close()
        store.close()
    seconds = _time.perf_counter() - wall
    metrics = [c for m in study.metrics for c in m.columns]
    return StudyResult(store.table(), study.variables, metrics, path=store.path, seconds=seconds,
                       new_runs=len(todo), system_name=study.system.name)


def _run_dask(study, todo, store, bar, scheduler, processes, threads, chunk_size) -> None:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise InputDataError("the Dask executor needs dask.distributed: pip install 'dask[distributed]'") from None
    cluster = None
    owned = False
    if isinstance(scheduler, Client):
        client = scheduler
    else:
        owned = True
        try:
            if scheduler is not None:
                client = Client(scheduler, timeout="20s")
            else:
                cluster = LocalCluster(n_workers=processes, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40)
                client = Client(cluster)
        except (OSError, TimeoutError) as exc:
            raise InputDataError(f"cannot reach the Dask scheduler {scheduler or 'of the local cluster'}: {exc}") from None
    try:
        workers = max(1, len(client.scheduler_info().get("workers", {})) or (processes or 1))
        size = chunk_size or _chunk_size(study, len(todo), workers)
        chunks = _chunks(todo, size, exact=chunk_size is not None)
        [ev] = client.scatter([_Evaluator(study, threads)], broadcast=True)
        pending = iter(chunks)
        runs_of = {}

        def submit():
            chunk = next(pending, None)
            if chunk is None:
                return None
            fut = client.submit(_evaluate_chunk, ev, [(k, study.values(k)) for k in chunk], pure=False)
            runs_of[fut.key] = chunk
            return fut

        window = [f for f in (submit() for _ in range(2 * workers + 2)) if f is not None]
        queue = as_completed(window)
        for fut in queue:
            chunk = runs_of.pop(fut.key)
            try:
                rows = fut.result()
            except Exception as exc:  # a task lost with its worker, or failing outside any run
                rows = [_task_failed(study, k, exc) for k in chunk]
            store.add(rows)
            bar.update(rows)
            nxt = submit()
            if nxt is not None:
                queue.add(nxt)
    finally:
        if owned:
            client.close()
            if cluster is not None:
                cluster.close()


def _task_failed(study, run, exc) -> dict:
    row = {"run": int(run), **study.values(run)}
    for m in study.metrics:
        row.update(dict.fromkeys(m.columns, float("nan")))
    row.update(status="failed", error=f"the Dask task of this run failed: {_describe(exc)}")
    return row
