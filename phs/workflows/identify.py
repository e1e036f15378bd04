"""Grey-box identification: output-error fit of chosen parameters to a recording.

The simulation of the whole recording is one CasADi expression of the free
parameters (and optionally of free initial states): CVODES integrates the
model with the recorded inputs linearly interpolated, the measured outputs
are evaluated on the recording's grid, and the residual's Jacobian comes from
CVODES forward sensitivities (exact, not finite differences).  The least
squares are solved by a trust-region reflective method (``scipy``) with that
Jacobian; parameters spanning decades are fitted in log scale.

Reported: fitted values, standard errors and 95 % intervals from the
Jacobian, the correlation matrix with non-identifiable pairs flagged, NRMSE
fit % per output channel (``100 (1 - ||y - yhat|| / ||y - mean y||)``) on the
training and validation recordings, residuals, iterations, time, and the
sensitivity table of the curling HASEL paper (fit % at -10, -5, 0, +5, +10 %
of each parameter and the standard deviation of those fits).
"""

from __future__ import annotations

import sys
import time as _time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.optimize
import sympy as sp

from codegen.functions import generate
from codegen.simulator import Simulator, simulate
from phs.errors import InputDataError, ParameterError, PHSError
from phs.params import TIME
from phs.signals import Sampled


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


@dataclass
class IdentificationResult:
    """Outcome of :func:`identify` (values in the parameters' own units)."""

    system: object
    free: list
    values: dict
    initial: dict
    std_errors: dict
    intervals: dict
    correlation: np.ndarray
    flagged_pairs: list
    fit_percent: dict
    validation_fit_percent: dict
    residuals: dict
    cost: float
    iterations: int
    seconds: float
    x0: np.ndarray
    outputs: list
    weights: dict
    log_scaled: list
    message: str = ""
    sensitivity: dict = field(default_factory=dict)
    _recording: object = None

    @property
    def fitted_system(self):
        """The system with the fitted parameter values."""
        return self.system.with_params({k: v for k, v in self.values.items() if k in self.system.param_names})

    def summary(self) -> str:
        lines = [f"Identification of {self.system.name!r}: {len(self.free)} parameter{'s' if len(self.free) != 1 else ''}, "
                 f"cost {self.cost:.6g}, "
                 f"{self.iterations} iterations, {self.seconds:.2f} s ({self.message})"]
        lines.append(f"  {'parameter':<14}{'initial':>12}{'fitted':>14}{'std error':>12}   95 % interval")
        for k in self.free:
            lo, hi = self.intervals[k]
            lines.append(f"  {k:<14}{self.initial[k]:>12.5g}{self.values[k]:>14.6g}{self.std_errors[k]:>12.3g}"
                         f"   [{lo:.5g}, {hi:.5g}]" + ("  (log scale)" if k in self.log_scaled else ""))
        for ch, v in self.fit_percent.items():
            val = self.validation_fit_percent.get(ch)
            lines.append(f"  fit {ch}: {v:.2f} % (training)" + (f", {val:.2f} % (validation)" if val is not None else ""))
        for a, b, c in self.flagged_pairs:
            lines.append(f"  warning: {a} and {b} are strongly correlated ({c:+.3f}): not separately identifiable")
        return "\n".join(lines)

    __str__ = summary

    def to_dict(self) -> dict:
        return {
            "system": self.system.name, "model_hash": self.system.model_hash(), "free": self.free,
            "values": self.values, "initial": self.initial, "std_errors": self.std_errors,
            "intervals": {k: list(v) for k, v in self.intervals.items()},
            "correlation": self.correlation.tolist(), "flagged_pairs": [list(p) for p in self.flagged_pairs],
            "fit_percent": self.fit_percent, "validation_fit_percent": self.validation_fit_percent,
            "cost": self.cost, "iterations": self.iterations, "seconds": self.seconds, "outputs": self.outputs,
            "log_scaled": self.log_scaled, "message": self.message,
            "sensitivity": {k: {str(s): f for s, f in v.items()} for k, v in self.sensitivity.items()},
        }

    def validate(self, recording) -> dict:
        """Fit % per channel of the fitted model on another recording (stored in ``validation_fit_percent``)."""
        fits = evaluate_fit(self.fitted_system, recording, self.outputs, x0=self.x0)
        self.validation_fit_percent = fits
        return fits

    def sensitivity_table(self, recording=None, steps=(-0.10, -0.05, 0.0, 0.05, 0.10), channel: str | None = None):
        """Fit % when each fitted parameter alone moves by ``steps`` (relative), and the standard deviation.

        Returns ``{parameter: {step: fit %, ..., "std": sd}}`` for ``channel`` (default the first output).
        """
        rec = recording if recording is not None else self._recording
        ch = channel or self.outputs[0]
        # parameters are inputs of the generated functions: one simulator serves every variant
        sim = Simulator(self.system, energy=False)
        table = {}
        for k in self.free:
            row = {}
            for s in steps:
                try:
                    fits = evaluate_fit(self.system, rec, [ch], x0=self.x0,
                                        params={**self.values, k: self.values[k] * (1 + s)}, simulator=sim)
                    row[s] = fits[ch]
                except PHSError:
                    row[s] = float("nan")
            row["std"] = float(np.nanstd([row[s] for s in steps], ddof=1))
            table[k] = row
        self.sensitivity = table
        return table

    def plot(self, path=None, recording=None):
        """Measured versus simulated for each channel (and residuals); returns the matplotlib figure."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rec = recording if recording is not None else self._recording
        res = simulate(self.fitted_system, rec.t, u={u: Sampled(tuple(rec.t), tuple(rec[u])) for u in
                                                     self.system.input_names}, x0=self.x0)
        fig, axes = plt.subplots(len(self.outputs), 1, figsize=(8, 2.6 * len(self.outputs)), sharex=True, squeeze=False)
        for ax, ch in zip(axes[:, 0], self.outputs, strict=True):
            ax.plot(rec.t, rec[ch], lw=1, label="measured")
            ax.plot(rec.t, res[ch], lw=1, label=f"model (fit {nrmse_fit(rec[ch], res[ch]):.1f} %)")
            ax.set_ylabel(ch)
            ax.legend(fontsize=8)
        axes[-1, 0].set_xlabel("t [s]")
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=90)
        return fig


def _simulate_outputs(system, recording, outputs, x0, params=None, simulator=None):
    u = {n: Sampled(tuple(recording.t), tuple(recording[n])) for n in system.input_names}
    sim = simulator if simulator is not None else Simulator(system, energy=False)
    res = sim.run(recording.t, u=u, x0=x0, params=params)
    return {ch: res[ch] for ch in outputs}


def evaluate_fit(system, recording, outputs, x0=None, params=None, simulator=None) -> dict:
    """NRMSE fit % per output channel of ``system`` simulated on ``recording``'s inputs.

    ``params`` overrides parameter values without building a new system; ``simulator`` reuses
    a :class:`codegen.Simulator` of ``system`` (and its integrators) across calls.
    """
    sim = _simulate_outputs(system, recording, outputs, x0, params, simulator)
    return {ch: nrmse_fit(recording[ch], sim[ch]) for ch in outputs}


def _kinks(U: np.ndarray) -> list[int]:
    """Sample indices where a uniformly sampled input's slope changes (its linear interpolant's kinks)."""
    if U.size == 0 or len(U) < 3:
        return []
    d2 = np.abs(U[2:] - 2 * U[1:-1] + U[:-2])
    tol = 1e-12 * max(float(np.max(np.abs(U))), 1e-300)
    return sorted({int(k) + 1 for k in np.nonzero(np.any(d2 > tol, axis=1))[0]})


class _Problem:
    """The residual and its exact Jacobian as CasADi functions of the fit coordinates."""

    def __init__(self, system, recording, free, log_scaled, outputs, weights, x0, estimate_x0, rtol, atol,
                 shooting: int = 1, defect_weight: float = 1e3):
        self.system = system
        t = recording.t
        N = len(t)
        self.N = N
        # no energy quadratures; the second-order correction of the sensitivity Jacobian changes
        # the sensitivities by ~1e-7 relative and costs most of the time
        sim = Simulator(system, rtol=rtol, atol=atol, energy=False,
                        integrator_options={"second_order_correction": False})
        scale = sim.scale
        nx, nu = len(system.states), len(system.inputs)
        pnames = system.param_names
        p0 = system.param_vector()
        self.nominal = np.array([p0[pnames.index(k)] for k in free])
        theta = ca.MX.sym("theta", len(free))
        xi = ca.MX.sym("xi", len(estimate_x0))
        entries = []
        for i, name in enumerate(pnames):
            if name in free:
                k = free.index(name)
                entries.append(self.nominal[k] * (ca.exp(theta[k]) if name in log_scaled else theta[k]))
            else:
                entries.append(ca.MX(p0[i]))
        pvec = ca.vertcat(*entries) if entries else ca.MX(0, 1)
        x0v = ca.MX(ca.DM(x0))
        for j, name in enumerate(estimate_x0):
            i = system.state_names.index(name)
            x0v[i] = xi[j] * scale[i]
        U = np.column_stack([recording[u] for u in system.input_names]) if nu else np.zeros((N, 0))
        grids = [(t, U[:, j]) for j in range(nu)]
        # multiple shooting: K windows, each integrated from its own (scaled) initial state; the
        # continuity defects enter the least squares with a large weight (quadratic penalty)
        K = max(1, min(int(shooting), (N - 1) // 3))
        ms_edges = [int(e) for e in np.linspace(0, N - 1, K + 1).round().astype(int)]
        S = ca.MX.sym("s", nx, K - 1)
        self.window_starts = np.array(ms_edges[1:-1], dtype=int)
        # a recorded input that is piecewise linear with few kinks (steps, staircases, square waves
        # as sampled) is integrated piece by piece with restarts at its kinks, so CVODES takes long
        # steps in between; otherwise it is interpolated and the step bounded by the sample interval
        kinks = _kinks(U)
        piecewise = nu > 0 and len(kinks) <= max(20, (N - 1) // 20)
        cuts = sorted(set(ms_edges) | (set(kinks) if piecewise else set()))
        lin = "_c0 + _c1*t"
        tmpl = sp.sympify(lin, locals={"t": TIME, "_c0": sp.Symbol("_c0", real=True), "_c1": sp.Symbol("_c1", real=True)})
        slots = [[(sp.srepr(tmpl), tmpl, 2)] for _ in range(nu)] if piecewise else [[] for _ in range(nu)]
        cols, defects = [x0v], []
        start = x0v
        dt = t[1] - t[0]
        for i0, i1 in zip(cuts[:-1], cuts[1:]):
            if piecewise:
                F, _layout = sim._integrator(i1 - i0, slots, [None] * nu)
                coef = []
                for j in range(nu):
                    slope = (U[i1, j] - U[i0, j]) / (t[i1] - t[i0])
                    coef += [1.0, U[i0, j] - slope * t[i0], slope]
                P = ca.vertcat(pvec, ca.DM([t[i0], dt] + coef))
            else:
                F, _layout = sim._integrator(i1 - i0, [[] for _ in range(nu)], grids)
                P = ca.vertcat(pvec, ca.DM([t[i0], dt]))
            xf = F(x0=start / ca.DM(scale), p=P)["xf"] * ca.repmat(ca.DM(scale), 1, i1 - i0)
            if i1 in ms_edges[1:-1]:
                k = ms_edges.index(i1) - 1
                cols.append(xf[:, :-1])
                defects.append(xf[:, -1] / ca.DM(scale) - S[:, k])
                start = S[:, k] * ca.DM(scale)
                cols.append(start)
            else:
                cols.append(xf)
                start = xf[:, -1]
        X = ca.horzcat(*cols)
        gen = generate(system)
        fo = gen.output.map(N, "serial")
        y_all, meas_all = fo(X, ca.DM(U.T), ca.repmat(pvec, 1, N))
        rows = []
        for ch in outputs:
            if ch in system.measured_names:
                rows.append(meas_all[system.measured_names.index(ch), :])
            elif ch in system.output_names:
                rows.append(y_all[system.output_names.index(ch), :])
            else:
                rows.append(X[system.state_names.index(ch), :])
        Yhat = ca.vertcat(*rows)  # (n_out, N)
        Ymeas = np.vstack([recording[ch] for ch in outputs])
        W = np.array([weights[ch] for ch in outputs])[:, None]
        r = ca.vec(((Yhat - ca.DM(Ymeas)) * ca.DM(np.repeat(W, N, axis=1))).T)
        wdef = ca.MX.sym("w_defect")
        if defects:
            r = ca.vertcat(r, wdef * ca.vertcat(*defects))
        self.n_outputs_residual = N * len(outputs)
        z = ca.vertcat(theta, xi, ca.vec(S))
        self._res = ca.Function("residual", [z, wdef], [r])
        self.n_rows = r.numel()
        self._jac = ca.Function("residual_jac", [z, wdef], [r, ca.jacobian(r, z)])
        self.defect_weight = defect_weight
        self.n_theta = len(free)

    def jac(self, z):
        return self._jac(z, self.defect_weight)

    def res(self, z):
        return self._res(z, self.defect_weight)

    def values(self, z, log_scaled, free):
        th = z[: self.n_theta]
        return {k: float(self.nominal[i] * (np.exp(th[i]) if k in log_scaled else th[i])) for i, k in enumerate(free)}


def identify(system, recording, free, *, bounds=None, x0=None, outputs=None, weights=None, log_scale=None,
             estimate_x0=(), validation=None, initial=None, rtol: float = 1e-8, atol: float | None = None,
             max_iter: int = 100, ftol: float = 1e-8, shooting: int = 1, progress: bool = False) -> IdentificationResult:
    """Fit parameters ``free`` of ``system`` to ``recording`` by output error.

    Parameters
    ----------
    system : PHSystem
    recording : phs.workflows.recording.Recording
        Uniformly sampled; provides every input of the system and the fitted outputs.
    free : sequence of str
        Parameters to fit.
    bounds : dict of str -> (lo, hi), optional
        Bounds in the parameters' units (default: each parameter's declared range).
    x0 : dict or array, optional
        Initial state (default: the simulator's default).
    outputs : sequence of str, optional
        Measured outputs (or port outputs, states) to fit; default every one in the recording.
    weights : dict of str -> float, optional
        Weight per channel; default ``1 / std`` of the measured channel (channels in different
        units count alike).
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
        Stop when the relative decrease of the cost in a step is below this.
    progress : bool
        Print the cost at each iteration on stderr.

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
    wall = _time.perf_counter()
    free = list(free)
    if not free:
        raise ParameterError("identify: give at least one free parameter")
    for k in free:
        system.param(k)  # raises ParameterError naming it
    if initial:
        system = system.with_params(initial)
    _, outs = recording.check_for(system, outputs)
    for name in estimate_x0:
        if name not in system.state_names:
            raise InputDataError(f"estimate_x0: system {system.name!r} has no state {name!r}")
    d = np.diff(recording.t)
    if (d.max() - d.min()) > 1e-6 * d.mean():
        raise InputDataError(f"{recording.source}: identification needs uniform sampling (use resample=)")
    if log_scale is None:
        log_scaled = [k for k in free if system.param(k).value > 0 and system.param(k).range[0] > 0
                      and system.param(k).range[1] / system.param(k).range[0] >= 10**1.5]
    else:
        log_scaled = [k for k in log_scale if k in free]
        bad = [k for k in log_scaled if system.param(k).value <= 0]
        if bad:
            raise ParameterError(f"identify: log scale needs positive values; {bad} are not positive")
    w = {ch: 1.0 / max(float(np.std(recording[ch])), 1e-300) for ch in outs}
    w.update(dict(weights or {}))
    sim = Simulator(system, rtol=rtol, atol=atol)
    x0v = sim.initial_state(x0)
    prob = _Problem(system, recording, free, log_scaled, outs, w, x0v, list(estimate_x0), rtol, atol, shooting=shooting)
    # bounds in fit coordinates
    lo, hi = [], []
    bounds = dict(bounds or {})
    for i, k in enumerate(free):
        b = bounds.get(k, system.param(k).range)
        if not (len(b) == 2 and b[0] < b[1]):
            raise ParameterError(f"identify: bounds of {k!r} must be (lo, hi) with lo < hi, got {b}")
        nom = prob.nominal[i]
        if k in log_scaled:
            if b[0] <= 0:
                raise ParameterError(f"identify: {k!r} is fitted in log scale; its lower bound must be positive")
            lo.append(np.log(b[0] / nom))
            hi.append(np.log(b[1] / nom))
        else:
            a, c = sorted((b[0] / nom, b[1] / nom)) if nom != 0 else (b[0], b[1])
            lo.append(a)
            hi.append(c)
    scale = sim.scale
    for name in estimate_x0:
        i = system.state_names.index(name)
        st = system.states[i]
        lo.append(st.range[0] / scale[i])
        hi.append(st.range[1] / scale[i])
    z0 = [0.0 if k in log_scaled else 1.0 for k in free]
    z0 += [x0v[system.state_names.index(n)] / scale[system.state_names.index(n)] for n in estimate_x0]
    if len(prob.window_starts):
        # window states start on the trajectory of the initial parameters
        u_sig = {n: Sampled(tuple(recording.t), tuple(recording[n])) for n in system.input_names}
        xs = simulate(system, recording.t, u=u_sig, x0=x0v).x[prob.window_starts] / scale
        z0 += list(xs.reshape(-1))  # column-major vec of (nx, K-1): window by window
        lo += [-np.inf] * xs.size  # declared ranges guide checks and sampling; they do not bound trajectories
        hi += [np.inf] * xs.size
    z0 = np.clip(np.array(z0), np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    it = [0]
    last = {}

    def fun(z):
        """Residual only: sensitivities are computed by ``jac`` for accepted points."""
        try:
            r = np.asarray(prob.res(z)).reshape(-1)
        except RuntimeError:  # the simulation failed at this trial point: a large residual rejects it
            r_prev = last.get("r")
            return np.full(prob.n_rows, 1e6) if r_prev is None else 10 * np.abs(r_prev) + 1e3
        last.update(r=r)
        if progress:
            it[0] += 1
            print(f"  identify {system.name}: evaluation {it[0]}, cost {0.5 * r @ r:.6g}", file=sys.stderr, flush=True)
        return r

    def jac(z):
        try:
            return np.asarray(prob.jac(z)[1])
        except RuntimeError as exc:
            raise PHSError(f"identify {system.name!r}: the sensitivity simulation failed: {str(exc).splitlines()[-1]}") from None

    # multiple shooting: continuation on the defect weight, from loose (windows fit the data
    # almost freely) to tight (one continuous trajectory)
    stages = [1.0, 10.0, 100.0, 1e3] if len(prob.window_starts) else [None]
    z, nfev = z0, 0
    for wd in stages:
        if wd is not None:
            prob.defect_weight = wd
            last.clear()
        sol = scipy.optimize.least_squares(fun, z, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                                           ftol=ftol, xtol=1e-10, gtol=1e-10, max_nfev=max_iter)
        z, nfev = sol.x, nfev + sol.nfev
    r, J = prob.jac(z)
    r = np.asarray(r).reshape(-1)[: prob.n_outputs_residual]
    J = np.asarray(J)[: prob.n_outputs_residual]
    n_res, n_par = len(r), len(z)
    sigma2 = float(r @ r) / max(n_res - n_par, 1)
    try:
        cov = sigma2 * np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((n_par, n_par), np.nan)
    se_z = np.sqrt(np.maximum(np.diag(cov), 0))
    values = prob.values(z, log_scaled, free)
    std, ci = {}, {}
    for i, k in enumerate(free):
        v = values[k]
        if k in log_scaled:
            std[k] = abs(v) * se_z[i]
            ci[k] = (v * float(np.exp(-1.96 * se_z[i])), v * float(np.exp(1.96 * se_z[i])))
        else:
            std[k] = abs(prob.nominal[i]) * se_z[i]
            ci[k] = (v - 1.96 * std[k], v + 1.96 * std[k])
    dd = np.sqrt(np.maximum(np.diag(cov)[:len(free)], 1e-300))
    corr = cov[: len(free), : len(free)] / np.outer(dd, dd)
    flagged = [(free[a], free[b], float(corr[a, b])) for a in range(len(free)) for b in range(a + 1, len(free))
               if abs(corr[a, b]) > 0.95]
    x0_fit = x0v.copy()
    for j, name in enumerate(estimate_x0):
        i = system.state_names.index(name)
        x0_fit[i] = z[len(free) + j] * scale[i]
    fitted = system.with_params(values)
    sims = _simulate_outputs(fitted, recording, outs, x0_fit)
    fits = {ch: nrmse_fit(recording[ch], sims[ch]) for ch in outs}
    result = IdentificationResult(
        system=system, free=free, values=values, initial={k: float(system.param(k).value) for k in free},
        std_errors=std, intervals=ci, correlation=corr, flagged_pairs=flagged, fit_percent=fits,
        validation_fit_percent={}, residuals={ch: recording[ch] - sims[ch] for ch in outs}, cost=float(sol.cost),
        iterations=int(nfev), seconds=_time.perf_counter() - wall, x0=x0_fit, outputs=outs, weights=w,
        log_scaled=log_scaled, message=str(sol.message), _recording=recording,
    )
    if validation is not None:
        result.validate(validation)
    return result
