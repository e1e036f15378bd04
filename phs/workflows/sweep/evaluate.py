"""Evaluation of a chunk of a study's runs (in this process or on Dask workers): one batch
simulation, then every metric of every run; a failure is recorded in its run's row."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from phs.errors import PHSError
from phs.workflows.interrupts import check
from phs.workflows.sweep.study import Study


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
            check()  # an interrupt the integrators swallowed: these runs were stopped, not failed; no row is kept
            for pos, (run, values) in enumerate(todo):
                err = res.errors[pos]
                rows[run] = self._failed(run, values, _describe(err)) if err is not None else \
                    self._measure(run, values, res[pos])
        return [rows[run] for run, _ in runs]

    def _failed(self, run, values, message) -> dict:
        return _failed_row(self.metrics, run, values, message)

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


def _failed_row(metrics, run, values, message) -> dict:
    """The row of a failed run: its variables, NaN for every metric column, and the error."""
    row = {"run": int(run), **values}
    for m in metrics:
        row.update(dict.fromkeys(m.columns, float("nan")))
    row.update(status="failed", error=message)
    return row
