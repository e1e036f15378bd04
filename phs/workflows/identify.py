"""Grey-box identification: output-error fit of chosen parameters to a recording.

CVODES integrates the model over the whole recording with the recorded inputs
linearly interpolated (restarted at the input's kinks; smooth stretches of a
finely sampled input by a cubic spline, see ``codegen.simulator.step_windows``), the measured outputs are
evaluated on the recording's grid, and the residual's Jacobian with respect to
the free parameters (and optionally free initial states) comes from CVODES
forward sensitivities integrated with the state (exact to the integration
tolerance, not finite differences), chained through the output functions'
Jacobians.  The least squares are solved by a trust-region reflective method
(``scipy``) with that Jacobian; parameters spanning decades are fitted in log
scale.  Large fits run the dynamics, their derivatives and the output functions
as compiled C, cached on disk by a hash of the model.

Reported: fitted values, standard errors and 95 % intervals from the
Jacobian, the correlation matrix with non-identifiable pairs flagged, NRMSE
fit % per output channel (``100 (1 - ||y - yhat|| / ||y - mean y||)``) on the
training and validation recordings, residuals, iterations, time, and the
sensitivity table of the curling HASEL paper (fit % at -10, -5, 0, +5, +10 %
of each parameter and the standard deviation of those fits).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time as _time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.optimize
import sympy as sp

from codegen.functions import _model_hash, generate
from codegen.simulator import Simulator, simulate, step_windows
from phs.errors import InputDataError, ParameterError, PHSError, SimulationError
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
    compiled: bool = False  # whether the fit ran compiled C (see ``identify(compile=...)``)

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


# compile by default when the fit is large: samples x (1 + directions) x the dynamics' size above this
# (the dynamics' C library, with their forward derivatives, takes a few seconds to build once per
# model and is then loaded from the disk cache; the sensitivities run 2-3 times faster compiled)
_COMPILE_WORK = 2e7
_CFLAGS = ("-O1",)  # as fast as -O2 on generated code here, and a third quicker to compile


def _decide_compile(compile, gen, N: int, n_dir: int, templated: bool) -> bool:
    """Whether to compile the fit's functions to C.  ``compile=None``: when a C compiler exists, the
    inputs are templates (not data baked into the code) and the fit is large (see ``_COMPILE_WORK``)."""
    if compile is not None:
        return bool(compile)
    if not templated or _c_compiler() is None:
        return False
    return N * (1 + n_dir) * gen.rhs.n_instructions() >= _COMPILE_WORK


def _c_compiler():
    return shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")


class _Library:
    """``funs`` compiled to C in one shared library, together with their Jacobians (``jacobian``) and
    forward derivatives in ``forward`` directions (CasADi loads those from the library by name),
    cached on disk like :func:`codegen.compile.compiled` (written under a temporary name, renamed
    into place).  The C source is written at once and the compiler runs as a separate process until
    :meth:`load`, so that the caller's other work overlaps the compilation."""

    def __init__(self, funs: list, key: str, jacobian: bool = False, forward: tuple = ()):
        from codegen.compile import cache_dir

        cc = _c_compiler()
        if cc is None:
            raise SimulationError("compilation to C requested but no C compiler (gcc/cc) was found; use compile=False")
        self.names = [f.name() for f in funs]
        # the functions' own serializations key the library too: a changed definition never loads a stale one
        content = hashlib.sha256("".join(f.serialize() for f in funs).encode()).hexdigest()
        tag = f"{key}|{content}|{self.names}|{ca.__version__}|{' '.join(_CFLAGS)}|jac={jacobian}|fwd={tuple(forward)}"
        d = cache_dir()
        self.lib = os.path.join(d, f"{self.names[0]}_{hashlib.sha256(tag.encode()).hexdigest()[:20]}.so")
        self._proc = self._tmp = None
        if os.path.exists(self.lib):
            return
        self._tmp = tempfile.TemporaryDirectory(dir=d)
        cname = f"{self.names[0]}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False})
        for fun in funs:
            cg.add(fun)
            if jacobian:
                cg.add(fun.jacobian())
            for nd in forward:
                cg.add(fun.forward(nd))
        cg.generate(self._tmp.name + os.sep)
        self._out = os.path.join(self._tmp.name, "lib.so")
        self._proc = subprocess.Popen([cc, *_CFLAGS, "-shared", "-fPIC", os.path.join(self._tmp.name, cname), "-o",
                                       self._out, "-lm"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    def load(self) -> list:
        """Wait for the compiler (if it runs) and load the functions."""
        if self._proc is not None:
            try:
                _, err = self._proc.communicate()
                if self._proc.returncode != 0:
                    raise SimulationError(f"compiling {self.names[0]} failed: {err.strip()[:500]}")
                os.replace(self._out, self.lib)
            finally:
                self._proc = None
                self._tmp.cleanup()
        return [ca.external(name, self.lib) for name in self.names]

    def discard(self) -> None:
        """Stop a running compiler and remove its files (the build is abandoned)."""
        if self._proc is not None:
            self._proc.kill()
            self._proc.communicate()
            self._proc = None
            self._tmp.cleanup()


class _Problem:
    """The weighted output-error residual and its exact Jacobian in the fit coordinates.

    ``z = [theta, xi, vec(S)]``: the free parameters' coordinates (``p / p_start`` or
    ``log(p / p_start)``), the estimated initial states (scaled, ``x / s``) and, with multiple
    shooting, the scaled start state of every window after the first (window by window).

    The recording is cut into segments (at the input's kinks and the windows' edges), each
    integrated by one CVODES call from the end of the previous one.  The Jacobian comes from
    CVODES forward sensitivities (integrators built with CasADi's ``nfwd``: the state and its
    sensitivities integrated together, one Newton matrix for all directions) seeded by the
    derivative of the parameter vector with respect to ``theta`` and by the window's start
    state; the outputs' sensitivities follow from the output function's
    Jacobian at each sample.  Everything runs numerically on the recording's grid: nothing is
    built per recording beyond one integrator per segment length.
    """

    def __init__(self, system, recording, free, log_scaled, outputs, weights, x0, estimate_x0, rtol, atol,
                 shooting: int = 1, defect_weight: float = 1e3, compile: bool | None = None, params=None):
        # ``params``: the parameter values (default the system's); the generated functions depend on
        # the structure only, so ``system`` may be any system of the same structure (whose functions
        # are already generated)
        self.system = system
        t = recording.t
        N = len(t)
        self.N = N
        nx, nu = len(system.states), len(system.inputs)
        self.nx = nx
        pnames = system.param_names
        self.p0 = p0 = np.array(system.param_vector() if params is None else params, dtype=float)
        self.nominal = np.array([p0[pnames.index(k)] for k in free])
        self.ifree = [pnames.index(k) for k in free]
        self.is_log = np.array([k in log_scaled for k in free], dtype=bool)
        self.n_theta = len(free)
        self.ixi = [system.state_names.index(n) for n in estimate_x0]
        self.n_xi = len(estimate_x0)
        self.x0 = np.asarray(x0, dtype=float)
        U = np.column_stack([recording[u] for u in system.input_names]) if nu else np.zeros((N, 0))
        self.U = U
        grids = [(t, U[:, j]) for j in range(nu)]
        # multiple shooting: K windows, each integrated from its own (scaled) initial state; the
        # continuity defects enter the least squares with a large weight (quadratic penalty)
        K = max(1, min(int(shooting), (N - 1) // 3))
        self.K = K
        self.ms_edges = [int(e) for e in np.linspace(0, N - 1, K + 1).round().astype(int)]
        self.window_starts = np.array(self.ms_edges[1:-1], dtype=int)
        # directions of the sensitivities in each window: theta, then the window's own start
        # (the estimated initial states in the first window, the whole start state in the others)
        self.n_dir = nd = self.n_theta + max(self.n_xi, nx if K > 1 else 0)
        # a recorded input that is piecewise linear with few kinks (steps, staircases, square waves
        # as sampled) is integrated piece by piece with restarts at its kinks, so CVODES takes long
        # steps in between; otherwise it is interpolated and the step bounded by the sample interval
        # (in windows whose step bound follows the input's smoothness: see ``step_windows``)
        kinks = _kinks(U)
        piecewise = nu > 0 and len(kinks) <= max(20, (N - 1) // 20)
        windows = step_windows(U) if nu > 0 and not piecewise else []
        cuts = sorted(set(self.ms_edges) | (set(kinks) if piecewise else {w[0] for w in windows}))
        bound = np.ones(N)  # the step bound of the window each sample interval belongs to
        for w0, w1, m in windows:
            bound[w0:w1] = m
        gen = generate(system)
        scale = np.array([st.typical for st in system.states], dtype=float)  # the simulator's scaling
        # the fitted channels and their Jacobians at one sample (mapped over the recording below)
        sx = gen.sx
        rows = []
        for ch in outputs:
            if ch in system.measured_names:
                rows.append(sx["measured"][system.measured_names.index(ch)])
            elif ch in system.output_names:
                rows.append(sx["y"][system.output_names.index(ch)])
            else:
                rows.append(sx["x"][system.state_names.index(ch)])
        yv = ca.vertcat(*rows)
        xs, us, ps = sx["x"], sx["u"], sx["p"]
        self.n_out = len(outputs)
        fy = ca.Function("identify_outputs", [xs, us, ps], [yv])
        # d y / d z (scaled states) and d y / d p for the free parameters
        fyj = ca.Function("identify_output_jacobians", [xs, us, ps],
                          [ca.densify(ca.mtimes(ca.jacobian(yv, xs), ca.diag(ca.DM(scale)))),
                           ca.densify(ca.jacobian(yv, ps[self.ifree]))])
        # compiled code: the dynamics with their Jacobian and forward derivative (which CVODES's
        # sensitivities call) in one library, the output functions in another (built by a second
        # compiler process meanwhile); both cached on disk
        self.compiled = _decide_compile(compile, gen, N, nd, piecewise or nu == 0)
        mhash = _model_hash(system)
        key = f"{mhash}|identify|{nd}"
        outputs_lib = None
        if self.compiled:  # compiles while the dynamics' library is built
            outputs_lib = _Library([fy, fyj], f"{mhash}|{list(outputs)}|{self.ifree}|{scale.tolist()}")

        def compiler(fun, fkey):
            # CVODES's sensitivities call the dynamics' forward derivative one direction at a time
            return _Library([fun], f"{fkey}|{key}", jacobian=True, forward=(1,)).load()[0]

        try:
            # no energy quadratures; the second-order correction of the sensitivity Jacobian changes
            # the sensitivities by ~1e-7 relative and costs most of the time.  ``sens`` integrates the
            # state and its nd forward sensitivities together (CasADi's ``nfwd``: one Newton matrix
            # for all directions)
            opts = {"second_order_correction": False}
            sim = Simulator(system, rtol=rtol, atol=atol, energy=False, compile=self.compiled, compiler=compiler,
                            integrator_options=opts)
            sens = Simulator(system, rtol=rtol, atol=atol, energy=False, compile=self.compiled, compiler=compiler,
                             integrator_options={**opts, "nfwd": nd})
            self.scale = sim.scale
            lin = "_c0 + _c1*t"
            tmpl = sp.sympify(lin, locals={"t": TIME, "_c0": sp.Symbol("_c0", real=True),
                                           "_c1": sp.Symbol("_c1", real=True)})
            slots = [[(sp.srepr(tmpl), tmpl, 2)] for _ in range(nu)] if piecewise else [[] for _ in range(nu)]
            dt = t[1] - t[0]
            # segments: (first sample, last sample, integrator, sensitivity integrator, the integrator
            # parameters after p)
            self.segments = []
            for i0, i1 in zip(cuts[:-1], cuts[1:]):
                if piecewise:
                    F, _layout = sim._integrator(i1 - i0, slots, [None] * nu)
                    Fs, _layout = sens._integrator(i1 - i0, slots, [None] * nu)
                    coef = []
                    for j in range(nu):
                        slope = (U[i1, j] - U[i0, j]) / (t[i1] - t[i0])
                        coef += [1.0, U[i0, j] - slope * t[i0], slope]
                    tail = np.array([t[i0], dt] + coef)
                else:
                    ms = float(np.min(bound[i0:i1]))
                    F, _layout = sim._integrator(i1 - i0, [[] for _ in range(nu)], grids, ms)
                    Fs, _layout = sens._integrator(i1 - i0, [[] for _ in range(nu)], grids, ms)
                    tail = np.array([t[i0], dt])
                self.segments.append((i0, i1, F, Fs, tail))
            if outputs_lib is not None:
                fy, fyj = outputs_lib.load()
        finally:
            if outputs_lib is not None:
                outputs_lib.discard()  # after a failure: nothing left running or half-written
        self.n_P = len(p0) + len(self.segments[0][4])
        self._fy, self._fyj = fy.map(N, "serial"), fyj.map(N, "serial")
        self.Ymeas = np.vstack([recording[ch] for ch in outputs])
        self.W = np.array([weights[ch] for ch in outputs], dtype=float)
        self.n_outputs_residual = N * self.n_out
        self.n_z = self.n_theta + self.n_xi + nx * (K - 1)
        self.n_rows = self.n_outputs_residual + nx * (K - 1)
        self.defect_weight = defect_weight
        self._last = None  # (z bytes, states, window ends) of the last nominal simulation
        self._last_res = None  # (z and defect weight bytes, residual) of the last residual
        self._last_jac = None  # (z and defect weight bytes, residual, Jacobian) of the last Jacobian

    # -- the coordinates ----------------------------------------------------------------------
    def _params(self, z):
        """Parameter vector and d p_free / d theta (diagonal) at ``z``."""
        th = np.asarray(z[: self.n_theta], dtype=float)
        g = np.where(self.is_log, np.exp(th), 1.0)
        p = self.p0.copy()
        p[self.ifree] = self.nominal * np.where(self.is_log, g, th)
        return p, self.nominal * g

    def _window_start(self, z, k) -> np.ndarray:
        """Scaled start state of window ``k``."""
        if k == 0:
            z0 = self.x0 / self.scale
            z0[self.ixi] = z[self.n_theta: self.n_theta + self.n_xi]
            return z0
        o = self.n_theta + self.n_xi + (k - 1) * self.nx
        return np.array(z[o: o + self.nx], dtype=float)

    # -- simulation ---------------------------------------------------------------------------
    def _simulate(self, z):
        """Scaled states at every sample (N, nx) and the scaled end state of every window."""
        key = np.asarray(z, dtype=float).tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1], self._last[2]
        p, _ = self._params(z)
        Z = np.empty((self.N, self.nx))
        ends = []
        seg = iter(self.segments)
        for k in range(self.K):
            e0, e1 = self.ms_edges[k], self.ms_edges[k + 1]
            zc = self._window_start(z, k)
            Z[e0] = zc
            i1 = e0
            while i1 < e1:
                i0, i1, F, _Fs, tail = next(seg)
                zs = _integrate(F, zc, np.concatenate([p, tail]), self.nx, i1 - i0)
                Z[i0 + 1: i1 + 1] = zs
                zc = zs[-1]
            ends.append(zc.copy())
        self._last = (key, Z, ends)
        return Z, ends

    def _residual(self, z, Z, ends, p):
        Y = _map_call(self._fy, [Z * self.scale, self.U, np.broadcast_to(p, (self.N, len(p)))], [(self.n_out,)])[0]
        r_out = ((Y.T - self.Ymeas) * self.W[:, None]).reshape(-1)  # channel by channel
        if self.K == 1:
            return r_out
        defects = [ends[k] - self._window_start(z, k + 1) for k in range(self.K - 1)]
        return np.concatenate([r_out, self.defect_weight * np.concatenate(defects)])

    def outputs(self, z) -> np.ndarray:
        """Simulated fitted channels (n_out, N) at ``z``."""
        Z, _ = self._simulate(z)
        p = self._params(z)[0]
        return _map_call(self._fy, [Z * self.scale, self.U, np.broadcast_to(p, (self.N, len(p)))], [(self.n_out,)])[0].T

    def res(self, z):
        key = np.asarray(z, dtype=float).tobytes() + np.float64(self.defect_weight).tobytes()
        if self._last_res is not None and self._last_res[0] == key:
            return self._last_res[1].copy()
        Z, ends = self._simulate(z)
        if not np.all(np.isfinite(Z)):
            raise RuntimeError("non-finite state")
        r = self._residual(z, Z, ends, self._params(z)[0])
        self._last_res = (key, r)
        return r.copy()

    def jac(self, z):
        """Residual and its Jacobian (n_rows, n_z) at ``z``."""
        key = np.asarray(z, dtype=float).tobytes() + np.float64(self.defect_weight).tobytes()
        if self._last_jac is not None and self._last_jac[0] == key:
            return self._last_jac[1].copy(), self._last_jac[2].copy()
        r, J = self._jac(z)
        self._last_jac = (key, r, J)
        return r.copy(), J.copy()

    def _jac(self, z):
        r = self.res(z)
        p, dp = self._params(z)
        nx, nth, nd, N = self.nx, self.n_theta, self.n_dir, self.N
        seed_p = np.zeros((nd, self.n_P))  # row d: the seed of direction d (C order = column-major (n_P, nd))
        seed_p[np.arange(nth), self.ifree] = dp
        Z = np.empty((N, nx))  # the state integrated with its sensitivities
        dZ = np.empty((N, nx, nd))  # d z_i / d (window directions)
        dends = []
        seg = iter(self.segments)
        for k in range(self.K):
            e0, e1 = self.ms_edges[k], self.ms_edges[k + 1]
            zc = self._window_start(z, k)
            S = np.zeros((nx, nd))
            if k == 0:
                S[self.ixi, nth + np.arange(self.n_xi)] = 1.0
            else:
                S[:, nth: nth + nx] = np.eye(nx)
            Z[e0], dZ[e0] = zc, S
            i1 = e0
            while i1 < e1:
                i0, i1, _F, Fs, tail = next(seg)
                zs, dzs = _integrate_sensitivities(Fs, zc, S, np.concatenate([p, tail]), seed_p, i1 - i0)
                Z[i0 + 1: i1 + 1], dZ[i0 + 1: i1 + 1] = zs, dzs
                zc, S = zs[-1], dzs[-1]
            dends.append(S.copy())
        if not (np.all(np.isfinite(Z)) and np.all(np.isfinite(dZ))):
            raise RuntimeError("non-finite sensitivity")
        Cx, Cp = _map_call(self._fyj, [Z * self.scale, self.U, np.broadcast_to(p, (N, len(p)))],
                           [(nx, self.n_out), (nth, self.n_out)])
        # d y_i / d directions = C_x,i dz_i (+ C_p,i dp/dtheta in the theta directions)
        dY = np.matmul(Cx.transpose(0, 2, 1), dZ)  # (N, n_out, nd)
        dY[:, :, :nth] += Cp.transpose(0, 2, 1) * dp
        J = np.zeros((self.n_rows, self.n_z))
        for c in range(self.n_out):
            rows = slice(c * N, (c + 1) * N)
            Jc = J[rows]
            Jc[:, :nth] = self.W[c] * dY[:, c, :nth]
            for k in range(self.K):
                e0, e1 = self.ms_edges[k], self.ms_edges[k + 1]
                hi = e1 + 1 if k == self.K - 1 else e1  # a window's last sample is the next one's start
                cols = self._window_columns(k)
                Jc[e0:hi, cols] = self.W[c] * dY[e0:hi, c, nth: nth + (cols.stop - cols.start)]
        for k in range(self.K - 1):
            rows = slice(self.n_outputs_residual + k * nx, self.n_outputs_residual + (k + 1) * nx)
            wd = self.defect_weight
            J[rows, :nth] = wd * dends[k][:, :nth]
            cols = self._window_columns(k)
            J[rows, cols] = wd * dends[k][:, nth: nth + (cols.stop - cols.start)]
            nxt = self._window_columns(k + 1)
            J[rows, nxt] -= wd * np.eye(nx)
        return r, J

    def _window_columns(self, k) -> slice:
        """Columns of ``z`` that are the start-state directions of window ``k``."""
        if k == 0:
            return slice(self.n_theta, self.n_theta + self.n_xi)
        o = self.n_theta + self.n_xi + (k - 1) * self.nx
        return slice(o, o + self.nx)

    def values(self, z, log_scaled, free):
        th = z[: self.n_theta]
        return {k: float(self.nominal[i] * (np.exp(th[i]) if k in log_scaled else th[i])) for i, k in enumerate(free)}


def _integrate(F, z0, P, nx: int, n: int) -> np.ndarray:
    """Scaled states (n, nx) at the integrator's n output times (buffers written in place)."""
    buf, trigger = F.buffer()
    z0 = np.ascontiguousarray(z0, dtype=float)
    P = np.ascontiguousarray(P, dtype=float)
    out = np.empty((n, nx))
    buf.set_arg(0, memoryview(z0))
    buf.set_arg(2, memoryview(P))
    buf.set_res(0, memoryview(out))
    trigger()
    return out


def _integrate_sensitivities(Fs, z0, S0, P, seed_p, n: int):
    """States (n, nx) and forward sensitivities (n, nx, nd) at the output times of an integrator
    built with ``nfwd = nd``, for the seeds ``S0`` (nx, nd) of the initial state and ``seed_p``
    (nd, n_P) of the parameters."""
    nd, nx = seed_p.shape[0], len(z0)
    buf, trigger = Fs.buffer()
    x0 = np.ascontiguousarray(np.vstack([z0, S0.T]))  # column-major (nx, 1 + nd)
    pp = np.ascontiguousarray(np.vstack([P, seed_p]))  # column-major (n_P, 1 + nd)
    out = np.empty((n, 1 + nd, nx))  # column-major (nx, (1 + nd) n): output time by output time
    buf.set_arg(0, memoryview(x0))
    buf.set_arg(2, memoryview(pp))
    buf.set_res(0, memoryview(out))
    trigger()
    return out[:, 0, :], out[:, 1:, :].transpose(0, 2, 1)


def _map_call(F, args, shapes) -> list[np.ndarray]:
    """Call a function mapped over N samples with per-sample arguments given as (N, k) arrays;
    returns each output as an (N, *shape) array (shape of the per-sample output, column-major)."""
    N = args[0].shape[0]
    buf, trigger = F.buffer()
    keep = [np.ascontiguousarray(a, dtype=float) for a in args]
    for i, a in enumerate(keep):
        buf.set_arg(i, memoryview(a))
    outs = [np.empty((N, *shape)) for shape in shapes]
    for i, o in enumerate(outs):
        buf.set_res(i, memoryview(o))
    trigger()
    return outs


def identify(system, recording, free, *, bounds=None, x0=None, outputs=None, weights=None, log_scale=None,
             estimate_x0=(), validation=None, initial=None, rtol: float = 1e-8, atol: float | None = None,
             max_iter: int = 100, ftol: float = 1e-8, shooting: int = 1, progress: bool = False,
             compile: bool | None = None) -> IdentificationResult:
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
            # an unidentifiable parameter has a huge log-scale error: its interval is (0, inf)
            spread = float(np.exp(min(1.96 * se_z[i], 700.0)))
            ci[k] = (v / spread, v * spread if spread < 1e300 else float("inf"))
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
    if len(prob.window_starts):  # the fitted model as one trajectory (the windows joined up to the defects)
        sims = _simulate_outputs(system, recording, outs, x0_fit, params=values)
    else:  # the trajectory of the final residual
        sims = dict(zip(outs, prob.outputs(z), strict=True))
    fits = {ch: nrmse_fit(recording[ch], sims[ch]) for ch in outs}
    result = IdentificationResult(
        system=system, free=free, values=values, initial={k: float(system.param(k).value) for k in free},
        std_errors=std, intervals=ci, correlation=corr, flagged_pairs=flagged, fit_percent=fits,
        validation_fit_percent={}, residuals={ch: recording[ch] - sims[ch] for ch in outs}, cost=float(sol.cost),
        iterations=int(nfev), seconds=_time.perf_counter() - wall, x0=x0_fit, outputs=outs, weights=w,
        log_scaled=log_scaled, message=str(sol.message), _recording=recording, compiled=prob.compiled,
    )
    if validation is not None:
        result.validate(validation)
    return result
