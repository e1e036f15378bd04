"""The identification driver: output-error least squares of the free parameters (and initial states).

The residual and its exact Jacobian come from :mod:`phs.workflows.identify.sensitivities`; the least
squares are solved by scipy's trust-region reflective method with that Jacobian, with multiple
shooting as a continuation on the weight of the windows' continuity defects.
"""

from __future__ import annotations

import sys
import time as _time

import numpy as np
import scipy.optimize

from codegen._solver_errors import in_words
from codegen.simulator import Simulator, simulate
from phs.errors import InputDataError, ParameterError, PHSError, SimulationError
from phs.workflows.identify.coordinates import _bounds, _channel_weights, _log_scaled, ml_weights
from phs.workflows.identify.result import IdentificationResult, _uncertainty, relative_factor
from phs.workflows.identify.scoring import _simulate_outputs, nrmse_fit
from phs.workflows.identify.sensitivities import _Problem
from phs.workflows.identify.summaries import identify_summaries, is_summaries
from phs.workflows.inputs import check_uniform

ML_PASSES = 3
"""Most re-weighted refits of ``identify(..., weights="ml")`` after the first fit."""

STALL = 5
"""Trial points in a row that do not lower the cost, after the fit has lowered it at least once, after which
a fit stops at its best point (message ``stalled``): its trust region has shrunk 4**5 ≈ 1000-fold below
its last step, and the decreases still predicted there are below what the integration at the fit's
tolerance resolves.  (scipy's own step tolerance took 12 such trials, 3.6 s, on the concealed time delay's
refit, ending where it stood.)"""


RESOLVED = 2.0
"""A trial point lowers the cost only by more than this many times the cost's resolution: the two costs of
a Jacobian's point (the state integrated alone and with its sensitivities, each with error control of its
own: ``_Problem.cost_resolution``, the largest of the fit's stage) differ by about the integration's error
in the cost, and a difference of two costs carries two such errors.  A trial point that does not lower the
cost by more, where the linearisation at the best point predicted no more either (the Gauss-Newton model a
trust-region step is chosen on: ``_Problem.predicted_decrease``) and no step at all would (the full
Gauss-Newton step's, ``_Problem.attainable_decrease``), ends the fit at its best point (message
``resolved``): no step the model proposes there can be told from the integration's error.  (The trial
step alone is not enough: after a trust region shrinks it predicts little along a long valley.  On the 17 s
lab recording ``esa:cubic_stiffness@500Hz`` a polish so ended after 4 evaluations at a cost of 34.04, where
scipy's plain fit from the model's values reached 33.39; with both predictions it went on to 33.53 in 6.)  On the EMPS stage
in its loop (a virtual stiffness of 1.4·10⁶ N/m turns a 10⁻⁸ m error of position into 0.01 N of force) the
refits' costs wandered by 10⁻⁵ of themselves for 8–10 trial points at rtol 1e-7, each reset by a slightly
lower one, before :data:`STALL` or ``ftol`` ended them.  Chosen by that argument (two errors in a
difference), not on a verdict measurement."""


DIFFERENCE_COLUMNS = 40
"""Most fit coordinates whose Jacobian :func:`_jacobian` takes by differences of the residual (one simulation
each) where the integration with sensitivities fails; a fit with more (multiple shooting over many windows)
fails there as before."""


def _jacobian(prob, z, hi, rtol: float):
    """The residual and its Jacobian at ``z``: from the state integrated with its sensitivities, or, where that
    integration fails while the state's alone passes (it controls the sensitivities' error too: on a 17 s lab
    recording a hysteresis loop's refit ended with ``CV_TOO_MUCH_WORK`` there), by forward differences of
    the residual, one simulation per coordinate with a step of ``√rtol`` (times ``|z_i|`` when larger than 1;
    backwards at an upper bound ``hi``), whose error is about ``√rtol`` of the derivative.  Raises the
    integration's ``RuntimeError`` when the state alone fails too or there are more than
    :data:`DIFFERENCE_COLUMNS` coordinates.

    Examples
    --------
    >>> class Line:                      # a residual r(z) = A z - b, whose sensitivities "fail"
    ...     A, b = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]), np.ones(3)
    ...     def jac(self, z): raise RuntimeError("CV_TOO_MUCH_WORK")
    ...     def res(self, z): return self.A @ z - self.b
    >>> r, J = _jacobian(Line(), np.array([0.5, -1.0]), np.array([np.inf, -0.99999]), 1e-8)
    >>> np.allclose(J, Line.A), np.allclose(r, Line.A @ [0.5, -1.0] - 1)
    (True, True)
    """
    try:
        return prob.jac(z)
    except RuntimeError:
        if len(z) > DIFFERENCE_COLUMNS:
            raise
        z = np.asarray(z, dtype=float)
        r0 = np.asarray(prob.res(z), dtype=float).reshape(-1)
        J = np.empty((len(r0), len(z)))
        for i in range(len(z)):
            h = np.sqrt(rtol) * max(1.0, abs(z[i]))
            h = -h if z[i] + h > hi[i] else h
            zi = z.copy()
            zi[i] += h
            J[:, i] = (np.asarray(prob.res(zi), dtype=float).reshape(-1) - r0) / h
        return r0, J


UNRESOLVED = 2
"""Trial points in a row, after a first real decrease, whose costs lie within :data:`RESOLVED` times the
cost's resolution of the best (above it: the step's decrease, predicted larger by the linearisation, is
not seen) after which a fit ends at its best point (message ``resolved``): the trust region has shrunk
16-fold past the last step whose decrease the integration resolved.  On the EMPS stage in its loop the
delay's refit after the friction ran 4 such trial points (1.6 s) before :data:`STALL` ended it.  Chosen by
that argument, not on a verdict measurement."""


class _Stalled(Exception):
    """Raised inside the residual to end a fit that no longer lowers its cost (:data:`STALL`), or lowers
    it by less than the integration resolves (:data:`RESOLVED`)."""


def identify(system, recording, free, *, bounds=None, x0=None, outputs=None, weights=None, log_scale=None,
             estimate_x0=(), validation=None, initial=None, rtol: float = 1e-8, atol: float | None = None,
             max_iter: int = 100, ftol: float = 1e-8, shooting: int = 1, progress=False,
             compile: bool | None = None, ml_start: dict | None = None) -> IdentificationResult:
    """Fit parameters ``free`` of ``system`` to ``recording`` by output error.

    Parameters
    ----------
    system : PHSystem
    recording : phs.workflows.recording.Recording, or Summary or sequence of Summary
        Uniformly sampled; provides every input of the system and the fitted outputs.  Signals in other
        units than the model's (a header ``U [kV]``) are converted (:meth:`~phs.workflows.recording.Recording.in_units_of`).
        Runs known only by statistics of their channels (a paper's table of means or ranges) are
        :class:`~phs.workflows.identify.summaries.Summary` objects: the fit is then to those statistics, with
        ``bounds``, ``x0``, ``log_scale``, ``initial``, ``rtol``, ``atol``, ``max_iter``, ``ftol``, ``compile`` and
        ``weights`` (label -> weight; default relative errors) as here, and returns a
        :class:`~phs.workflows.identify.summaries.SummaryFit` (:mod:`phs.workflows.identify.summaries`).
    free : sequence of str
        Parameters to fit.
    bounds : dict of str -> (lo, hi), optional
        Bounds in the parameters' units (default: each parameter's declared range).
    x0 : dict or array, optional
        Initial state (default: the simulator's default).
    outputs : sequence of str, optional
        Measured outputs (or port outputs, states) to fit; default every one in the recording.
    weights : dict of str -> float, or "ml", optional
        Weight per channel; default ``1 / std`` of the measured channel (channels in different
        units count alike).  ``"ml"``: maximum likelihood with one unknown noise variance per channel,
        by iterative re-weighting (``1 / sigma`` with ``sigma`` each channel's residual RMS, floored at
        :data:`~phs.workflows.identify.coordinates.CHANNEL_FLOOR` of its standard deviation; at most
        :data:`ML_PASSES` refits, until no weight moves by more than 10 %); the result's ``weights`` are
        the final ones.
    ml_start : dict of str -> float, optional
        With ``weights="ml"``: the weights of the first fit (default ``1 / std`` of each channel).  A fit
        that continues an earlier one (the same model on more of the recording) starts from the weights
        that one ended with and then usually needs no re-weighting pass.
    log_scale : sequence of str, optional
        Parameters fitted in log scale; default those whose declared range spans >= 1.5 decades.
    estimate_x0 : sequence of str
        Initial states estimated with the parameters.
    validation : Recording, optional
        Scored with the fitted model.
    initial : dict, optional
        Starting values (default: the system's current values).
    shooting : int
        Number of multiple-shooting windows (1: single shooting).  Each window starts from its own
        state, estimated with the parameters; continuity between windows enters the least squares
        as heavily weighted defects.  Helps oscillatory or drifting systems whose single-shooting
        cost has many local minima.
    max_iter : int
        Maximum number of residual evaluations.
    ftol : float
        Stop when the relative decrease of the cost in a step is below this; also stops when
        :data:`STALL` trial points in a row, after a first decrease, do not lower the cost (the
        integration's resolution reached; message ``stalled``), or when a trial point's predicted and
        actual decreases are both within what the integration resolves (:data:`RESOLVED`; message
        ``resolved``).
    progress : bool or callable
        Print the cost at each residual evaluation on stderr; a callable is called with the evaluation's
        number and cost instead (a progress bar's hook).
    compile : bool, optional
        Run the simulation and its sensitivities as compiled C (cached on disk by a hash of the
        model, built once per model and number of fitted directions; results agree with the
        interpreted functions to rounding).  Default: compile when a C compiler is available, the
        inputs are piecewise linear (steps, staircases, square waves as sampled) and the fit is
        large; otherwise run CasADi's interpreted functions.

    Returns
    -------
    IdentificationResult

    Raises
    ------
    ParameterError, InputDataError
        Naming an unknown parameter, output or state, bad bounds, or a recording without a needed signal.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> from phs.workflows.recording import Recording
    >>> truth = rc_circuit().with_params({"R.R": 2e3})
    >>> t = np.linspace(0, 0.01, 201)
    >>> u = np.where(t > 0.002, 1.0, 0.0)
    >>> y = simulate(truth, t, u={"U": u})["v_C"]
    >>> fit = identify(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"])
    >>> round(fit.values["R.R"])
    2000
    """
    if is_summaries(recording):
        other = {"outputs": outputs is not None, "estimate_x0": bool(estimate_x0), "validation": validation is not None,
                 "shooting": shooting != 1, "progress": bool(progress), "ml_start": ml_start is not None,
                 "weights='ml'": isinstance(weights, str)}
        if any(other.values()):
            raise ParameterError(f"identify: {', '.join(k for k, v in other.items() if v)} do(es) not apply to a fit to "
                                 "summary statistics")
        return identify_summaries(system, recording, free, bounds=bounds, x0=x0, weights=weights, log_scale=log_scale,
                                  initial=initial, rtol=rtol, atol=atol, max_iter=max_iter, ftol=ftol, compile=compile)
    recording = recording.in_units_of(system)  # units of the file's headers (kV, mm) to the model's
    validation = validation.in_units_of(system) if validation is not None else None
    if ml_start is not None and weights != "ml":
        raise ParameterError("identify: ml_start (the first fit's weights) needs weights='ml'")
    if isinstance(weights, str):
        if weights != "ml":
            raise ParameterError(f"identify: weights must be a dict of channel weights or 'ml', got {weights!r}")
        return _identify_ml(system, recording, free, bounds=bounds, x0=x0, outputs=outputs, log_scale=log_scale,
                            estimate_x0=estimate_x0, validation=validation, initial=initial, rtol=rtol, atol=atol,
                            max_iter=max_iter, ftol=ftol, shooting=shooting, progress=progress, compile=compile,
                            start=ml_start)
    wall = _time.perf_counter()
    free = list(free)
    if not free and not estimate_x0:
        raise ParameterError("identify: give at least one free parameter (or states in estimate_x0)")
    for k in free:
        system.param(k)  # raises ParameterError naming it
    code = system  # its generated functions serve every parameter value (they take p as an input)
    if initial:
        system = system.with_params(initial)
    _, outs = recording.check_for(system, outputs)
    for name in estimate_x0:
        if name not in system.state_names:
            raise InputDataError(f"estimate_x0: system {system.name!r} has no state {name!r}")
    # uniform up to the rounding of its stamps (at an epoch time of 1.7e9 s a float resolves 2.4e-7 s): the
    # recording's own rule (phs.workflows.inputs.check_uniform)
    check_uniform(recording.t, recording.source, lambda k: f"sample {k}", "t", "; identification needs uniform sampling (use resample=)")
    log_scaled = _log_scaled(system, free, log_scale)
    w = _channel_weights(recording, outs, weights)
    sim = Simulator(code, rtol=rtol, atol=atol)
    x0v = sim.initial_state(x0)
    p_start = system.param_vector()
    try:
        prob = _Problem(code, recording, free, log_scaled, outs, w, x0v, list(estimate_x0), rtol, atol,
                        shooting=shooting, compile=compile, params=p_start)
    except SimulationError:
        if compile is not None:  # asked for explicitly: say why it failed
            raise
        # compiling is only a speed-up: without it the same fit runs interpreted
        prob = _Problem(code, recording, free, log_scaled, outs, w, x0v, list(estimate_x0), rtol, atol,
                        shooting=shooting, compile=False, params=p_start)
    scale = sim.scale
    lo, hi = _bounds(system, free, log_scaled, prob.nominal, bounds, estimate_x0, scale)
    z0 = [0.0 if k in log_scaled else 1.0 for k in free]
    z0 += [x0v[system.state_names.index(n)] / scale[system.state_names.index(n)] for n in estimate_x0]
    if len(prob.window_starts):
        # window states start on the trajectory of the initial parameters
        u_sig = {n: recording.input_signal(n) for n in system.input_names}
        xs = simulate(system, recording.t, u=u_sig, x0=x0v).x[prob.window_starts] / scale
        z0 += list(xs.reshape(-1))  # column-major vec of (nx, K-1): window by window
        lo += [-np.inf] * xs.size  # declared ranges guide checks and sampling; they do not bound trajectories
        hi += [np.inf] * xs.size
    z0 = np.clip(np.array(z0), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    it = [0]
    last = {}
    best: dict = {}  # the stage's lowest cost, its point, evaluations since, whether it ever fell

    def note(z, cost):
        best["n"] = best.get("n", 0) + 1
        best["res"] = max(best.get("res", 0.0), prob.cost_resolution)
        low, band = best.get("cost", np.inf), RESOLVED * best["res"]
        if cost < low - band:
            best.update(cost=cost, z=np.array(z, dtype=float), since=0, fell="z" in best)
            return
        if cost < low:  # lower, by less than the integration resolves: kept
            best.update(cost=cost, z=np.array(z, dtype=float))
        if band > 0 and prob.predicted_decrease(z) <= band and prob.attainable_decrease() <= band:
            best["why"] = (f"resolved: the step's predicted and actual decreases of the cost are within {RESOLVED:g} "
                           f"times its resolution at rtol {rtol:g} ({best['res']:.3g})")
            raise _Stalled
        if cost < low:
            return
        best["since"] = best.get("since", 0) + 1
        # a trial point within the band either side of the best tells the fit nothing either: two in a row
        # after a first real decrease end it (its trust region has shrunk 16-fold past the last resolved step)
        best["unresolved"] = best.get("unresolved", 0) + 1 if cost <= low + band else 0
        if best.get("fell") and best["unresolved"] >= UNRESOLVED:
            best["why"] = (f"resolved: {UNRESOLVED} trial points in a row within {RESOLVED:g} times the cost's resolution "
                           f"at rtol {rtol:g} ({best['res']:.3g}) of the best")
            raise _Stalled
        if best.get("fell") and best["since"] >= STALL:
            best["why"] = f"stalled: {STALL} trial points in a row did not lower the cost"
            raise _Stalled

    def fun(z):
        """Residual only: sensitivities are computed by ``jac`` for accepted points."""
        try:
            r = np.asarray(prob.res(z)).reshape(-1)
        except RuntimeError:  # the simulation failed at this trial point: a large residual rejects it
            r_prev = last.get("r")
            note(z, np.inf)
            return np.full(prob.n_rows, 1e6) if r_prev is None else 10 * np.abs(r_prev) + 1e3
        note(z, 0.5 * float(r @ r))
        last.update(r=r)
        if progress:
            it[0] += 1
            if callable(progress):  # a progress bar's hook: (evaluation, cost)
                progress(it[0], 0.5 * float(r @ r))
            else:
                print(f"  identify {system.name}: evaluation {it[0]}, cost {0.5 * r @ r:.6g}", file=sys.stderr, flush=True)
        return r

    def jac(z):
        try:
            return np.asarray(_jacobian(prob, z, hi, rtol)[1])
        except RuntimeError as exc:
            raise PHSError(f"identify {system.name!r}: the sensitivity simulation failed: "
                           + in_words(str(exc).splitlines()[-1], hint="at parameter values the fit tried")) from None

    # multiple shooting: continuation on the defect weight, from loose (windows fit the data
    # almost freely) to tight (one continuous trajectory)
    stages = [1.0, 10.0, 100.0, 1e3] if len(prob.window_starts) else [None]
    z, nfev = z0, 0
    for wd in stages:
        if wd is not None:
            prob.defect_weight = wd
            last.clear()
        best.clear()  # a new defect weight: costs of another stage do not compare
        try:
            sol = scipy.optimize.least_squares(fun, z, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                                               ftol=ftol, xtol=1e-10, gtol=1e-10, max_nfev=max_iter)
            z, nfev, cost, message = sol.x, nfev + sol.nfev, float(sol.cost), str(sol.message)
        except _Stalled:
            z, nfev, cost, message = best["z"], nfev + best["n"], best["cost"], best["why"]
    r, J = _jacobian(prob, z, hi, rtol)
    r = np.asarray(r).reshape(-1)[: prob.n_outputs_residual]
    J = np.asarray(J)[: prob.n_outputs_residual]
    values = prob.values(z, log_scaled, free)
    std, ci, corr, flagged, ident, unident = _uncertainty(
        r, J, values, prob.nominal, free, log_scaled, n_channels=len(outs), rtol=rtol,
        units={k: system.param(k).unit for k in free})
    x0_fit = x0v.copy()
    for j, name in enumerate(estimate_x0):
        i = system.state_names.index(name)
        x0_fit[i] = z[len(free) + j] * scale[i]
    if len(prob.window_starts):  # the fitted model as one trajectory (the windows joined up to the defects)
        sims = _simulate_outputs(system, recording, outs, x0_fit, params=values)
    else:  # the trajectory of the final residual
        sims = dict(zip(outs, prob.outputs(z), strict=True))
    fits = {ch: nrmse_fit(recording[ch], sims[ch]) for ch in outs}
    result = IdentificationResult(
        system=system, free=free, values=values, initial={k: float(system.param(k).value) for k in free},
        std_errors=std, intervals=ci, correlation=corr, flagged_pairs=flagged, fit_percent=fits,
        validation_fit_percent={}, residuals={ch: recording[ch] - sims[ch] for ch in outs}, cost=cost,
        iterations=int(nfev), seconds=_time.perf_counter() - wall, x0=x0_fit, outputs=outs, weights=w,
        log_scaled=log_scaled, message=message, _recording=recording, compiled=prob.compiled,
        identifiable=ident, unidentifiable=unident,
        factor=relative_factor(J, values, prob.nominal, free, log_scaled), rtol=rtol,
        cost_resolution=max(best.get("res", 0.0), prob.cost_resolution),
    )
    if validation is not None:
        result.validate(validation)
    return result


def _identify_ml(system, recording, free, *, x0, outputs, initial, validation, start, **kw) -> IdentificationResult:
    """``identify`` with maximum-likelihood channel weights (iteratively re-weighted, floored), the first
    fit with the weights ``start`` (default ``1 / std``)."""
    wall = _time.perf_counter()
    res = first = identify(system, recording, free, x0=x0, outputs=outputs, initial=initial, weights=start, **kw)
    iterations = res.iterations
    for _ in range(ML_PASSES):
        w = ml_weights(res.residuals, recording, res.outputs)
        if all(abs(w[ch] / res.weights[ch] - 1.0) <= 0.1 for ch in res.outputs):
            break
        start = dict(initial or {})
        start.update(res.values)
        nxt = identify(system, recording, free, x0=res.x0, outputs=res.outputs, initial=start, weights=w, **kw)
        res = nxt
        iterations += res.iterations
    res.initial, res.iterations = first.initial, iterations
    res.seconds = _time.perf_counter() - wall
    if validation is not None:
        res.validate(validation)
    return res
