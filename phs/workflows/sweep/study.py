"""A design study: one system, a time grid, inputs, the runs' variables and the metrics of each run."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from phs.errors import InputDataError, ParameterError
from phs.workflows.sweep.design import _unit_samples
from phs.workflows.sweep.metrics import Metric, as_metrics


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
        :class:`~phs.workflows.sweep.metrics.Metric` objects, specifications such as ``"peak:tip"``,
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
    >>> from phs.workflows.sweep import Uniform
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

            recording = u
            missing = [n for n in system.input_names if n not in u.names]
            if missing:
                raise InputDataError(f"recording {u.source!r} has no input {missing[0]!r} of {system.name!r}")
            t = u.t if t is None else t
            u = {n: recording.input_signal(n) for n in system.input_names}
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
