"""Recordings of the electrostatic actuator whose truth holds physics outside the diagnosis library,
simulated from hand-written equations with scipy.

The specimen (:data:`examples.concealed_truths.BASE`), the voltage programs (``steps``: training and
validation runs of :func:`examples.concealed_effects.program`), the sampling (1 kHz), the channels and the
noise (1 % of the position's range, 3 % of the current's std) are those of :mod:`examples.concealed_novel`.
The truths are not built from components and not run by the framework's simulator: their right-hand
sides are written out below with numpy and integrated by scipy (:func:`simulate`), so a
recording does not share its equations with the models the diagnosis fits.  The nominal model is
:func:`systems.electrostatic_actuator.electrostatic_actuator`: ``x' = p/m``, ``p' = -k x - b p/m +
Q²/(2 eps A)``, ``Q' = i``, ``i = (U - Q (g0 - x)/(eps A)) / R_s``; measured ``position = x`` and
``current = i``.  The cases (:data:`OUTSIDE`; sizes at ``size = 1`` in :data:`SIZES`):

second_mode
    The moving electrode carries a flexible appendage: a mass ``m2`` = 0.3 g (0.3 m) joined to it by
    a spring ``k2`` and a damper ``c2`` (the appendage alone rings at ``f2`` = 90 Hz with damping
    ratio ``zeta2`` = 0.03: ``k2 = m2 (2 pi f2)²`` = 95.9 N/m, ``c2 = 2 zeta2 sqrt(k2 m2)`` = 0.0102
    N s/m).  States ``x, p, Q, x2, p2`` (``x2`` the appendage's displacement, ``p2 = m2 x2'``); the
    appendage pulls on the electrode with ``k2 (x2 - x) + c2 (p2/m2 - p/m)``.  Coupled, the
    actuator's modes are 29.5 Hz, damping ratio 0.047 (the bare electrode's 34.1 Hz, 0.056, lowered
    by the appendage's mass) and 104 Hz, damping ratio 0.039: well above the main resonance, below the
    500 Hz Nyquist frequency.  The sensor reads the electrode's ``x``.  An extra storage (mass and spring)
    with its dissipation, on ``x``.  ``size`` scales ``m2``, ``k2`` and ``c2`` together (the
    appendage's own frequency and damping ratio stay).
stiffness_drift
    The suspension softens as it warms during the recording:
    ``k(t) = k (1 - a (1 - exp(-t / T_d)))`` with ``a`` = 0.2 and ``T_d`` = 8 s (a 20 s run ends
    18.4 % softer, a 3 s run 6.3 %); every recording, the validation run too, starts cold (``t`` from 0).  A drift of
    a parameter in time, on ``x``.  ``size`` scales ``a``.
current_limit
    The drive limits its output current: ``i = i_max tanh(i_nom / i_max)`` with ``i_nom = (U - Q
    (g0 - x)/(eps A)) / R_s``, and the recorded current is ``i``.  ``i_max`` = 2.0 uA, half the
    largest ``|i_nom|`` the nominal actuator draws on the 20 s training program (4.01 uA, at the
    edges of the +-16 V square wave repeated at 1.08 times its amplitude); the validation run's steps
    draw up to 2.16 uA.  The source's RC time is 1.1 us: where the program asks less than ``i_max``
    the drop across the source grows until the asked current flows, and the recorded current is the
    nominal one; where it asks more (the training run's square-wave edges, the validation run's largest
    step, REST to 19.4 V) the gap charges at about ``i_max`` and the current's spike is cut.  A saturating
    series conductance between the source and the gap (dissipative: ``(U - V_C) i >= 0``), at the
    input ``U``.  ``size`` divides ``i_max``.
flexible_mode
    The equations of ``second_mode`` with an appendage tuned near the electrode's resonance and lightly
    damped: ``m2`` = 0.1 g (0.1 m), ``f2`` = 38 Hz, ``zeta2`` = 0.01 (``k2`` = 5.70 N/m, ``c2`` = 4.78e-4
    N s/m).  Coupled, the modes are 30.3 Hz, damping ratio 0.038, and 42.8 Hz, 0.027: two modes on
    either side of the bare electrode's 34.1 Hz, whose beating no single
    mass, spring and damper reproduce.  Driven by the ``ringing`` program (:data:`PROGRAM`: square waves
    of four amplitudes; validation with a 10-50 Hz chirp across both modes).  An extra storage on ``x``;
    ``size`` as for ``second_mode``.

``size`` -> 0 gives the nominal actuator in every case.  Between samples the command is read as the
recordings declare it (``holds={"U": "linear"}``) and as the framework's simulator reads such an
input (:func:`reading`, from the simulator's plan): a straight line between the kinks of a
piecewise-linear command (the training runs), and where the samples hold a sine or a chirp (the
validation runs) the lines over their straight stretches, the cubic not-a-knot spline through every
sample over the windows smooth enough for long steps (:func:`codegen._grid.step_windows`), the spline
of a window's own samples where it is smooth but bounded to one sample interval, the line between
samples elsewhere.  Read otherwise (a line everywhere), the current of the validation run's first cycle
would differ from the framework's reading by up to 2.0e-3 of its range, five times its noise std, where
the chirp reaches 30 Hz (half a sample of delay), and the position by 8.4e-4 of its range: an error of
the reading, not of the physics.

Measured with ``python examples/concealed_outside.py`` (20 s runs, seed 0, each case on its program; the nominal model
refitted on the training run, free ``k, b, eps``, with :func:`phs.workflows.identify.identify`):
fit % as position / current; ``gain`` the truth's own validation gain over the refit
(:func:`examples.concealed_novel.truth_gain`, the sum over channels of RSS over the channel's
variance), ``noise`` the noise-free truth's own validation RSS in those units:

| case | nominal refit, training | nominal refit, validation | noise-limited, validation | gain | noise | gain / noise |
| --- | --- | --- | --- | ---: | ---: | ---: |
| second_mode | 86.2 / 81.9 | 83.0 / 81.8 | 90.5 / 97.0 | 1042.6 | 199.9 | 5.22 |
| stiffness_drift | 83.0 / 96.5 | 81.4 / 96.1 | 90.7 / 97.0 | 531.6 | 191.1 | 2.78 |
| current_limit | 83.0 / 64.1 | 83.6 / 87.6 | 91.8 / 97.0 | 698.9 | 151.0 | 4.63 |
| flexible_mode | 79.6 / 84.4 | 66.4 / 84.0 | 92.7 / 97.0 | 2649.7 | 123.2 | 21.50 |

Measured the same way, the novel cases' gain over their noise is 0.99 (fringe_field), 17.9
(heating_resistance), 5.8 (engaging_spring), 2.4 (softening_stiffness) and 7.5 (drive_gain).  The
specimen's own nominal actuator (``size`` 1e-9) would lose on these validation runs 4510, 2670 and
13.8 (position + current): the current limit's validation run hardly reaches the limit, and its loss
is that of a refit pulled off by the training run's cut edges (eps, which sets the spikes' height).

What a rigid added mass leaves of ``second_mode``: refitted with ``m`` free too (``k, b, eps, m``, what
the library's ``added_mass`` expresses), the refit comes within 2.4 of the truth's validation RSS (0.01
of the noise's): on these programs the 104 Hz mode's own ringing lies below the noise, and the case
asks whether a diagnosis finds the appendage's mass more than its mode.  Across the ranges the case is
meant to span it stays so (m2, mode, damping ratio: 0.3 m, 82 Hz, 0.02: 0.04 of the noise's RSS; 0.4 m,
85 Hz, 0.02: 0.07; 0.4 m, 96 Hz, 0.02: 0.03; 0.5 m, 88 Hz, 0.02: 0.11), while the nominal refit loses 6
to 35 times the noise's RSS there.  The voltage steps excite the mode, but its ringing decays with a
time constant of 39 ms (damping ratio 0.039 at 104 Hz), and the programs hold no sine near it.

What a rigid added mass leaves of ``flexible_mode`` (``python examples/concealed_outside.py --cases
flexible_mode --free k,b,eps,m``): the refit with ``m`` free (m = 1.29 g) scores 69.6 / 95.4 on validation
(the nominal refit 66.4 / 84.0) and still loses 1770.6 over the truth's validation RSS, 0.67 of the truth's
gain of 2649.7 and 14.4 times the noise's 123.2: the mass takes the current's loss, not the beating of the
two modes in the position.  Chosen on 8 s runs (gain / noise of the nominal refit; share of the truth's
gain the ``m``-free refit leaves): heavy appendages above the resonance are a rigid mass on these
programs (m2, f2, zeta2: 0.5 m, 40 Hz, 0.01: 66, 0.09; 0.7 m, 55 Hz, 0.015: 66, 0.01; 1.0 m, 40 Hz, 0.015:
80, 0.04; 0.3 m, 45 Hz, 0.01: 22, 0.13), lighter ones near it are not (0.1 m, 45 Hz, 0.01: 7.4, 0.41;
0.2 m, 40 Hz: 29, 0.42; 0.15 m, 37 Hz, 0.015: 37, 0.53; 0.1 m, 38 Hz: 25, 0.64; 0.1 m, 34 Hz: 65, 0.55;
at 36 Hz on 20 s runs: 29, 0.65).  Tuned below the resonance (0.05-0.3 m at 28-30 Hz) the ``m``-free refit
gains nothing (a share of 0.89-1.17: it ends in another local minimum) and the nominal position fit falls
below 50 %.

Examples
--------
>>> rec, info = generate("second_mode", seconds=0.5)
>>> rec.names, info["nature"], info["state"], sorted(info["clean"])
(['U', 'position', 'current'], 'storage', 'x', ['current', 'position'])
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

from phs.errors import InputDataError

if __package__:  # imported as examples.concealed_outside
    from .concealed_effects import CHANNELS, NOISE, NOMINAL_FREE, PROGRAMS, program
    from .concealed_novel import truth_gain
    from .concealed_truths import BASE
else:  # run as a script: the modules beside this file
    if os.path.dirname(os.path.abspath(__file__)) not in sys.path:
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from concealed_effects import CHANNELS, NOISE, NOMINAL_FREE, PROGRAMS, program
    from concealed_novel import truth_gain
    from concealed_truths import BASE

__all__ = ["OUTSIDE", "SIZES", "NATURE", "INPUT", "PROGRAM", "parameters", "command", "reading", "simulate", "generate",
           "concealment", "truth_gain"]

OUTSIDE = ("second_mode", "stiffness_drift", "current_limit", "flexible_mode")
"""The cases: an extra mechanical mode (an appendage ringing far above the resonance, then a light one tuned near it), a slow drift of a
parameter, a current limit at the electrical input."""
SIZES = {
    "second_mode": {"m2": 0.3e-3, "f2": 90.0, "zeta2": 0.03},
    "stiffness_drift": {"a": 0.2, "T_d": 8.0},
    "current_limit": {"i_max": 2.0e-6},
    "flexible_mode": {"m2": 0.1e-3, "f2": 38.0, "zeta2": 0.01},
}
"""Each effect at ``size = 1``: the appendage's mass [kg], own frequency [Hz] and damping ratio; the share
the stiffness loses when warm and the warming's time constant [s]; the drive's current limit [A].  Chosen on
the refitted nominal model's validation loss on 20 s runs (module docstring): the truth's own gain 2.8-5.2 times
the noise's RSS, inside the novel cases' 1.0-17.9; with m2 0.4 m it was 8.6, with a = 0.15 1.6, with i_max 1.5 uA
(0.37 of the largest nominal current) 26, with 3 uA 0.3.  Within the ranges the cases are meant to span (m2
0.3-0.5 m, a mode at 80-150 Hz with damping ratio 0.02-0.05; a 0.1-0.2 and T_d of the order of the run;
i_max 0.3-0.6 of the largest nominal current).  ``flexible_mode`` was chosen otherwise: a mode a rigid added mass
does not explain (a refit with ``m`` free leaves 0.67 of the truth's gain of 21.5 times the noise's RSS; the
appendages tried are in the module docstring)."""
NATURE = {"second_mode": ("storage", "x"), "stiffness_drift": ("drift", "x"), "current_limit": ("dissipative", "Q"),
          "flexible_mode": ("storage", "x")}
"""What discovery should say: an extra storage (mass and spring, with its damper), a parameter drifting in
time, a dissipation (the limit is a saturating conductance in the source's loop); and on which state."""
INPUT = {"current_limit": "U"}
"""The input at which an input case acts."""
PROGRAM = {"flexible_mode": "ringing"}
"""The voltage program of a case (:data:`examples.concealed_effects.TRAINING` and ``VALIDATION``; default
``steps``): ``ringing``'s square-wave edges set the appendage ringing and its validation chirp sweeps 10-50 Hz
across both modes.  Chosen on 8 s runs of ``flexible_mode``: on ``steps`` the nominal refit loses 7.1 times the
noise's RSS and a refit with ``m`` free leaves 0.28 of the truth's gain, on ``ringing`` 25 and 0.64.  The other
cases keep ``steps``, on which their sizes were chosen."""
_APPENDAGE = ("second_mode", "flexible_mode")  # the cases with an appendage (the same equations, other sizes)
RTOL = 1e-10
"""Relative tolerance of the scipy integration (absolute: a hundredth of it times each state's typical size,
:data:`_TYPICAL`).  Chosen on 3 s runs of the appendage case (then m2 = 0.4 g) against scipy's BDF at 1e-11: LSODA at 1e-10 agrees
to 9e-10 of the position's range and 1.3e-7 of the current's (at 1e-9: 7e-9 and 1.1e-6), 0.3-0.4 s a run;
Radau at 1e-9 takes 4 s (a 20 s run: 23-31 s).  The current ``U - Q/C(x)`` over ``R_s`` is a difference of two
nearly equal voltages, hence the tight tolerance."""
_TYPICAL = np.array([1e-5, 2e-6, 2e-9, 1e-5, 1e-6])  # x [m], p [kg m/s], Q [C], x2 [m], p2 [kg m/s]
_FORMS = {
    "second_mode": "a flexible appendage: mass m2 on a spring k2 and damper c2 riding on the electrode",
    "stiffness_drift": "suspension stiffness drifting as it warms: k(t) = k (1 - a (1 - exp(-t/T_d)))",
    "current_limit": "the drive's current limit: i = i_max tanh(i_nom / i_max), i_nom = (U - Q/C(x)) / R_s",
    "flexible_mode": "an appendage tuned near the resonance: mass m2 on a lightly damped spring k2 and damper c2 riding on the electrode",
}


def parameters(effect: str, size: float = 1.0) -> dict:
    """The effect's parameters at ``size`` (SI units; the appendage cases also give ``k2`` and ``c2``).

    Raises
    ------
    InputDataError
        For an unknown case, a size that is not a positive finite number, or a drift so large that the
        stiffness would reach zero.

    Examples
    --------
    >>> p = parameters("second_mode", 0.5)
    >>> p["m2"], round(p["k2"], 1), p["f2"]
    (0.00015, 48.0, 90.0)
    >>> parameters("current_limit", 2.0)
    {'i_max': 1e-06}
    """
    if effect not in OUTSIDE:
        raise InputDataError(f"unknown case {effect!r}; known: {', '.join(OUTSIDE)}")
    if isinstance(size, bool) or not isinstance(size, (int, float, np.integer, np.floating)) or not (0 < size < math.inf):
        raise InputDataError(f"{effect}: effect size must be a positive finite number, got {size!r}")
    v = dict(SIZES[effect])
    size = float(size)
    if effect in _APPENDAGE:
        m2 = v["m2"] * size
        k2 = m2 * (2 * math.pi * v["f2"]) ** 2
        return {"m2": m2, "f2": v["f2"], "zeta2": v["zeta2"], "k2": k2, "c2": 2 * v["zeta2"] * math.sqrt(k2 * m2)}
    if effect == "stiffness_drift":
        if v["a"] * size >= 1.0:
            raise InputDataError(f"stiffness_drift: size {size} makes the stiffness fall to zero (a = {v['a'] * size:g} >= 1)")
        return {"a": v["a"] * size, "T_d": v["T_d"]}
    return {"i_max": v["i_max"] / size}


def command(effect: str, seconds: float, validation: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Sample times and voltage command of a case's training or validation run: the program :data:`PROGRAM`
    names, as :func:`examples.concealed_effects.program` gives it to the library's cases driven by it
    (``steps`` to the control ``none``, ``ringing`` to ``quadratic_drag``).

    Examples
    --------
    >>> t, U = command("flexible_mode", 1.0)
    >>> bool(np.array_equal(U, program("quadratic_drag", 1.0)[1])), len(t)
    (True, 1001)
    >>> bool(np.array_equal(command("second_mode", 1.0, validation=True)[1], program("none", 1.0, validation=True)[1]))
    True
    """
    if effect not in OUTSIDE:
        raise InputDataError(f"unknown case {effect!r}; known: {', '.join(OUTSIDE)}")
    kind = PROGRAM.get(effect, "steps")
    driven = "none" if kind == "steps" else min(e for e, k in PROGRAMS.items() if k == kind)
    return program(driven, seconds, validation)


# -- the command between samples -----------------------------------------------------------------------------------------
def reading(t, U) -> list[tuple[int, int, str]]:
    """How the command is read between samples: pieces ``(i0, i1, kind)`` over sample indices, ``kind``
    ``"line"`` (the straight line from sample ``i0`` to ``i1``, no kink between), ``"spline"`` (the cubic
    not-a-knot spline through every sample of the command, smooth across the piece) or ``"local"`` (the cubic
    not-a-knot spline through the piece's own samples ``i0 .. i1`` alone).

    As the framework's simulator reads a sampled input declared linear, taken from its plan
    (:func:`codegen._plan.plan_for`): where a run lets the step span several samples the spline of all
    samples, where a run bounded by one interval is smooth on its own samples their local spline
    (:func:`codegen._grid.bounded_runs`), elsewhere the line between samples, one line across samples that
    lie on it (a hold, a ramp between kinks).

    Examples
    --------
    >>> t, U = program("none", 1.0)
    >>> reading(t, U)[:2]
    [(0, 1, 'line'), (1, 199, 'line')]
    >>> t, U = program("none", 3.0, validation=True)
    >>> sorted({k for _, _, k in reading(t, U)})
    ['line', 'local', 'spline']
    """
    from codegen._interpolants import interpolation
    from codegen._plan import plan_for
    from phs.signals import Sampled

    t, U = np.asarray(t, dtype=float), np.asarray(U, dtype=float)
    plan = plan_for(t, [Sampled(tuple(t), tuple(U))])
    tol = 1e-9 * (float(np.max(np.abs(U))) + 1e-300)  # a sample on the line of its neighbours, to rounding
    rel = t - plan.origin
    out: list[tuple[int, int, str]] = []
    for r in plan.runs:
        i0 = int(np.searchsorted(rel, r.start - 1e-9 * r.step))
        i1 = int(np.searchsorted(rel, r.start + r.n * r.step - 1e-9 * r.step))
        if r.choice[0] is None and r.local:
            out.append((i0, i1, "local"))
        elif r.choice[0] is None and interpolation(len(t), r.max_step) == "bspline":
            out.append((i0, i1, "spline"))
        else:
            for j in range(i0, i1):
                if out and out[-1][2] == "line" and out[-1][1] == j and _on_line(t, U, out[-1][0], j, j + 1, tol):
                    out[-1] = (out[-1][0], j + 1, "line")
                else:
                    out.append((j, j + 1, "line"))
    return out


def _on_line(t, U, i0: int, j: int, i1: int, tol: float) -> bool:
    """Whether sample ``j`` lies on the straight line from sample ``i0`` to sample ``i1`` (within ``tol``)."""
    u = U[i0] + (U[i1] - U[i0]) * (t[j] - t[i0]) / (t[i1] - t[i0])
    return bool(abs(u - U[j]) <= tol)


# -- the truths' equations -----------------------------------------------------------------------------------------------
def _equations(effect: str, v: dict):
    """Right-hand side ``f(t, z, u)``, its Jacobian in ``z`` and the measured channels of a truth, written out."""
    m, k, b, eps, A, g0, Rs = (BASE[n] for n in ("m", "k", "b", "eps", "A", "g0", "R_s"))
    ea = eps * A
    two, drift, limit = effect in _APPENDAGE, effect == "stiffness_drift", effect == "current_limit"
    m2, k2, c2 = (v.get(n, 1.0) for n in ("m2", "k2", "c2"))
    a, Td, imax = v.get("a", 0.0), v.get("T_d", 1.0), v.get("i_max", 1.0)

    def stiffness(tt):
        return k * (1.0 + a * math.expm1(-tt / Td)) if drift else k

    def current(z, u):
        """Source current and its derivative with respect to the nominal current."""
        i_nom = (u - z[2] * (g0 - z[0]) / ea) / Rs
        if not limit:
            return i_nom, 1.0
        r = i_nom / imax
        return imax * math.tanh(r), 1.0 / math.cosh(r) ** 2 if abs(r) < 350 else 0.0

    def f(tt, z, u):
        x, p, Q = z[0], z[1], z[2]
        vel = p / m
        i, _ = current(z, u)
        F = -stiffness(tt) * x - b * vel + Q * Q / (2 * ea)
        if not two:
            return np.array([vel, F, i])
        Fa = k2 * (z[3] - x) + c2 * (z[4] / m2 - vel)
        return np.array([vel, F + Fa, i, z[4] / m2, -Fa])

    def jac(tt, z, u):
        x, Q = z[0], z[2]
        J = np.zeros((len(z), len(z)))
        _, g = current(z, u)
        J[0, 1] = 1 / m
        J[1, 0], J[1, 1], J[1, 2] = -stiffness(tt), -b / m, Q / ea
        J[2, 0], J[2, 2] = g * Q / (ea * Rs), -g * (g0 - x) / (ea * Rs)
        if two:
            J[1, 0] -= k2
            J[1, 1] -= c2 / m
            J[1, 3], J[1, 4] = k2, c2 / m2
            J[3, 4] = 1 / m2
            J[4, 0], J[4, 1], J[4, 3], J[4, 4] = k2, c2 / m, -k2, -c2 / m2
        return J

    def measured(Z, U):
        x, Q = Z[:, 0], Z[:, 2]
        i_nom = (U - Q * (g0 - x) / ea) / Rs
        return {"position": x.copy(), "current": imax * np.tanh(i_nom / imax) if limit else i_nom}

    return (5 if two else 3), f, jac, measured


def simulate(effect: str, t, U, size: float = 1.0) -> dict:
    """Noise-free ``position`` and ``current`` of a truth driven by the command ``U`` sampled at ``t``
    (from rest, no charge), the command read between samples as :func:`reading` says.

    The equations are integrated by scipy's LSODA (BDF on these stiff equations: the source's RC time is
    1.1 us) with their hand-written Jacobian at :data:`RTOL`,
    restarting wherever the command has a kink (at each piece of :func:`reading`).

    Examples
    --------
    >>> t, U = program("none", 0.5)
    >>> a, b = simulate("current_limit", t, U), simulate("current_limit", t, U, size=1e-6)
    >>> bool(np.max(np.abs(a["current"])) < np.max(np.abs(b["current"])))
    True
    """
    from scipy.integrate import solve_ivp
    from scipy.interpolate import make_interp_spline

    from phs.errors import SimulationError

    v = parameters(effect, size)
    t, U = np.asarray(t, dtype=float), np.asarray(U, dtype=float)
    n_states, f, jac, measured = _equations(effect, v)
    pieces = reading(t, U)
    spline = make_interp_spline(t, U, k=3) if any(kind == "spline" for _, _, kind in pieces) else None
    atol = RTOL * 1e-2 * _TYPICAL[:n_states]
    Z = np.zeros((len(t), n_states))
    z = np.zeros(n_states)
    for i0, i1, kind in pieces:
        a, b = float(t[i0]), float(t[i1])
        if kind == "line":
            ua, slope = float(U[i0]), float((U[i1] - U[i0]) / (b - a))

            def u_at(tt, ua=ua, slope=slope, a=a):
                return ua + slope * (tt - a)
        else:
            course = spline if kind == "spline" else make_interp_spline(t[i0:i1 + 1], U[i0:i1 + 1], k=3)

            def u_at(tt, course=course):
                return float(course(tt))
        sol = solve_ivp(lambda tt, zz: f(tt, zz, u_at(tt)), (a, b), z, method="LSODA", t_eval=t[i0 + 1:i1 + 1], rtol=RTOL,
                        atol=atol, jac=lambda tt, zz: jac(tt, zz, u_at(tt)))
        if not sol.success or sol.y.shape[1] != i1 - i0:
            raise SimulationError(f"{effect}: the integration failed between t = {a:g} and {b:g} s ({sol.message})")
        Z[i0 + 1:i1 + 1] = sol.y.T
        z = sol.y[:, -1]
    if np.any(Z[:, 0] >= BASE["g0"]):
        raise SimulationError(f"{effect}: the gap closed (x reached g0 = {BASE['g0']} m)")
    return measured(Z, U)


# -- recordings ----------------------------------------------------------------------------------------------------------
def generate(effect: str, *, seconds: float = 20.0, seed: int = 0, validation: bool = False, size: float = 1.0):
    """A noisy 1 kHz recording of a truth outside the library, and what the truth was.

    Parameters
    ----------
    effect : str
        One of :data:`OUTSIDE`.
    seconds : float
        Length of the recording (at least 0.5 s).
    seed : int
        Noise seed; every case, seed and split has its own stream.
    validation : bool
        The validation program instead of the training program (the drift starts cold again).
    size : float
        Multiplier of the effect's strength (:func:`parameters`).

    Returns
    -------
    (Recording, dict)
        Signals ``U``, ``position``, ``current``; ``info``: ``effect``, ``form``, ``parameters``,
        ``nature``, ``state`` and ``input`` (what discovery should name), ``noise_std``, ``clean``,
        ``nominal_free``, ``base_parameters``, ``program``, ``seed``, ``seconds``, ``validation``, ``size``.

    Raises
    ------
    InputDataError
        For an unknown case, a size that is not positive and finite, a recording shorter than 0.5 s.

    Examples
    --------
    >>> rec, info = generate("stiffness_drift", seconds=0.5, validation=True)
    >>> len(rec), info["parameters"], info["validation"]
    (501, {'a': 0.2, 'T_d': 8.0}, True)
    """
    from phs.workflows.recording import Recording

    v = parameters(effect, size)
    t, U = command(effect, seconds, validation)
    clean = simulate(effect, t, U, size)
    scale = {"position": float(np.ptp(clean["position"])), "current": float(np.std(clean["current"]))}
    noise_std = {ch: NOISE[ch] * scale[ch] for ch in CHANNELS}
    rng = np.random.default_rng([200 + OUTSIDE.index(effect), int(seed), int(bool(validation))])
    noisy = {ch: clean[ch] + noise_std[ch] * rng.standard_normal(len(t)) for ch in CHANNELS}
    split = "validation" if validation else "train"
    rec = Recording.from_arrays(t, {"U": U, **noisy}, source=f"concealed_outside:{effect}:{split}",
                                units={"U": "V", "position": "m", "current": "A"}, holds={"U": "linear"})
    nature, state = NATURE[effect]
    return rec, {"effect": effect, "form": _FORMS[effect], "parameters": v, "nature": nature, "state": state,
                 "input": INPUT.get(effect, ""), "noise_std": noise_std, "clean": clean, "nominal_free": list(NOMINAL_FREE),
                 "base_parameters": dict(BASE), "program": PROGRAM.get(effect, "steps"), "seed": int(seed), "seconds": float(seconds),
                 "validation": bool(validation), "size": float(size)}


def concealment(effect: str, *, seconds: float = 20.0, seed: int = 0, size: float = 1.0, free=NOMINAL_FREE) -> dict:
    """Refit the nominal actuator (free ``k, b, eps``, or the parameters ``free`` names: with ``m`` too, what the
    library's rigid ``added_mass`` expresses) to a case's training run and measure what it loses on the
    validation run.

    Returns
    -------
    dict
        Per channel: ``nominal_fit``, ``nominal_validation_fit`` (fit %), ``truth_validation_fit`` (the
        noise-free truth against the noisy validation run); ``nominal_rss`` (the refit's validation RSS,
        summed over channels in units of each channel's variance), ``noise_rss`` (the truth's own), ``gain``
        (:func:`truth_gain`), ``values`` (the refitted parameters), ``fit_seconds``.

    Examples
    --------
    >>> r = concealment("current_limit", seconds=0.5, size=1e-6)
    >>> bool(abs(r["gain"]) < 0.05 * r["noise_rss"])
    True
    """
    from phs.workflows.identify import identify, nrmse_fit
    from systems.electrostatic_actuator import electrostatic_actuator

    train, _ = generate(effect, seconds=seconds, seed=seed, size=size)
    val, iva = generate(effect, seconds=seconds, seed=seed, size=size, validation=True)
    wall = time.perf_counter()
    fit = identify(electrostatic_actuator(), train, list(free), validation=val)
    out = {"effect": effect, "free": list(free), "seconds": float(seconds), "seed": int(seed), "size": float(size),
           "values": {k: float(x) for k, x in fit.values.items()}, "fit_seconds": time.perf_counter() - wall,
           "nominal_fit": {}, "nominal_validation_fit": {}, "truth_validation_fit": {}}
    rss = 0.0
    for ch in CHANNELS:
        out["nominal_fit"][ch] = float(fit.fit_percent[ch])
        out["nominal_validation_fit"][ch] = float(fit.validation_fit_percent[ch])
        out["truth_validation_fit"][ch] = nrmse_fit(val[ch], iva["clean"][ch])
        rss += len(val) * (1.0 - out["nominal_validation_fit"][ch] / 100.0) ** 2  # RSS / var(y) from the NRMSE fit
    out["nominal_rss"] = rss
    out["gain"] = truth_gain(rss, val, iva["clean"])
    out["noise_rss"] = rss - out["gain"]
    return out


def main(argv=None) -> int:
    """Command line: the concealment table of the module docstring.

    ``python examples/concealed_outside.py [--seconds S] [--seed N] [--cases A,B] [--size F] [--free k,b,eps,m]``

    Examples
    --------
    >>> main(["--seconds", "0.5", "--cases", "current_limit", "--size", "1e-6"])  # doctest: +ELLIPSIS
    | case | nominal refit, training | ...
    0
    """
    ap = argparse.ArgumentParser(prog="concealed_outside.py", description="Refit the nominal actuator to each outside case "
                                 "and print what it loses on validation.")
    ap.add_argument("--seconds", type=float, default=20.0, help="length of every recording (default 20 s)")
    ap.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    ap.add_argument("--cases", default=",".join(OUTSIDE), help="comma-separated cases (default: every one)")
    ap.add_argument("--size", type=float, default=1.0, help="effect size (default 1)")
    ap.add_argument("--free", default=",".join(NOMINAL_FREE), help="comma-separated refitted parameters of the nominal "
                    "actuator (default k,b,eps; k,b,eps,m: what a rigid added mass expresses)")
    args = ap.parse_args(argv)
    free = [p.strip() for p in args.free.split(",") if p.strip()]
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in OUTSIDE]
    if unknown:
        ap.error(f"unknown case(s) {unknown}; known: {', '.join(OUTSIDE)}")

    def pair(d):
        return " / ".join(f"{d[ch]:.1f}" for ch in CHANNELS)

    print("| case | nominal refit, training | nominal refit, validation | noise-limited, validation | gain | noise | gain / noise |")
    print("| --- | --- | --- | --- | ---: | ---: | ---: |")
    for c in cases:
        r = concealment(c, seconds=args.seconds, seed=args.seed, size=args.size, free=free)
        print(f"| {c} | {pair(r['nominal_fit'])} | {pair(r['nominal_validation_fit'])} | {pair(r['truth_validation_fit'])} "
              f"| {r['gain']:.1f} | {r['noise_rss']:.1f} | {r['gain'] / r['noise_rss']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
