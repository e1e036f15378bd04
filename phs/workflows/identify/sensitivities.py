"""The weighted output-error residual of a fit and its exact Jacobian from CVODES forward sensitivities.

The recording is cut into segments (at the recorded inputs' kinks, or where the step bound of a
smooth input changes, and at the multiple-shooting windows' edges); each segment is one CVODES
call from the end of the previous one, and its forward sensitivities are integrated with the state.
Large fits run the dynamics, their derivatives and the output functions as compiled C
(:mod:`phs.workflows.identify.c_library`).
"""

from __future__ import annotations

import dataclasses
import os
import shutil

import casadi as ca
import numpy as np

from codegen._inputs import input_signals, run_sampled
from codegen._layout import ParamLayout
from codegen._output import check_covered
from codegen._plan import plan_for
from codegen.functions import _model_hash, generate
from codegen.simulator import Simulator
from phs.workflows.identify.c_library import _Library

# compile by default when the fit is large: samples x (1 + directions) x the dynamics' size above this
# (the dynamics' C library, with their forward derivatives, takes a few seconds to build once per
# model and is then loaded from the disk cache; the sensitivities run 2-3 times faster compiled)
_COMPILE_WORK = 2e7


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
        nx = len(system.states)
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
        # multiple shooting: K windows, each integrated from its own (scaled) initial state; the
        # continuity defects enter the least squares with a large weight (quadratic penalty)
        K = max(1, min(int(shooting), (N - 1) // 3))
        self.K = K
        self.ms_edges = [int(e) for e in np.linspace(0, N - 1, K + 1).round().astype(int)]
        self.window_starts = np.array(self.ms_edges[1:-1], dtype=int)
        # directions of the sensitivities in each window: theta, then the window's own start
        # (the estimated initial states in the first window, the whole start state in the others)
        self.n_dir = nd = self.n_theta + max(self.n_xi, nx if K > 1 else 0)
        # the recording's inputs as a simulation reads them (held, interpolated, a declared law, a course between
        # the samples: Recording.input_signal), cut into the simulator's own runs (codegen._plan): straight lines
        # between the kinks of inputs with few kinks and over the long straight stretches of the others, an
        # interpolant with a step bound elsewhere, a restart at every jump of a held input; the windows' edges
        # are breakpoints too
        sigs = input_signals(system, {n: recording.input_signal(n) for n in system.input_names}, t)
        plan = plan_for(t, sigs, cuts=tuple(t[self.window_starts].tolist()))
        self.U = plan.U
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
        self.compiled = _decide_compile(compile, gen, N, nd, all(g is None for g in plan.sampled))
        cc = _c_compiler() if self.compiled else None
        mhash = _model_hash(system)
        key = f"{mhash}|identify|{nd}"
        outputs_lib = None
        if self.compiled:  # compiles while the dynamics' library is built
            outputs_lib = _Library([fy, fyj], f"{mhash}|{list(outputs)}|{self.ifree}|{scale.tolist()}", cc)

        def compiler(fun, fkey):
            # CVODES's sensitivities call the dynamics' forward derivative one direction at a time
            return _Library([fun], f"{fkey}|{key}", cc, jacobian=True, forward=(1,)).load()[0]

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
            window_times = t[self.window_starts] - plan.origin  # the runs count time from the grid's start
            self.segments = []
            for r in plan.runs:
                sampled = run_sampled(plan.sampled, r.choice, r)
                F, layout = sim._integrator(r.n, plan.slots, sampled, r.max_step)
                Fs, layout_s = sens._integrator(r.n, plan.slots, sampled, r.max_step)
                tail = sim._pvec(np.zeros(0), r.start, r.step, layout, r.choice)
                # the window a run belongs to: the number of window starts at or before its start (grid points,
                # so a run starting on one starts exactly there)
                window = int(np.searchsorted(window_times, r.start + 1e-9 * r.step, side="right"))
                self.segments.append(_Segment(r.j[r.on], r.on, window, F, Fs, tail, layout, layout_s))
            check_covered(plan.runs, N, f"identification on {recording.source}")
            if outputs_lib is not None:
                fy, fyj = outputs_lib.load()
        finally:
            if outputs_lib is not None:
                outputs_lib.discard()  # after a failure: nothing left running or half-written
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
        self._attainable: dict = {}  # the last Jacobian's key: its Gauss-Newton step's predicted decrease
        self.cost_resolution = 0.0  # the cost's resolution at the last Jacobian's point (see _jac)

    # -- the coordinates ----------------------------------------------------------------------
    def _params(self, z):
        """Parameter vector and d p_free / d theta (diagonal) at ``z``."""
        th = np.asarray(z[: self.n_theta], dtype=float)
        g = np.where(self.is_log, np.exp(np.clip(th, -700.0, 700.0)), 1.0)  # beyond: a float overflow, not a value
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
        k = 0
        zc = self._window_start(z, 0)
        Z[0] = zc
        for sg in self.segments:
            if sg.window != k:  # a window's first run: the previous window ends, this one starts from its own state
                ends.append(zc.copy())
                k = sg.window
                zc = self._window_start(z, k)
                Z[self.ms_edges[k]] = zc
            zs = _integrate(sg.F, zc, np.concatenate([p, sg.tail]), self.nx, len(sg.on))
            Z[sg.rows] = zs[sg.on]
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
        return self.outputs_of(Z, self._params(z)[0])

    def outputs_of(self, Z, p) -> np.ndarray:
        """The fitted channels (n_out, N) of the scaled states ``Z`` (N, nx) under the parameter vector ``p``."""
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
        # row d: the seed of direction d in the model's parameters (the run's and the inputs' entries of a
        # segment's parameter vector, which differ by segment kind, have none: see _Segment.seeds)
        seed_p = np.zeros((nd, len(p)))
        seed_p[np.arange(nth), self.ifree] = dp
        Z = np.empty((N, nx))  # the state integrated with its sensitivities
        dZ = np.empty((N, nx, nd))  # d z_i / d (window directions)
        dends = []
        k, S, zc = -1, None, None
        for sg in self.segments:
            if sg.window != k:  # a window's first run: its own start state, seeded by its own directions
                if k >= 0:
                    dends.append(S.copy())
                k = sg.window
                zc = self._window_start(z, k)
                S = np.zeros((nx, nd))
                if k == 0:
                    S[self.ixi, nth + np.arange(self.n_xi)] = 1.0
                else:
                    S[:, nth: nth + nx] = np.eye(nx)
                e0 = self.ms_edges[k]
                Z[e0], dZ[e0] = zc, S
            zs, dzs = _integrate_sensitivities(sg.Fs, zc, S, np.concatenate([p, sg.tail]), sg.seeds(seed_p), len(sg.on))
            Z[sg.rows], dZ[sg.rows] = zs[sg.on], dzs[sg.on]
            zc, S = zs[-1], dzs[-1]
        dends.append(S.copy())
        if not (np.all(np.isfinite(Z)) and np.all(np.isfinite(dZ))):
            raise RuntimeError("non-finite sensitivity")
        Cx, Cp = _map_call(self._fyj, [Z * self.scale, self.U, np.broadcast_to(p, (N, len(p)))],
                           [(nx, self.n_out), (nth, self.n_out)])
        # the state integrated with its sensitivities took steps of its own (their error is controlled too):
        # the two costs of one point differ by about the integration's error in the cost, below which a
        # decrease is not resolved (read by the fit's stopping rule, phs.workflows.identify.solve)
        r_out = r[: self.n_outputs_residual]
        r_sens = ((self.outputs_of(Z, p) - self.Ymeas) * self.W[:, None]).reshape(-1)
        self.cost_resolution = abs(0.5 * float(r_sens @ r_sens - r_out @ r_out))
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

    def predicted_decrease(self, z) -> float:
        """The decrease of the cost ``½|r|²`` from the last Jacobian's point to ``z`` that the residual's
        linearisation there predicts (the Gauss-Newton model a trust-region step is chosen on); infinite
        before a first Jacobian."""
        if self._last_jac is None:
            return float("inf")
        key, r, J = self._last_jac
        at = np.frombuffer(key[:-8], dtype=float)  # the key: the point's bytes, then the defect weight's
        z = np.asarray(z, dtype=float)
        if at.shape != z.shape:
            return float("inf")
        Jd = J @ (z - at)
        return -float(r @ Jd + 0.5 * Jd @ Jd)

    def attainable_decrease(self) -> float:
        """The largest decrease of the cost ``½|r|²`` the residual's linearisation at the last Jacobian's
        point predicts for any step (the full Gauss-Newton step's, ``½|P r|²`` with ``P`` the projection on
        the Jacobian's columns; bounds ignored); infinite before a first Jacobian."""
        if self._last_jac is None:
            return float("inf")
        key, r, J = self._last_jac
        if key not in self._attainable:
            step = np.linalg.lstsq(J, r, rcond=None)[0]
            Jd = J @ step
            self._attainable = {key: 0.5 * float(Jd @ Jd)}
        return self._attainable[key]

    def _window_columns(self, k) -> slice:
        """Columns of ``z`` that are the start-state directions of window ``k``."""
        if k == 0:
            return slice(self.n_theta, self.n_theta + self.n_xi)
        o = self.n_theta + self.n_xi + (k - 1) * self.nx
        return slice(o, o + self.nx)

    def values(self, z, log_scaled, free):
        th = z[: self.n_theta]
        return {k: float(self.nominal[i] * (np.exp(th[i]) if k in log_scaled else th[i])) for i, k in enumerate(free)}


@dataclasses.dataclass(frozen=True)
class _Segment:
    """One CVODES call of a fit (a run of the simulator's plan, :class:`codegen._output.OutputRun`): the samples its
    output steps land on (``rows``; ``on`` marks which output steps are samples: a breakpoint between samples is an
    output step of its own), the multiple-shooting window it belongs to, the plain and the sensitivity integrator,
    the part of their parameter vector after the model's parameters (``tail``) and their layouts, checked against
    the tail where the segment is made: a line segment's vector carries its inputs' weights and constants, an
    interpolated stretch's does not."""

    rows: np.ndarray
    on: np.ndarray
    window: int
    F: object
    Fs: object
    tail: np.ndarray
    layout: ParamLayout
    layout_s: ParamLayout

    def __post_init__(self):
        where = f"fit segment ending at sample {int(self.rows[-1]) if len(self.rows) else '?'}"
        self.layout.check(np.zeros(self.layout.n_model + len(self.tail)), where)
        self.layout_s.check(np.zeros(self.layout_s.n_model + len(self.tail)), where)

    def seeds(self, seed_p: np.ndarray) -> np.ndarray:
        """The seeds ``(nd, size)`` of this segment's parameter vector from those of the model's parameters
        ``seed_p`` ``(nd, n_model)`` (zero for the run's and the inputs' entries)."""
        out = np.zeros((seed_p.shape[0], self.layout_s.size))
        out[:, : seed_p.shape[1]] = seed_p
        return out


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
