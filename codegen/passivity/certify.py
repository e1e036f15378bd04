"""The certificate: every test of :mod:`codegen.passivity` over one box, gathered into a report."""

from __future__ import annotations

import time

from codegen.passivity._box import _resolve_box, _sample, _valid
from codegen.passivity._model import _model
from codegen.passivity._result import PassivityTest
from codegen.passivity.energy import _trajectory
from codegen.passivity.local import local_passivity
from codegen.passivity.report import PassivityReport
from codegen.passivity.storage import _storage
from codegen.passivity.structural import _dissipation, _interconnection, _sign_violations, _symbolic_dissipation
from phs.errors import InputDataError
from phs.structure_units import structure_unit_problems


def certify(system, *, box: dict | None = None, params: dict | None = None, equilibrium=None, u=None, x0=None,
            trajectory=None, samples: int = 2000, starts: int = 8, seed: int = 0, progress=None) -> PassivityReport:
    """Certify that ``system`` is passive over a box of states (and parameters), and say where it is not.

    Runs the tests of :mod:`codegen.passivity`: ``interconnection``, ``dissipation`` (the margin),
    ``feedthrough``, ``storage``, and, when asked, ``trajectory`` and ``local``; a failed ``units`` test is added
    when the dimensions of the structure disagree (see :mod:`phs.structure_units`).

    Parameters
    ----------
    system : PHSystem
    box : dict, optional
        ``{name: (lower, upper)}``: states default to their declared ranges; parameters named here are varied
        over the given bounds (``None``: their declared range), the others stay at their values.
    params : dict, optional
        Parameter overrides by name (e.g. fitted values); they need not satisfy the parameters' declared sign
        (a negative resistance is reported, not refused).
    equilibrium : dict, array, EquilibriumResult or True, optional
        Adds the ``local`` test at this equilibrium: a claimed state (``{name: value}``, checked), a solver
        result, or True to solve for it under ``u`` from ``x0``.
    u : dict or float, optional
        Constant input at the equilibrium (implies ``equilibrium=True`` when that is not given).
    x0 : dict, optional
        Starting point of the equilibrium solver (fixes the conserved quantities, e.g. the curling HASEL's
        ``seg{i}.l_p``).
    trajectory : SimulationResult or dict, optional
        Adds the ``trajectory`` test: a simulation result, or ``{"t": ..., "u": ..., "x0": ...}`` to simulate
        (``u`` may hold a recording's input columns as arrays on ``t``).
    samples : int
        Points of the dense sample of the box.
    starts : int
        Starts of each ``nlpsol`` minimisation (the best half of the sample and random others).
    seed : int
        Seed of the sample and of the random starts.
    progress : callable, optional
        Called with the name of each stage as it starts (``"structure"``, ``"equilibrium"``, ``"trajectory"``,
        ``"sampling"``, ``"dissipation"``, ``"storage"``): a progress bar's hook.

    Returns
    -------
    PassivityReport

    Raises
    ------
    InputDataError
        For a malformed box (unknown name, lower > upper bound, non-finite bound) or trajectory.
    ParameterError
        For an unknown parameter in ``params``.
    EquilibriumError
        When the equilibrium given is not one, or none is found.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> rep = certify(rc_circuit(), params={"R.R": -1e3}, samples=64, starts=1)   # a negative resistor
    >>> rep.passive, rep["dissipation"].verdict, rep["dissipation"].element
    (False, 'fail', 'R (declared positive but R.R = -1000)')
    >>> certify(rc_circuit(), box={"C.Q": (1e-6, -1e-6)})
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: box 'C.Q': lower bound 1e-06 > upper bound -1e-06
    """
    from phs.checks import check_system

    wall = time.perf_counter()
    for name, v in (("samples", samples), ("starts", starts)):
        if not isinstance(v, int) or isinstance(v, bool) or v < (1 if name == "samples" else 0):
            raise InputDataError(f"certify: {name} must be a {'positive' if name == 'samples' else 'nonnegative'} "
                                 f"integer, got {v!r}")
    stage = progress if progress is not None else (lambda name: None)
    b = _resolve_box(system, box, params)
    stage("structure")
    model = _model(system)
    checks = check_system(system, samples=16, seed=seed)
    violations = _sign_violations(system, b)
    symbolic = _symbolic_dissipation(system, checks, violations)
    local = None
    if equilibrium is not None or u is not None:
        stage("equilibrium")
        local = local_passivity(system, None if equilibrium is True else equilibrium, u, params=params, x0=x0)
    traj = None
    if trajectory is not None:
        stage("trajectory")
        traj = _trajectory(system, trajectory, params)
    stage("sampling")
    V, info = _sample(model, b, samples, seed)
    tests = [_interconnection(system, checks)]
    wrong_units = structure_unit_problems(system)[0]  # a structure whose units disagree is no physical power balance
    if wrong_units:
        tests.append(PassivityTest("units", "fail", "dimensional analysis of J, R, G, P, S, N and the outputs",
                                   "; ".join(wrong_units)))
    if len(V) == 0:
        why = "no point of the box satisfies the validity conditions " + "; ".join(info.get("empty", []))
        tests += [PassivityTest(n, "undecided", "sampled", why) for n in ("dissipation", "feedthrough", "storage")]
        margin = float("nan")
    else:
        X, P = b.points(V, model.nx)
        valid = _valid(model, b, X, P)
        V, X, P, valid = V[valid], X[valid], P[valid], valid[valid]
        if len(V) == 0:
            why = "no sampled point is inside the validity domain at these parameter values"
            tests += [PassivityTest(n, "undecided", "sampled", why) for n in ("dissipation", "feedthrough", "storage")]
            margin = float("nan")
        else:
            stage("dissipation")
            dtest, ftest, margin = _dissipation(model, b, V, X, P, valid, starts, seed, symbolic, system.param_vector())
            stage("storage")
            tests += [dtest, ftest, _storage(model, b, V, X, P, valid, starts, seed, checks)]
    if traj is not None:
        tests.append(traj)
    if local is not None:
        tests.append(local.test())
    info = {"samples": samples, "starts": starts, "seed": seed, "seconds": time.perf_counter() - wall,
            "sampling": info.get("groups", [])}
    return PassivityReport(system, tests, margin, b.as_dict(), dict(zip(system.param_names, map(float, b.p))), info)
