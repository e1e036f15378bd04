"""Design-space sweeps and ensembles: many simulations of one model, one row of metrics per run.

A :class:`Study` is a system, a time grid, inputs, the runs' variables (a
full-factorial ``grid`` of values, ``samples`` drawn from ``distributions`` by
Latin hypercube or plain random sampling, or both: every grid point combined
with every sample) and :mod:`metrics <phs.workflows.sweep.metrics>`.
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
resumes where it stopped (:mod:`phs.workflows.sweep.store`), and a run that
fails (integrator failure, validity domain left, a metric raising) is recorded
with its error without stopping the study.

Modules: :mod:`~phs.workflows.sweep.study` (:class:`Study`), :mod:`~phs.workflows.sweep.design`
(distributions and sampling), :mod:`~phs.workflows.sweep.metrics`, :mod:`~phs.workflows.sweep.run`
(:func:`sweep`, the executors), :mod:`~phs.workflows.sweep.evaluate` (a chunk of runs),
:mod:`~phs.workflows.sweep.store` (the results file), :mod:`~phs.workflows.sweep.result`
(:class:`StudyResult`) and :mod:`~phs.workflows.sweep.cli` (``phs sweep``).

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

from phs.workflows.sweep.design import LogNormal, LogUniform, MultivariateNormal, Normal, Uniform, from_fit
from phs.workflows.sweep.result import StudyResult
from phs.workflows.sweep.run import sweep
from phs.workflows.sweep.study import Study

__all__ = ["Study", "StudyResult", "sweep", "Uniform", "LogUniform", "Normal", "LogNormal", "MultivariateNormal",
           "from_fit"]
