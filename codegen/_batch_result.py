"""The result of a batch: the trajectories of every run in arrays shared with CasADi's outputs.

:class:`BatchResult` holds the states, inputs, energy accounts and batch-evaluated signals of all
runs; ``result[k]`` is run ``k`` as a :class:`~codegen.results.SimulationResult` whose derived
signals come from the batch's arrays where they were evaluated for the whole batch.
"""

from __future__ import annotations

import numpy as np

from codegen._output import energy_accounts
from codegen.results import SimulationResult

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


class BatchResult:
    """Trajectories of the runs of a batch, in arrays shared with CasADi's outputs.

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

    ``result[k]`` is run ``k`` as a :class:`~codegen.results.SimulationResult` (raising its error
    if it failed); ``len(result)`` is the number of runs.

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

    def __repr__(self) -> str:
        return f"BatchResult({self.system.name!r}, {len(self)} runs, {int(self.ok.sum())} ok, {len(self.t)} samples)"
