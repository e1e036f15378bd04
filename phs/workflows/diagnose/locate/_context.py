"""What every locator shares, gathered once per call: the validated signals, the input events (steps,
velocity reversals, input peaks), the excitation's frequency and the regressor matrix (:class:`_Ctx`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from phs.errors import InputDataError
from phs.workflows.diagnose.locate.features import _regressor_matrix


# -- validation ----------------------------------------------------------------------------------------------------
def _signal(what, name, x, n):
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputDataError(f"{what} {name!r} is not numeric") from None
    if a.ndim != 1:
        raise InputDataError(f"{what} {name!r} must be one-dimensional, got shape {a.shape}")
    if a.size != n:
        raise InputDataError(f"{what} {name!r} has {a.size} samples, the time grid has {n}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise InputDataError(f"{what} {name!r} has {bad.size} non-finite value(s), the first at sample {bad[0]}")
    return a


def _validate(t, residuals, features, inputs, velocities=(), noise_std=None):
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise InputDataError("time grid 't' is not numeric") from None
    if t.ndim != 1 or t.size < 16:
        raise InputDataError(f"time grid 't' must be one-dimensional with at least 16 samples, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise InputDataError("time grid 't' has non-finite values")
    n = t.size
    dt = (t[-1] - t[0]) / (n - 1)
    if not dt > 0 or np.max(np.abs(np.diff(t) - dt)) > 0.01 * dt:
        raise InputDataError("time grid 't' is not uniform and increasing (jitter above 1 % of the step); resample first")
    res = {str(k): _signal("residual", k, v, n) for k, v in residuals.items()}
    feats = {str(k): _signal("feature", k, v, n) for k, v in features.items()}
    ins = {str(k): _signal("input", k, v, n) for k, v in inputs.items()}
    vel = [str(v) for v in velocities]
    for v in vel:
        if v not in feats:
            raise InputDataError(f"velocity {v!r} is not among the features ({', '.join(feats) or 'none'})")
    vel = list(dict.fromkeys(vel + [k for k in feats if k.startswith("v:")]))
    sig = {}
    for k, s in (noise_std or {}).items():
        if k not in res:
            raise InputDataError(f"noise_std names {k!r}, which is not a residual channel ({', '.join(res)})")
        if not (isinstance(s, (int, float, np.floating, np.integer)) and math.isfinite(s) and s >= 0):
            raise InputDataError(f"noise_std of {k!r} must be a finite number >= 0, got {s!r}")
        sig[k] = float(s)
    return t, dt, res, feats, ins, vel, sig


# -- events --------------------------------------------------------------------------------------------------------
def _steps(u, rel=0.05):
    """Sample indices where ``u`` jumps (first sample at the new level) and the jumps: a jump is a change
    above ``rel`` of the range over at most a few samples, with quiet flanks (so fast sines are no steps)."""
    span = float(np.ptp(u))
    if span == 0:
        return []
    du = np.diff(u)
    adu = np.abs(du)
    idx = np.flatnonzero(adu > rel * span)
    if not idx.size:
        return []
    out = []
    for g in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):
        i0, i1 = int(g[0]), int(g[-1])
        jump = float(u[i1 + 1] - u[i0])
        w = max(3, i1 - i0 + 1)
        flank = np.concatenate([adu[max(0, i0 - w):i0], adu[i1 + 1:i1 + 1 + w]])
        if abs(jump) >= rel * span and not (flank.size and flank.max() > 0.25 * adu[i0:i1 + 1].max()):
            out.append((i1 + 1, jump))
    return out


def _reversals(v, band=0.05):
    """Indices where the velocity ``v`` changes sign, with a dead band of ``band`` times its peak."""
    a = float(np.max(np.abs(v)))
    if a == 0:
        return []
    s = np.where(v > band * a, 1, np.where(v < -band * a, -1, 0))
    nz = np.flatnonzero(s)
    if nz.size < 2:
        return []
    sn = s[nz]
    out = []
    for c in np.flatnonzero(sn[1:] != sn[:-1]):
        i0, i1 = nz[c], nz[c + 1]
        out.append(int(i0 + np.argmax(np.sign(v[i0:i1 + 1]) == sn[c + 1])))
    return out


def _fundamental(u, fs):
    """Fundamental frequency of a periodic input (at least 3 periods, 60 % of its power at the harmonics), or None."""
    x = u - u.mean()
    n = x.size
    if not np.any(x):
        return None
    X = np.abs(np.fft.rfft(x * np.hanning(n))) ** 2
    X[0] = 0.0
    df = fs / n
    k = int(np.argmax(X))
    if k < 3 or k >= X.size - 1:
        return None
    a, b, c = np.log(X[k - 1:k + 2] + 1e-300)
    den = a - 2 * b + c
    f0 = (k + (0.5 * (a - c) / den if den < 0 else 0.0)) * df
    f = np.arange(X.size) * df

    def share(f0):
        h = np.round(f / f0)
        return float(X[(h >= 1) & (np.abs(f - h * f0) <= 2.5 * df + 0.002 * h * f0)].sum() / X.sum())

    for d in (2, 3):  # the largest peak may be a harmonic of the true fundamental
        if f0 / d >= 3 * df and X[np.abs(f - f0 / d) <= 2.5 * df].sum() > 0.02 * X.sum():
            f0 /= d
            break
    return f0 if share(f0) >= 0.6 else None


@dataclass
class _Ctx:
    """What every channel shares: grid, events, excitation, the regressor matrix."""

    t: np.ndarray
    dt: float
    features: dict
    inputs: dict
    velocities: list
    steps: dict            # input -> [(index, jump)]
    merged: list           # [(index, input, jump)] over all inputs, sorted
    reversals: dict        # velocity -> [index]
    peaks: dict            # input -> [(index, "peak"|"trough")]
    f0: float | None
    f0_input: str | None
    f_exc: float | None
    f_exc_source: str
    specs: list = field(default_factory=list)
    Z: np.ndarray | None = None
    means: np.ndarray | None = None
    sds: np.ndarray | None = None

    @property
    def n(self):
        return self.t.size

    @property
    def fs(self):
        return 1.0 / self.dt


def _merge_steps(steps):
    allst = sorted((i, name, j) for name, lst in steps.items() for i, j in lst)
    merged = []
    for i, name, j in allst:
        if merged and i - merged[-1][0] <= 2:
            continue
        merged.append((i, name, j))
    return merged


def _prepare(t, dt, feats, ins, vel):
    """The context of one call: input events, the excitation's frequency and the regressor matrix."""
    fs = 1.0 / dt
    steps = {k: _steps(u) for k, u in ins.items()}
    merged = _merge_steps(steps)
    revs = {v: _reversals(feats[v]) for v in vel}
    peaks = {}
    for k, u in ins.items():
        if not steps[k] and np.ptp(u) > 0:
            prom = 0.25 * np.ptp(u)
            peaks[k] = sorted([(int(i), "peak") for i in signal.find_peaks(u, prominence=prom)[0]]
                              + [(int(i), "trough") for i in signal.find_peaks(-u, prominence=prom)[0]])
    f0, f0_in = None, None
    for k, u in ins.items():
        f = _fundamental(u, fs)
        if f is not None and (f0 is None or np.var(u) > np.var(ins[f0_in])):
            f0, f0_in = f, k
    T = t.size * dt
    if f0 is not None:
        f_exc, src = f0, f"the excitation frequency of {f0_in}"
    elif merged:
        f_exc, src = len(merged) / (2 * T), "the step rate of the inputs"
    else:
        cen = []
        for u in ins.values():
            X = np.abs(np.fft.rfft(u - u.mean())) ** 2
            if X.sum() > 0:
                cen.append(float(np.sum(np.fft.rfftfreq(u.size, dt) * X) / X.sum()))
        f_exc, src = (min(cen), "the mean frequency of the inputs") if cen else (None, "")
    ctx = _Ctx(t, dt, feats, ins, vel, steps, merged, revs, peaks, f0, f0_in, f_exc, src)
    ctx.specs, ctx.Z, ctx.means, ctx.sds = _regressor_matrix(t, feats, ins, vel, merged)
    return ctx
