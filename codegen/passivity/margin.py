"""The dissipation margin alone: the cheap form of the certificate's margin for design sweeps."""

from __future__ import annotations

import numpy as np

from codegen.passivity._box import EIGENVALUE_TOL, _min_eig, _reference, _resolve_box, _sample, _valid
from codegen.passivity._model import _model
from phs.errors import InputDataError


def dissipation_margin(system, params: dict | None = None, box: dict | None = None, samples: int = 256,
                       seed: int = 0) -> float:
    """Smallest scaled eigenvalue of ``[[R, P], [P^T, S]]`` over a sample of the box (no optimisation).

    The cheap form of :attr:`PassivityReport.margin` for design sweeps: the sample points (drawn once from
    the valid part of the box at the system's own parameter values) and the generated function of D are
    cached, so each further call is one mapped CasADi evaluation and a batch of small eigenvalue problems.
    The scaling is that of :mod:`codegen.passivity` (fixed by the system's own parameter values), so the
    margins of variants with different ``params`` compare directly.

    Parameters
    ----------
    system : PHSystem
    params : dict, optional
        Parameter overrides by name.
    box : dict, optional
        ``{name: (lower, upper)}`` for states (default: declared ranges) and parameters to vary.
    samples : int
        Number of sample points.
    seed : int
        Seed of the sample.

    Returns
    -------
    float
        The margin; ``nan`` when no sample point is inside the validity domain at these parameters.

    Raises
    ------
    InputDataError
        For a malformed box (unknown name, lower > upper bound).
    ParameterError
        For an unknown parameter in ``params``.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> msd = mass_spring_damper()
    >>> round(dissipation_margin(msd), 12), round(dissipation_margin(msd, params={"b.b": 0.2}), 12)  # half the damping
    (1.0, 0.5)
    >>> dissipation_margin(msd, params={"b.b": -0.4}) < 0                        # an active damper
    True
    """
    if not isinstance(samples, int) or samples < 1:
        raise InputDataError(f"dissipation_margin: samples must be a positive integer, got {samples!r}")
    model = _model(system)
    b = _resolve_box(system, box, params)
    if not model.support:
        return 0.0
    sD, sR = _reference(model, b, system.param_vector())
    V, _ = _sample(model, b, samples, seed, p=system.param_vector())
    if len(V) == 0:
        return float("nan")
    X, P = b.points(V, model.nx)
    Dk = model.D(X, P)
    valid = _valid(model, b, X, P)
    lamD = np.where(valid, _min_eig(Dk, sD, vectors=False)[0], np.nan)
    if not np.any(np.isfinite(lamD)):
        return float("nan")
    if np.nanmin(lamD) < -EIGENVALUE_TOL or sR.Q.shape[1] == 0:
        return float(min(np.nanmin(lamD), 0.0)) if np.nanmin(lamD) < -EIGENVALUE_TOL else 0.0
    lam = np.where(valid, _min_eig(Dk, sR, vectors=False)[0], np.nan)
    return float(np.nanmin(lam)) if np.any(np.isfinite(lam)) else float("nan")
