"""The rows of a study, one per run, as columns: reading, summary and plots."""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from phs._results import ResultMixin, finish, names, panels
from phs.errors import InputDataError
from phs.workflows.figures import axis_label
from phs.workflows.sweep.store import read_rows

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure


class StudyResult(ResultMixin):
    """The rows of a study: one per run, as columns.

    ``result[name]`` is a column; ``len(result)`` the number of runs; :meth:`plot` draws each metric
    against each variable, :meth:`to_pandas` gives one row per run.

    Attributes
    ----------
    columns : dict of str -> array
        ``run``, the variables, the metric columns, ``status`` and ``error``.
    variables : list of str
        Variable columns.
    metrics : list of str
        Metric columns.
    path : str or None
        The results file.
    seconds : float
        Wall time of the evaluation that produced the new rows.
    new_runs : int
        Runs evaluated by that evaluation (the others came from a resumed file).
    units : dict of str -> str
        Units of the columns whose unit is known (parameters, metrics), for plots.

    Examples
    --------
    >>> import numpy as np
    >>> from phs.workflows.sweep import Study, sweep
    >>> from systems.examples import rc_circuit
    >>> study = Study(rc_circuit(), np.linspace(0, 1e-3, 11), u={"U": 1.0}, grid={"R.R": [1e3, 2e3]},
    ...               metrics=["final:v_C"])
    >>> res = sweep(study, threads=1, progress=False)
    >>> len(res), res.ok.tolist(), [round(float(v), 4) for v in res["final_v_C"]]
    (2, [True, True], [0.6321, 0.3935])
    """

    def __init__(self, columns: dict, variables: list[str], metrics: list[str], path=None, seconds: float = 0.0,
                 new_runs: int = 0, system_name: str = "", units: dict | None = None):
        self.columns = columns
        self.variables = list(variables)
        self.metrics = list(metrics)
        self.path = path
        self.seconds = float(seconds)
        self.new_runs = int(new_runs)
        self.system_name = system_name
        self.units = dict(units or {})

    @classmethod
    def read(cls, path) -> StudyResult:
        """Read a results file written by :func:`sweep` (Parquet files carry the variables' names;
        for CSV every numeric column is listed as a metric).

        Examples
        --------
        >>> import os, tempfile
        >>> from phs.workflows.sweep import Study, sweep
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
        return cls(cols, variables, metrics, path=os.fspath(path), system_name=meta.get("system", ""),
                   units=meta.get("units"))

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

    def to_pandas(self) -> pd.DataFrame:
        """The rows as a pandas DataFrame, one per run; the known units in ``df.attrs["units"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> r = StudyResult({"run": np.arange(2), "R.R": np.array([1e3, 2e3]), "status": np.array(["ok", "ok"])},
        ...                 ["R.R"], [], units={"R.R": "Ohm"})
        >>> r.to_pandas().attrs["units"]  # doctest: +SKIP
        {'R.R': 'Ohm'}
        """
        from codegen.tables import require_pandas

        df = require_pandas("StudyResult.to_pandas()").DataFrame(self.columns)
        df.attrs["units"] = {c: u for c, u in self.units.items() if c in self.columns}
        return df

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

    def label(self, column: str) -> str:
        """Axis label of a column: ``name [unit]`` when its unit is known.

        Examples
        --------
        >>> r = StudyResult({"run": np.arange(1)}, ["R.R"], ["n"], units={"R.R": "Ohm", "n": "1"})
        >>> r.label("R.R"), r.label("n"), r.label("other")
        ('R.R [Ohm]', 'n [-]', 'other')
        """
        return axis_label(column, self.units.get(column, ""))

    def plot(self, path=None, metrics: Sequence[str] | None = None, variables: Sequence[str] | None = None, *,
             ax=None) -> Figure:
        """Each metric against each variable (failed runs as red crosses on the lower edge).

        With two or more variables, points are coloured by the next variable; axes are labelled
        ``name [unit]`` where the unit is known.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix: either the whole file appears
            or, on any failure, nothing changes).
        metrics, variables : sequence of str, optional
            The rows and columns of the grid of panels (default: every metric, every variable).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes, ``len(metrics) * len(variables)`` of them in reading order.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> r = StudyResult({"run": np.arange(2), "R.R": np.array([1e3, 2e3]), "n": np.array([0.6, 0.4]),
        ...                  "status": np.array(["ok", "ok"])}, ["R.R"], ["n"], units={"R.R": "Ohm"})
        >>> [(a.get_xlabel(), a.get_ylabel()) for a in r.plot().axes]
        [('R.R [Ohm]', 'n')]
        """
        metrics = list(metrics or self.metrics)
        variables = list(variables or self.variables)
        unknown = [c for c in metrics + variables if c not in self.columns]
        if unknown:
            raise InputDataError(f"plot: no column {unknown[0]!r}")
        if not metrics or not variables:
            raise InputDataError("plot: need at least one metric and one variable column")
        fig, axes = panels(ax, len(metrics), len(variables), figsize=(3.4 * len(variables) + 0.8, 2.6 * len(metrics)),
                           what="StudyResult.plot")
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
                        fig.colorbar(sc, ax=ax, label=self.label(other))
                else:
                    ax.scatter(x[good], y[good], s=12)
                if (~ok).any():
                    ax.scatter(x[~ok], np.full(int((~ok).sum()), lo), marker="x", color="red", s=18,
                               label="failed" if (i, j) == (0, 0) else None)
                if i == len(metrics) - 1:
                    ax.set_xlabel(self.label(v))
                if j == 0:
                    ax.set_ylabel(self.label(m))
                ax.grid(True, alpha=0.3)
        if (~ok).any():
            axes[0, 0].legend(fontsize="small")
        fig.suptitle(f"{self.system_name}: {len(self)} runs ({int((~ok).sum())} failed)")
        return finish(fig, path)

    def _headline(self) -> str:
        return (f"{self.system_name + ', ' if self.system_name else ''}{len(self)} runs, {int(self.ok.sum())} ok; "
                f"variables {names(self.variables, 4) or 'none'}; metrics {names(self.metrics, 4) or 'none'}")

    def _table(self) -> tuple[list, list]:
        """Each metric's smallest, median and largest value over the successful runs (at most 20 metrics)."""
        rows = []
        for c in self.metrics[:20]:
            v = self.columns[c][self.ok]
            v = v[np.isfinite(v)]
            rows.append((self.label(c), *((v.min(), np.median(v), v.max()) if len(v) else ("", "", "")), len(v)))
        if len(self.metrics) > 20:
            rows.append((f"... {len(self.metrics) - 20} more metrics", "", "", "", ""))
        return ["metric", "min", "median", "max", "finite runs"], rows
