"""The result of a batch: the trajectories of every run in arrays shared with CasADi's outputs.

:class:`BatchResult` holds the states, inputs, energy accounts and batch-evaluated signals of all
runs; ``result[k]`` is run ``k`` as a :class:`~codegen.results.SimulationResult` whose derived
signals come from the batch's arrays where they were evaluated for the whole batch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from codegen._output import energy_accounts
from codegen.results import SimulationResult
from phs._results import ResultMixin, finish, panels, require_pandas

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

#: Derived signals that :meth:`codegen.batch.BatchSimulator.run` can evaluate for a whole chunk at once.
SIGNALS = ("measured", "output", "power", "hamiltonian")


class _BatchRun(SimulationResult):
    """A run of a batch: a :class:`SimulationResult` whose derived signals were evaluated for the batch."""

    def __init__(self, system, t, x, u, p, stats, pre: dict):
        super().__init__(system, t, x, u, p, stats)
        self._pre = pre

    @property
    def measured(self) -> np.ndarray:
        """Measured outputs (nt, n_measured)."""
        m = self._pre.get("measured")
        return m if m is not None else super().measured

    @property
    def y(self) -> np.ndarray:
        """Power-conjugate outputs (nt, nu)."""
        y = self._pre.get("output")
        return y if y is not None else super().y

    @property
    def H(self) -> np.ndarray:
        """Hamiltonian along the trajectory."""
        h = self._pre.get("hamiltonian")
        return h if h is not None else super().H

    @property
    def _power(self):
        pw = self._pre.get("power")
        return pw if pw is not None else super()._power

    def __getitem__(self, name: str) -> np.ndarray:
        col = self._pre.get("columns", {}).get(name)
        return col if col is not None else super().__getitem__(name)


class BatchResult(ResultMixin):
    """Trajectories of the runs of a batch, in arrays shared with CasADi's outputs.

    ``result[k]`` is run ``k`` as a :class:`~codegen.results.SimulationResult` (raising its error
    if it failed); ``len(result)`` is the number of runs; :meth:`plot` overlays the runs,
    :meth:`to_pandas` gives one row per run and sample.

    Attributes
    ----------
    t : array (nt,)
    x : array (n, nt, nx)
        States of every run (rows of failed runs are NaN).
    u : array (n, nt, nu)
        Inputs on the grid.
    p : array (n, n_params)
        Parameter values.
    quadratures : array (n, nt, 2 + n_dissipators) or None
        Cumulative supplied energy, dissipated energy and energy dissipated per element
        (with ``energy=True``).
    errors : list
        ``None`` for a run that succeeded, else its :class:`~phs.errors.PHSError`.
    signals : dict
        Derived signals evaluated for the whole batch (``"measured"``: (n, nt, n_measured), ...).
    seconds : float
        Wall time of the batch.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen.batch import BatchSimulator
    >>> from systems.examples import rc_circuit
    >>> batch = BatchSimulator(rc_circuit(), np.linspace(0, 1e-3, 11), threads=2)
    >>> res = batch.run([{"R.R": 1e3}, {"R.R": 2e3}], u={"U": 1.0})
    >>> len(res), bool(res.ok.all()), res.x.shape
    (2, True, (2, 11, 1))
    >>> round(float(res[0]["v_C"][-1]), 6)   # 1 - exp(-1)
    0.632121
    """

    def __init__(self, system, t, x, u, p, quadratures, errors, signals, stats):
        self.system = system
        self.t = t
        self.x = x
        self.u = u
        self.p = p
        self.quadratures = quadratures
        self.errors = errors
        self.signals = signals
        self.stats = stats
        self.seconds = float(stats.get("seconds", 0.0))

    def __len__(self) -> int:
        return len(self.errors)

    @property
    def ok(self) -> np.ndarray:
        """Boolean array: which runs succeeded."""
        return np.array([e is None for e in self.errors], dtype=bool)

    def __getitem__(self, k: int) -> SimulationResult:
        k = range(len(self))[k]
        if self.errors[k] is not None:
            raise self.errors[k]
        s = self.system
        pre = {}
        for name, arr in self.signals.items():
            if name == "power":
                pre[name] = tuple(a[k] for a in arr)
            elif name == "hamiltonian":
                pre[name] = arr[k][:, 0]
            elif name in SIGNALS:
                pre[name] = arr[k]
            else:  # one measured output
                pre.setdefault("columns", {})[name] = arr[k]
        stats = {"runs": self.stats.get("integrator_calls"), "seconds": self.seconds / max(len(self), 1),
                 "method": "cvodes", "rtol": self.stats.get("rtol"), "atol": self.stats.get("atol"), "batch": True}
        res = _BatchRun(s, self.t, self.x[k], self.u[k], self.p[k], stats, pre)
        if self.quadratures is not None:
            res.quadratures = energy_accounts(s, self.quadratures[k])
        return res

    def _signals(self) -> tuple[list[str], np.ndarray]:
        """Names and ``(n, nt, k)`` values of what :meth:`plot` and :meth:`to_pandas` show: the measured
        outputs (NaN for a failed run), or the states when the model has none."""
        s = self.system
        if not s.measured:
            return list(s.state_names), self.x
        vals = np.full((len(self), len(self.t), len(s.measured)), np.nan)
        for k in np.flatnonzero(self.ok):
            vals[k] = self[int(k)].measured
        return list(s.measured_names), vals

    def plot(self, path=None, *, ax=None) -> Figure:
        """Every successful run overlaid, a panel per measured output (per state when the model has none).

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes, one per panel.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> import numpy as np
        >>> from codegen.batch import BatchSimulator
        >>> from systems.examples import rc_circuit
        >>> res = BatchSimulator(rc_circuit(), np.linspace(0, 1e-3, 11)).run([{"R.R": 1e3}, {"R.R": 2e3}], u={"U": 1.0})
        >>> [a.get_ylabel() for a in res.plot().axes], len(res.plot().axes[0].lines)
        (['v_C [V]'], 2)
        """
        s = self.system
        labels, vals = self._signals()
        units = {m.name: m.unit for m in s.measured} | {st.name: st.unit for st in s.states}
        fig, grid = panels(ax, len(labels), figsize=(8, 2.4 * len(labels)), sharex=True, what="BatchResult.plot")
        for j, (a, name) in enumerate(zip(grid[:, 0], labels, strict=True)):
            for k in np.flatnonzero(self.ok):
                a.plot(self.t, vals[k, :, j], lw=0.8, alpha=0.7)
            a.set_ylabel(f"{name} [{units.get(name, '')}]")
            a.grid(True, alpha=0.3)
        grid[-1, 0].set_xlabel("t [s]")
        failed = len(self) - int(self.ok.sum())
        fig.suptitle(f"{s.name}: {len(self)} runs" + (f" ({failed} failed, not shown)" if failed else ""))
        return finish(fig, path)

    def to_pandas(self) -> pd.DataFrame:
        """One row per run and sample: ``run``, ``t``, the parameters of the run, the states, the inputs and the
        measured outputs (NaN for a failed run); the units in ``df.attrs["units"]``.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen.batch import BatchSimulator
        >>> from systems.examples import rc_circuit
        >>> res = BatchSimulator(rc_circuit(), np.linspace(0, 1e-3, 11)).run([{"R.R": 1e3}, {"R.R": 2e3}], u={"U": 1.0})
        >>> df = res.to_pandas()  # doctest: +SKIP
        >>> df.shape, df.groupby("run")["v_C"].last().round(4).tolist()  # doctest: +SKIP
        ((22, 6), [0.6321, 0.3935])
        """
        pd = require_pandas("BatchResult.to_pandas()")
        s = self.system
        n, nt = len(self), len(self.t)
        cols = {"run": np.repeat(np.arange(n), nt), "t": np.tile(self.t, n)}
        for j, name in enumerate(s.param_names):
            if np.ptp(self.p[:, j]) > 0:
                cols[name] = np.repeat(self.p[:, j], nt)
        for j, name in enumerate(s.state_names):
            cols[name] = self.x[:, :, j].reshape(-1)
        for j, name in enumerate(s.input_names):
            cols[name] = self.u[:, :, j].reshape(-1)
        if s.measured:
            labels, vals = self._signals()
            for j, name in enumerate(labels):
                cols[name] = vals[:, :, j].reshape(-1)
        df = pd.DataFrame(cols)
        units = {"t": "s"} | {q.name: q.unit for q in s.params} | {st.name: st.unit for st in s.states}
        units |= {i.name: i.unit for i in s.inputs} | {m.name: m.unit for m in s.measured}
        df.attrs["units"] = {c: units[c] for c in cols if c in units}
        return df

    def _headline(self) -> str:
        return f"{self.system.name!r}, {len(self)} runs, {int(self.ok.sum())} ok, {len(self.t)} samples"

    def _table(self) -> tuple[list, list]:
        """The parameters that differ between runs and each run's outcome (at most 20 runs)."""
        s = self.system
        varied = [j for j in range(len(s.param_names)) if len(self) and np.ptp(self.p[:, j]) > 0][:4]
        rows = [(k, *(self.p[k, j] for j in varied), "ok" if e is None else str(e)[:80])
                for k, e in enumerate(self.errors[:20])]
        if len(self) > 20:
            rows.append((f"... {len(self) - 20} more runs", *([""] * len(varied)), ""))
        return ["run", *(s.param_names[j] for j in varied), "outcome"], rows
