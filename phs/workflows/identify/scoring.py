"""How well a model reproduces a recording: the NRMSE fit % per output channel."""

from __future__ import annotations

import numpy as np

from codegen.simulator import Simulator


def nrmse_fit(y, yhat) -> float:
    """NRMSE fit in percent: ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` (MATLAB ``goodnessOfFit``).

    Examples
    --------
    >>> nrmse_fit(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    100.0
    """
    y, yhat = np.asarray(y, dtype=float), np.asarray(yhat, dtype=float)
    den = np.linalg.norm(y - y.mean())
    return float(100.0 * (1.0 - np.linalg.norm(y - yhat) / den)) if den > 0 else float("nan")


def _simulate_outputs(system, recording, outputs, x0, params=None, simulator=None):
    u = {n: recording.input_signal(n) for n in system.input_names}
    sim = simulator if simulator is not None else Simulator(system, energy=False)
    res = sim.run(recording.t, u=u, x0=x0, params=params)
    return {ch: res[ch] for ch in outputs}


def evaluate_fit(system, recording, outputs, x0=None, params=None, simulator=None) -> dict:
    """NRMSE fit % per output channel of ``system`` simulated on ``recording``'s inputs.

    ``params`` overrides parameter values without building a new system; ``simulator`` reuses
    a :class:`codegen.Simulator` of ``system`` (and its integrators) across calls.  The recording's
    signals are taken in the model's units (:meth:`~phs.workflows.recording.Recording.in_units_of`).
    """
    recording = recording.in_units_of(system)
    sim = _simulate_outputs(system, recording, outputs, x0, params, simulator)
    return {ch: nrmse_fit(recording[ch], sim[ch]) for ch in outputs}
