"""The dissipation inequality along a trajectory, with the dissipated energy split per resistive element."""

from __future__ import annotations

import numpy as np

from codegen.passivity._result import PassivityTest
from phs.errors import InputDataError

ENERGY_TOL = 1e-6
"""Relative tolerance of the dissipation inequality along a trajectory (at least twice the run's own energy-balance
error): CVODES runs at ``rtol=1e-8`` close the balance to ~1e-6 of the energy exchanged (2e-7 to 1.2e-6 measured on
the 4-segment curling HASEL under square waves)."""


def dissipation_inequality(source, t=None, *, u=None, x0=None, params=None, rtol: float = 1e-8) -> PassivityTest:
    """Check ``∫ y^T u dt - (H(t) - H(0)) >= 0`` along a trajectory, with the dissipated energy split per element.

    The supplied energy, the dissipated energy and each resistive element's dissipated energy are
    quadratures of generated CasADi functions integrated by the same CVODES run as the states
    (:class:`codegen.Simulator`); the inequality is checked at every output time.

    Parameters
    ----------
    source : SimulationResult or PHSystem
        A simulation result, or a system to simulate on ``t`` with ``u``, ``x0``, ``params``.
    t : array, optional
        Time grid (required when ``source`` is a system).
    u : dict, signal or array, optional
        Inputs, as for :func:`codegen.simulate` (e.g. a recording's input columns as arrays on ``t``).
    x0 : dict or array, optional
        Initial state.
    params : dict, optional
        Parameter overrides.
    rtol : float
        Relative tolerance of the simulation.

    Returns
    -------
    PassivityTest
        Named ``trajectory``; ``numbers`` holds the energies at the final time (``supplied``,
        ``stored`` = H(T) - H(0), ``dissipated``, ``dissipated_by`` per element, ``unattributed``), the
        smallest slack ``min_t [E_supplied(t) - (H(t) - H(0))]`` absolute and relative to the energy
        exchanged, the relative error of the per-element split and the energy-balance error.

    Raises
    ------
    InputDataError
        When ``source`` is a system and ``t`` is missing (and for malformed inputs, from the simulator).

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rlc_circuit
    >>> test = dissipation_inequality(rlc_circuit(), np.linspace(0, 2e-3, 201), u={"U": 1.0})
    >>> test.verdict, sorted(test.numbers["dissipated_by"])
    ('pass', ['R'])
    >>> abs(test.numbers["supplied"] - test.numbers["stored"] - test.numbers["dissipated"]) < 1e-6 * test.numbers["supplied"]
    True
    """
    from codegen.results import SimulationResult
    from codegen.simulator import simulator

    if isinstance(source, SimulationResult):
        res = source
    else:
        if t is None:
            raise InputDataError("dissipation_inequality: give the time grid t to simulate the system on")
        # the certificate's what-if: an override of the wrong sign is simulated to show what it does
        res = simulator(source, rtol=rtol).run(t, u=u, x0=x0, params=params, signs=False)
    s = res.system
    q = res.quadratures or {}
    labels = [label for label, _ in s.dissipators]
    if "E_supplied" in q:
        Es, Ed = np.asarray(q["E_supplied"]), np.asarray(q["E_dissipated"])
        parts = {label: np.asarray(q[f"E_dissipated[{label}]"]) for label in labels}
        method = "energy accounts integrated as quadratures by the simulation's CVODES run"
    else:
        def cum(f):
            return np.concatenate([[0.0], np.cumsum(np.diff(res.t) * (f[1:] + f[:-1]) / 2)])

        Es, Ed = cum(res.supplied), cum(res.dissipated)
        parts = {label: cum(v) for label, v in res.dissipator_powers.items()}
        method = "energy accounts by the trapezoidal rule on the output grid"
    dH = res.H - res.H[0]
    slack = Es - dH
    scale = max(float(np.max(np.abs(Es))), float(np.max(np.abs(dH))), float(np.max(np.abs(Ed))), 1e-300)
    split = np.sum(list(parts.values()), axis=0) if parts else np.zeros_like(Ed)
    unattributed = Ed - split
    split_error = float(np.max(np.abs(unattributed)) / max(float(np.max(np.abs(Ed))), 1e-300)) if parts else float("nan")
    balance = float(np.max(np.abs(dH - (Es - Ed))) / scale)
    k = int(np.argmin(slack[1:])) + 1 if len(slack) > 1 else 0  # the slack is 0 at the start
    numbers = {"T": float(res.t[-1] - res.t[0]), "supplied": float(Es[-1]), "stored": float(dH[-1]),
               "dissipated": float(Ed[-1]), "dissipated_by": {label: float(v[-1]) for label, v in parts.items()},
               "unattributed": float(unattributed[-1]), "split_relative_error": split_error,
               "balance_error": balance, "min_slack": float(slack[k]), "min_slack_relative": float(slack[k] / scale),
               "min_slack_time": float(res.t[k])}
    worst = {"t": float(res.t[k]), **{n: float(v) for n, v in zip(s.state_names, res.x[k])}}
    series = {"t": res.t, "supplied": Es, "stored": dH, "dissipated": Ed, "parts": parts, "unattributed": unattributed}
    if balance > 1e-3:
        return PassivityTest("trajectory", "undecided", method,
                             f"the simulation's energy balance error {balance:.3g} is too large to decide (tighten rtol)",
                             numbers, worst, "", series)
    tol = max(ENERGY_TOL, 2 * balance)  # a violation below the run's own balance error cannot be told from it
    numbers["tolerance_relative"] = tol
    if slack[k] < -tol * scale:
        negative = {label: float(v[k]) for label, v in parts.items() if v[k] < 0}
        element = ", ".join(sorted(negative, key=negative.get)) if negative else "unattributed dissipation (R as given)"
        return PassivityTest("trajectory", "fail", method,
                             f"the dissipation inequality is violated: supplied − stored energy = {slack[k]:.4g} J "
                             f"< 0 at t = {res.t[k]:.6g} s (dissipated {Ed[k]:.4g} J)", numbers, worst, element, series)
    top = max(parts, key=lambda n: parts[n][-1]) if parts else ""
    worst = {}  # the slack's minimum of a passing run is its start, not a point worth reporting
    return PassivityTest("trajectory", "pass", method,
                         f"∫ yᵀu dt − ΔH ≥ 0 over [0, {numbers['T']:.6g}] s: supplied {Es[-1]:.6g} J = stored {dH[-1]:.6g} J "
                         f"+ dissipated {Ed[-1]:.6g} J" + (f" (largest: {top}, {parts[top][-1]:.4g} J; per-element split "
                                                           f"error {split_error:.2g})" if parts else ""),
                         numbers, worst, top, series)


def _trajectory(system, trajectory, params) -> PassivityTest:
    from codegen.results import SimulationResult

    if isinstance(trajectory, SimulationResult):
        if trajectory.system.model_hash() != system.model_hash():
            raise InputDataError(f"trajectory: the simulation result is of {trajectory.system.name!r}, not {system.name!r}")
        return dissipation_inequality(trajectory)
    if not isinstance(trajectory, dict):
        raise InputDataError("trajectory: give a SimulationResult or a dict with 't' (and 'u', 'x0')")
    unknown = set(trajectory) - {"t", "u", "x0", "rtol"}
    if unknown:
        raise InputDataError(f"trajectory: unknown key(s) {sorted(unknown)}; use 't', 'u', 'x0', 'rtol'")
    if "t" not in trajectory:
        raise InputDataError("trajectory: the dict needs the time grid 't'")
    return dissipation_inequality(system, trajectory["t"], u=trajectory.get("u"), x0=trajectory.get("x0"),
                                  params=params, rtol=trajectory.get("rtol", 1e-8))
