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

    Variables are parameters of the system or, with ``u_for``/``x0_for``, any other name those
    functions read.

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

    def identity(self) -> dict:
        """What makes this study the one it is, as stored with its results and compared on resume.

        Fields: ``model_hash`` (structure and parameter names), ``params`` (every parameter's value
        with the fixed overrides), ``inputs`` (a description and ``inputs_digest``, a digest of the
        inputs sampled on the grid and between its points, for the first and last run), the time grid
        (``t_start``, ``t_end``, ``samples``, ``t_digest``), ``x0``, the tolerances (``rtol``,
        ``atol``, ``max_steps``), ``metrics`` (their columns) and the design (``variables``,
        ``n_runs``, ``seed``, ``sampling``, ``samples_drawn``, ``design_digest`` of every run's values).  Resuming compares them with
        :func:`identity_differences`.

        Examples
        --------
        >>> from systems.examples import rc_circuit
        >>> a = Study(rc_circuit(), [0, 1e-3], u={"U": 1.0}, grid={"R.R": [1e3, 2e3]}, metrics=["final:v_C"])
        >>> b = Study(rc_circuit(), [0, 2e-3], u={"U": 1.0}, grid={"R.R": [1e3, 2e3]}, metrics=["final:v_C"])
        >>> a.identity()["metrics"], identity_differences(a.identity(), b.identity())
        (['final_v_C'], ['t_end stored 0.001, requested 0.002'])
        """
        import hashlib

        from codegen._inputs import input_signals, inputs_at

        def digest(*arrays) -> str:
            h = hashlib.sha256()
            for a in arrays:
                h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
            return h.hexdigest()[:16]

        t = self.t
        times = np.sort(np.concatenate([t, 0.5 * (t[1:] + t[:-1])]))
        samples = []
        for run in sorted({0, self.n_runs - 1}):
            try:  # a user's function failing for a run fails that run when it runs, not the study here
                u = self.u_for(self.values(run)) if self.u_for is not None else self.u
                sigs = input_signals(self.system, u, t)
                samples.append(inputs_at(sigs, times - t[0]) if len(sigs) else np.zeros(0))
            except Exception:  # noqa: BLE001
                samples.append(np.full(1, np.nan))
        if self.x0_for is not None:
            x0 = []
            for run in sorted({0, self.n_runs - 1}):
                try:
                    x0.append(repr(self.x0_for(self.values(run))))
                except Exception as exc:  # noqa: BLE001 - as above
                    x0.append(f"failed: {type(exc).__name__}")
        else:
            x0 = None if self.x0 is None else repr(self.x0)
        shown = self.u_for if self.u_for is not None else self.u
        text = " ".join(repr(shown).split())
        params = self.system.param_values()
        params.update(self.params)
        return {"model_hash": self.system.model_hash(), "params": {k: float(v) for k, v in params.items()},
                "inputs": text if len(text) <= 120 else text[:117] + "...", "inputs_digest": digest(*samples),
                "t_start": float(t[0]), "t_end": float(t[-1]), "samples": len(t), "t_digest": digest(t), "x0": x0,
                "rtol": self.options["rtol"], "atol": self.options["atol"], "max_steps": self.options["max_steps"],
                "metrics": [m.name for m in self.metrics], "variables": list(self.variables), "n_runs": self.n_runs,
                "seed": self.seed, "sampling": self.sampling, "samples_drawn": self.samples,
                "design_digest": digest(*(self.design[v] for v in self.variables))}

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


def identity_differences(stored: dict, requested: dict) -> list[str]:
    """What differs between a stored study identity and a requested one (:meth:`Study.identity`), in words.

    Fields missing from ``stored`` (results written before they were recorded) are not compared;
    a digest is named only when nothing readable differs.

    Examples
    --------
    >>> identity_differences({"params": {"K_b": 0.04}, "rtol": 1e-8}, {"params": {"K_b": 0.08}, "rtol": 1e-6})
    ['parameter K_b stored 0.04, requested 0.08', 'rtol stored 1e-08, requested 1e-06']
    """
    def show(v) -> str:
        if isinstance(v, float):
            return f"{v:.12g}"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(show(x) for x in v) + "]"
        return "none" if v is None else str(v)

    out = []
    for key, want in requested.items():
        if key not in stored:
            continue
        have = stored[key]
        if key == "params" and isinstance(have, dict):
            for name in dict.fromkeys([*have, *want]):
                a, b = have.get(name), want.get(name)
                if a != b:
                    out.append(f"parameter {name} stored {show(a)}, requested {show(b)}")
        elif key == "inputs_digest" and have != want and stored.get("inputs") == requested.get("inputs"):
            out.append(f"inputs (same description, other values on the grid) stored digest {have}, requested {want}")
        elif key == "t_digest" and have != want and not any(stored.get(k) != requested.get(k)
                                                            for k in ("t_start", "t_end", "samples")):
            out.append(f"time grid (same ends and samples, other times) stored digest {have}, requested {want}")
        elif key == "design_digest" and have != want and not any(stored.get(k) != requested.get(k)
                                                                 for k in ("variables", "n_runs", "seed", "sampling",
                                                                          "samples_drawn")):
            out.append(f"design (same variables and runs, other values: another seed, range or sampling) "
                       f"stored digest {have}, requested {want}")
        elif key.endswith("_digest") or key == "inputs":
            if key == "inputs" and stored.get("inputs_digest", want) != requested.get("inputs_digest"):
                out.append(f"inputs stored {show(have)}, requested {show(want)}")
        elif have != want:
            out.append(f"{key} stored {show(have)}, requested {show(want)}")
    return out
