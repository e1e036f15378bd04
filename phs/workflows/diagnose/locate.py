"""Locate where a simulation and a recording differ: numbered findings from the residuals alone.

Step 2 of the diagnosis.  Nothing here knows about port-Hamiltonian models: :func:`locate` reads a
uniform time grid, the residuals (measured minus simulated, per output channel), signals of the
fitted nominal model along the recording (*features*: positions, velocities, charges, ...) and the
applied inputs, and returns :class:`Finding` objects, each with a place and a number.

Velocities: a feature is a velocity if its name starts with ``"v:"`` (the prefix is dropped in the
reported names) or is listed in ``velocities=``.  Velocities give the reversal events and the
``sign(v)`` products; the time since the last input step is computed here from the inputs.

=====================  ============================================================================
kind                   strength, and when ``details["significant"]`` is true
=====================  ============================================================================
``time_window``        share of the residual energy inside the window(s).  Single windows: where the
                       mean energy over a few periods of the residual exceeds both twice the average
                       and the surrogates' highest window.  Windows locked to events (``0-L s after
                       each step``, ``±L/2 around each reversal / input peak``): density at least 1.5
                       times the average and an excess share above the surrogates'
``feature``            R² of a straight-line fit of the residual on one regressor: a feature or input
                       ``x``, ``|x|``, ``sign(x)``, ``x²``, ``x³``, ``x·|x|``, ``x·sign(v)`` for each
                       velocity ``v``, ``dU/dt``, the time since the last input step; significant
                       above the surrogates' best R² over all regressors
``spectrum``           share of the residual power in a spectral peak (significant above a running
                       median of the spectrum, F test at 1 % over all bins), or the share of the
                       residual power coherent with an input (significant when the peak coherence
                       beats its 1 % level and the share exceeds the noise bias by 0.05)
``harmonic``           share of the residual power at the h-th multiple of the excitation's
                       fundamental (the input with 60 % of its power at one fundamental's
                       harmonics, at least 3 periods); significant when the band's peak stands out
                       of the background between harmonics (F test at 1 %) and sits on the harmonic
``input_lag``          peak of the normalised cross-correlation of the residual with an input or its
                       derivative, over lags up to a tenth of the recording; ``lag > 0`` means the
                       residual follows (lags behind) the input; significant above the surrogates'
                       peak over the same lags, input and derivative
``amplitude_scaling``  exponent p of residual RMS ∝ level^p, over the constant-level segments
                       between an input's steps or over blocks of a smooth input (amplitude
                       √2·std); significant for log-log R² >= 0.5, |p| >= 0.25 and |p| >= 3 standard
                       errors, with at least two distinct levels 1.5 times apart
``rate_scaling``       the same against the block's rate (RMS of dU/dt over RMS of U, in Hz)
``whiteness``          Ljung-Box statistic Q over lags 1..min(20, n/5) (``details["p_value"]``);
                       significant means *not* white (p < 0.01).  Always reported
``drift``              share of the residual energy below a tenth of the excitation frequency (at
                       least 2/T); significant above 0.2 and the surrogates' share when the band's
                       mean periodogram (without 0 Hz) stands out of the next bins above it, or the
                       mean (0 Hz) out of the lowest bins (F tests at 1 %).  Or the share of
                       the energy after the input steps explained by exponential tails
                       ``a_j exp(-(t - t_j)/τ)`` (one τ, an amplitude and an offset per step;
                       ``details``: ``tau_s``, amplitudes per unit step); significant when above
                       0.1 and the surrogates' gain, τ inside its range and the tails following the
                       steps' direction (75 % of them)
=====================  ============================================================================

The surrogates are the null of *stationary noise with the residual's own spectrum, unrelated to the
model signals*: :data:`N_SURROGATES` Gaussian series whose spectrum is the residual's Welch spectrum
with segments of an eighth of the recording (which smears spectral lines, so a residual locked to a
periodic excitation is not mistaken for noise).  A threshold is the :data:`NULL_QUANTILE` quantile of
a Gumbel law fitted to the surrogates' best values over all regressors, windows or lags, so it holds
for the whole family.  Measured on 300 recordings of noise (3 s at 1 kHz, a square-wave input, three
features): on white noise each analysis reports a significant finding in at most 2 % of them; on
coloured noise (first-order low-pass, 5 and 50 ms) at most 2 %, except ``drift`` (3 % at 50 ms).

``noise_std`` (the measurement noise per channel) does not change the tests; it adds
``share_above_noise`` to time windows and ``share_of_structured`` to features, and is subtracted
from the block energies of the scaling fits.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import dataclass, field

import numpy as np
import scipy.fft as sfft
from scipy import ndimage, optimize, signal, stats

from phs.errors import InputDataError
from phs.io import write_atomic

KINDS = ("time_window", "feature", "spectrum", "harmonic", "input_lag", "amplitude_scaling", "rate_scaling",
         "whiteness", "drift")
"""The kinds of :class:`Finding`, in the order :func:`locate` reports them."""
N_SURROGATES = 100
"""Noise surrogates per channel for the significance thresholds."""
NULL_QUANTILE = 0.99
"""Quantile of the surrogates' best value used as the significance threshold."""

_TRANSFORMS = {"x": "{}", "|x|": "|{}|", "sign(x)": "sign({})", "x^2": "{}²", "x^3": "{}³", "x|x|": "{}·|{}|"}


@dataclass(frozen=True)
class Finding:
    """One located mismatch: a kind, the channel, a place in words and a number.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`.
    channel : str
        Output channel whose residual this is about.
    where : str
        Human-readable place ("t = 2.00–2.35 s (after the step of U at 2.00 s)", "residual ~ sign(v)").
    strength : float
        The number; its meaning per kind is tabulated in the module docstring.
    meaning : str
        One sentence saying what ``strength`` means here.
    details : dict
        Further numbers (JSON-serialisable); ``details["significant"]`` is always present.

    Examples
    --------
    >>> f = Finding("whiteness", "y", "lags 1–20", 31.4, "Ljung-Box Q", {"p_value": 0.05, "significant": False})
    >>> f.to_dict()["strength"], f.significant
    (31.4, False)
    """

    kind: str
    channel: str
    where: str
    strength: float
    meaning: str
    details: dict = field(default_factory=dict, hash=False)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputDataError(f"finding kind {self.kind!r} is not one of {', '.join(KINDS)}")

    @property
    def significant(self) -> bool:
        """Whether the finding beats its noise threshold (``details["significant"]``)."""
        return bool(self.details.get("significant", True))

    def to_dict(self) -> dict:
        """Plain JSON types (non-finite numbers become ``None``).

        Examples
        --------
        >>> Finding("drift", "y", "below 0.1 Hz", float("nan"), "share", {"f": np.float64(0.1)}).to_dict()["strength"] is None
        True
        """
        return {"kind": self.kind, "channel": self.channel, "where": self.where, "strength": _json(self.strength),
                "meaning": self.meaning, "details": _json(self.details)}


def _json(obj):
    if isinstance(obj, dict):
        return {str(k): _json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_json(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj if obj is None or isinstance(obj, str) else str(obj)


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


def _disp(key: str) -> str:
    return key[2:] if key.startswith("v:") else key


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


def _since_step(t, merged):
    n = t.size
    if not merged:
        return t - t[0]
    idx = np.array([m[0] for m in merged])
    k = np.searchsorted(idx, np.arange(n), side="right") - 1
    return np.where(k >= 0, t - t[idx[np.maximum(k, 0)]], t - t[0])


def _regressor(spec, ctx_t, features, inputs, merged):
    """The signal of a regressor described by ``spec`` (the ``details`` of a feature finding)."""
    tr = spec["transform"]
    if tr == "time_since_step":
        return _since_step(ctx_t, merged)
    s = (inputs if spec["source"] == "input" else features)[spec["base"]]
    if tr == "d/dt":
        return np.gradient(s, ctx_t[1] - ctx_t[0])
    if tr == "x·sign(v)":
        return s * np.sign(features[spec["velocity"]])
    return {"x": lambda: s, "|x|": lambda: np.abs(s), "sign(x)": lambda: np.sign(s), "x^2": lambda: s * s,
            "x^3": lambda: s * s * s, "x|x|": lambda: s * np.abs(s)}[tr]()


def _prepare(t, dt, feats, ins, vel):
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

    # regressors: every transform of every feature and input, products with sign(velocity), dU/dt, time since step
    specs = []
    rows, means, sds = [], [], []

    def add(sig, name, spec):
        m, s = float(sig.mean()), float(sig.std())
        if s > 1e-12 * (float(np.max(np.abs(sig))) + 1e-300):
            rows.append(((sig - m) / s).astype(np.float32))
            specs.append({"regressor": name, **spec})
            means.append(m)
            sds.append(s)

    bases = [("feature", k) for k in feats] + [("input", k) for k in ins]
    for src_, k in bases:
        for tr, fmt in _TRANSFORMS.items():
            spec = {"source": src_, "base": k, "transform": tr, "velocity": None}
            add(_regressor(spec, t, feats, ins, merged), fmt.format(_disp(k), _disp(k)), spec)
    for src_, k in bases:
        if src_ == "feature" and k in vel:
            continue
        for v in vel:
            spec = {"source": src_, "base": k, "transform": "x·sign(v)", "velocity": v}
            add(_regressor(spec, t, feats, ins, merged), f"{_disp(k)}·sign({_disp(v)})", spec)
    for k in ins:
        spec = {"source": "input", "base": k, "transform": "d/dt", "velocity": None}
        add(_regressor(spec, t, feats, ins, merged), f"d{k}/dt", spec)
    if merged:
        spec = {"source": "events", "base": None, "transform": "time_since_step", "velocity": None}
        add(_since_step(t, merged), "time since last step", spec)
    if rows:
        keep = []
        for i in range(len(rows)):  # a regressor equal to an earlier (simpler) one of the same signal is dropped
            if not any(specs[j]["base"] == specs[i]["base"] and (np.array_equal(rows[i], rows[j]) or np.array_equal(rows[i], -rows[j]))
                       for j in keep):
                keep.append(i)
        ctx.Z = np.vstack([rows[i] for i in keep])
        ctx.means, ctx.sds = np.array(means)[keep], np.array(sds)[keep]
        specs = [specs[i] for i in keep]
    ctx.specs = specs
    return ctx


# -- helpers -------------------------------------------------------------------------------------------------------
def _acf(x, maxlag):
    n = x.size
    maxlag = int(min(maxlag, n - 1))
    nfft = sfft.next_fast_len(2 * n)
    X = sfft.rfft(x, nfft)
    a = sfft.irfft(X * np.conj(X), nfft)[:maxlag + 1]
    return a / a[0] if a[0] > 0 else np.zeros(maxlag + 1)


def _runs(mask):
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _event_mask(n, idx, before, after):
    d = np.zeros(n + 1, dtype=np.int64)
    idx = np.asarray(idx)
    np.add.at(d, np.clip(idx - before, 0, n), 1)
    np.add.at(d, np.clip(idx + after, 0, n), -1)
    return np.cumsum(d[:-1]) > 0


def _fmt_s(x, T):
    d = int(min(6, max(0, math.ceil(-math.log10(max(T, 1e-12) / 2000)))))
    return f"{x:.{d}f}"


def _fmt_lag(s):
    if abs(s) < 1:
        return f"{s * 1e3:+.3g} ms"
    return f"{s:+.3g} s"


def _ordinal(k):
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


def _welch_len(n, fs, f0):
    L = max(256, n // 4)
    if f0:
        L = max(L, 2 ** math.ceil(math.log2(16 * fs / f0)))  # 16 bins between harmonics
    return int(min(n, L))


def _surrogates(rc, rng):
    """Gaussian noise with the residual's smoothed (Welch, an eighth of the recording) spectrum:
    standardized series (K, n) and their spectra (K, n//2+1), in single precision."""
    n = rc.size
    L = int(min(n, max(64, n // 8)))
    fw, P = signal.welch(rc, nperseg=L, detrend=False)  # rc is centred; a per-segment detrend would empty the lowest bins
    P[0] *= 2  # one-sided densities double every bin but 0 Hz and Nyquist: undo it for the shape
    if L % 2 == 0:
        P[-1] *= 2
    fr = np.fft.rfftfreq(n)
    A = np.sqrt(np.maximum(np.interp(fr, fw, P), 0.0)).astype(np.float32)
    A[0] = 0.0
    if n % 2 == 0:
        A[-1] = 0.0
    spec = rng.standard_normal((N_SURROGATES, fr.size, 2), dtype=np.float32).view(np.complex64)[..., 0] * A
    # Parseval: the series' sum of squares, from the one-sided spectrum
    ss = 2 * np.sum(spec.real**2 + spec.imag**2, axis=1) / n
    sd = np.sqrt(np.maximum(ss / n, 1e-30)).astype(np.float32)[:, None]
    spec /= sd
    return sfft.irfft(spec, n, axis=1), spec


def _peak_frequency(P, k, df) -> float:
    """Frequency of the peak at bin ``k``, refined by a parabola through the log-spectrum."""
    off = 0.0
    if 0 < k < P.size - 1:
        a, b, c = np.log(P[k - 1:k + 2] + 1e-300)
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den < 0 else 0.0
    return float((k + off) * df)


def _running_median(P, size, exclude=None):
    """Running median of ``P`` over ``size`` bins; ``exclude``d bins are first filled in (log-linearly) from the others."""
    Q = P
    if exclude is not None and exclude.any() and (~exclude).sum() >= 3:
        idx = np.arange(P.size)
        Q = P.copy()
        Q[exclude] = np.exp(np.interp(idx[exclude], idx[~exclude], np.log(P[~exclude] + 1e-300)))
    return ndimage.median_filter(Q, size=min(size, 2 * (P.size // 2) + 1), mode="nearest")


def _peak_threshold(alpha, dof, m_bg) -> float:
    """Ratio of a spectral bin (chi² with ``dof``) to a background estimated as the median of ``m_bg``
    neighbouring bins (taken as a third as many independent ones) exceeded with probability ``alpha``."""
    return float(stats.f.isf(alpha, dof, max(2.0, dof * m_bg / 3)))


def _gumbel_quantile(maxima) -> float:
    """:data:`NULL_QUANTILE` of a Gumbel law fitted by moments to the surrogates' maxima (steadier than
    the empirical quantile of 100 values)."""
    m = np.asarray(maxima, dtype=float)
    beta = float(m.std()) * math.sqrt(6) / math.pi
    return float(m.mean() - 0.5772156649 * beta - beta * math.log(-math.log(NULL_QUANTILE)))


# -- the analyses (each returns candidate findings, best first) ---------------------------------------------------
def _time_windows(ch, rc, ctx, sigma, sur):
    """Single windows where the energy density of the (centred) residual stands out, and windows locked to
    events (after steps, around reversals and input peaks).  Null: the same statistic on the surrogates."""
    n, dt, t = ctx.n, ctx.dt, ctx.t
    T = n * dt
    e = rc**2
    E = float(e.sum())
    if not E > 0:
        return []
    mu = E / n
    es2 = sur.astype(np.float64) ** 2  # (K, n), unit mean
    out = []

    def above_noise(mask_or_slice):
        if sigma > 0 and E > n * sigma**2:
            return float(np.sum(e[mask_or_slice] - sigma**2) / (E - n * sigma**2))
        return None

    # window length: several periods of the residual's mean frequency, at least n/200 samples
    P = np.abs(np.fft.rfft(rc)) ** 2
    fbar = float(np.sum(np.arange(P.size) * P) / P.sum()) / n  # cycles per sample
    W = int(min(max(5, n // 200, round(2 / max(fbar, 1e-9))), max(5, n // 10)))
    c = np.concatenate([[0.0], np.cumsum(e)])
    d = (c[W:] - c[:-W]) / W  # mean over the full windows [i, i + W)
    cs = np.concatenate([np.zeros((es2.shape[0], 1)), np.cumsum(es2, axis=1)], axis=1)
    q = max(2.0, _gumbel_quantile(np.max(cs[:, W:] - cs[:, :-W], axis=1) / W))
    thr = mu * q
    events = ([(i, "step", name) for i, name, _ in ctx.merged]
              + [(i, "reversal", v) for v, lst in ctx.reversals.items() for i in lst]
              + [(i, kind, k) for k, lst in ctx.peaks.items() for i, kind in lst])
    ev_t = np.array([t[i] for i, _, _ in events]) if events else np.zeros(0)
    for i0, i1 in _runs(d > thr):
        i1 = i1 - 1 + W
        share = float(e[i0:i1].sum() / E)
        ts = (i1 - i0) / n
        ta, tb = t[i0], t[i1 - 1]
        where = f"t = {_fmt_s(ta, T)}–{_fmt_s(tb, T)} s"
        slack = max(W * dt, 0.25 * (tb - ta))
        near = np.flatnonzero((ev_t >= ta - slack) & (ev_t <= tb))
        ev = {}
        if near.size:
            j = near[np.argmin(np.abs(ev_t[near] - ta))]
            _, kind, src = events[j]
            ev = {"event": kind, "source": _disp(src), "t_event": float(ev_t[j])}
            phrase = {"step": "after the step of", "reversal": "at the reversal of"}.get(kind, f"at the {kind} of")
            where += f" ({phrase} {_disp(src)} at {_fmt_s(ev_t[j], T)} s)"
        out.append(Finding("time_window", ch, where, share,
                           f"share of the residual energy in this window, which covers {ts:.1%} of the recording "
                           f"({share / ts:.1f} times the mean density; noise reaches {q:.1f})",
                           {"t_start": float(ta), "t_end": float(tb), "time_share": ts, "density_ratio": share / ts,
                            "threshold_ratio": q, "window_s": W * dt, "share_above_noise": above_noise(slice(i0, i1)),
                            "windows": [[float(ta), float(tb)]], **ev, "significant": True}))
    out.sort(key=lambda f: -f.strength)
    groups = [("step", name, [i for i, _ in lst], "after") for name, lst in ctx.steps.items()]
    groups += [("reversal", v, lst, "around") for v, lst in ctx.reversals.items()]
    groups += [("peak", k, [i for i, _ in lst], "around") for k, lst in ctx.peaks.items()]
    locked = []
    for kind, src, idx, align in groups:
        if len(idx) < 2:
            continue
        idx = np.asarray(idx)
        spacing = float(np.median(np.diff(idx)))
        cands = []
        for frac in (0.05, 0.1, 0.2, 0.4):
            L = max(2, int(round(frac * spacing)))
            m = _event_mask(n, idx, 0, L) if align == "after" else _event_mask(n, idx, L // 2, L - L // 2)
            ts = float(m.mean())
            if 0 < ts < 0.9:
                cands.append((float(e[m].sum() / E), ts, L, m))
        if not cands:
            continue
        # null: the best excess share over the same window lengths, on each surrogate
        tot2 = es2.sum(axis=1)
        null = np.max([np.einsum("kn,n->k", es2, m.astype(float), optimize=False) / tot2 - ts for _, ts, _, m in cands], axis=0)
        thr_x = _gumbel_quantile(null)
        es, ts, L, m = max(cands, key=lambda x: x[0] - x[1])
        win = [[float(t[a]), float(t[b - 1])] for a, b in _runs(m)][:200]
        span = L * dt
        where = (f"0–{span:.3g} s after each of {len(idx)} steps of {src}" if align == "after"
                 else f"±{span / 2:.3g} s around each of {len(idx)} {kind}s of {_disp(src)}")
        locked.append(Finding("time_window", ch, where, es,
                              f"share of the residual energy within these windows, which cover {ts:.1%} of the recording "
                              f"({es / ts:.1f} times the mean density)",
                              {"event": kind, "source": _disp(src), "n_events": len(idx), "window_s": span, "time_share": ts,
                               "density_ratio": es / ts, "excess_share": es - ts, "threshold_excess": thr_x,
                               "share_above_noise": above_noise(m), "windows": win,
                               "significant": bool(es / ts >= 1.5 and es - ts > thr_x)}))
    locked.sort(key=lambda f: -(f.strength - f.details["time_share"]))
    return locked + out


def _feature_findings(ch, r, rc, ctx, sur, sigma, kmax):
    if ctx.Z is None:
        return []
    n = ctx.n
    sd_r = float(rc.std())
    corr = np.einsum("ij,j->i", ctx.Z, (rc / sd_r).astype(np.float32), optimize=False).astype(float) / n
    r2 = np.minimum(corr**2, 1.0)
    thr = _gumbel_quantile(np.max((np.einsum("ij,kj->ik", ctx.Z, sur, optimize=False) / n) ** 2, axis=0))
    chosen = []
    for j in np.argsort(-r2)[:max(10, 4 * kmax)]:
        same = [c for c in chosen if abs(float(np.einsum("i,i->", ctx.Z[c[0]], ctx.Z[j], optimize=False))) / n > 0.98]
        if same:
            same[0][1].append(ctx.specs[j]["regressor"])
            continue
        if len(chosen) < kmax:
            chosen.append((j, []))
    var_r = sd_r**2
    out = []
    for j, eq in chosen:
        spec = ctx.specs[j]
        b = float(corr[j] * sd_r / ctx.sds[j])
        a = float(r.mean() - b * ctx.means[j])
        det = {**spec, "r2": float(r2[j]), "coefficient": b, "intercept": a, "threshold": thr, "equivalent": eq,
               "null": f"{NULL_QUANTILE:.0%} quantile of the best R² over {N_SURROGATES} noise surrogates (Gumbel fit)",
               "significant": bool(r2[j] > thr)}
        if sigma > 0 and var_r > sigma**2:
            det["share_of_structured"] = float(min(1.0, r2[j] * var_r / (var_r - sigma**2)))
        out.append(Finding("feature", ch, f"residual ~ {spec['regressor']}", float(r2[j]),
                           f"R² of a straight-line fit of the residual on {spec['regressor']}: the share of the residual's "
                           f"variance it explains (noise unrelated to the model reaches {thr:.3g})", det))
    return out


def _welch(x, fs, L):
    f, P = signal.welch(x, fs, nperseg=L)
    dof = 2.0 * (1 + (x.size - L) // (L // 2))
    return f, P, dof, (1 - 2 / (9 * dof)) ** 3  # median of chi²_dof/dof, to turn medians into means


def _spectral(ch, rc, ctx):
    """Harmonics of the excitation (fine resolution), other spectral peaks (averaged spectrum), coherence."""
    n, fs = ctx.n, ctx.fs
    harm_out, peaks_out, coh_out = [], [], []
    if ctx.f0:
        f0 = ctx.f0
        f, P, dof, medcorr = _welch(rc, fs, _welch_len(n, fs, f0))
        df = f[1] - f[0]
        tot = float(P.sum())
        H = int(min(20, 0.95 * (fs / 2) / f0))
        bands = [np.abs(f - h * f0) <= max(2 * df, 0.005 * h * f0) for h in range(1, H + 1)]
        harm = np.any(bands, axis=0) if bands else np.zeros(f.size, bool)
        below = f <= (H + 0.5) * f0
        free = float(np.mean(~harm[below])) if below.any() else 0.0
        size = max(9, int(3 * f0 / df)) | 1
        # background between the harmonics (harmonic bins interpolated out) when there is room for it
        bg = _running_median(P, size, harm if free >= 0.3 else None) / medcorr
        m_bg = size * (free if free >= 0.3 else 1.0)
        for h, band in enumerate(bands, 1):
            if not band.any() or tot <= 0:
                continue
            fk = h * f0
            b0 = float(bg[int(np.argmin(np.abs(f - fk)))])
            share = float(P[band].sum() / tot)
            ratio = float(P[band].max() / b0) if b0 > 0 else math.inf
            thr = _peak_threshold(0.01 / (H * band.sum()), dof, m_bg)
            # the band's peak must sit on the harmonic (a line one bin away is another frequency);
            # the tolerance allows the fundamental's own uncertainty (~0.1/T) times the order
            fpk = _peak_frequency(P, int(np.flatnonzero(band)[np.argmax(P[band])]), df)
            on_line = abs(fpk - fk) <= max(0.6 * df, 0.1 * h * fs / n)
            name = "fundamental" if h == 1 else f"{_ordinal(h)} harmonic"
            harm_out.append(Finding("harmonic", ch, f"{name} of {f0:.4g} Hz ({fk:.4g} Hz, excitation {ctx.f0_input})", share,
                                    "share of the residual power in this harmonic's band",
                                    {"order": h, "frequency_hz": fk, "fundamental_hz": f0, "input": ctx.f0_input,
                                     "peak_hz": float(fpk), "ratio_to_background": ratio, "threshold_ratio": thr,
                                     "significant": bool(ratio > thr and share >= 0.01 and on_line)}))
        harm_out.sort(key=lambda x: -x.strength)
    # other peaks, on an averaged spectrum against a running median a quarter of the frequency wide
    Lp = int(min(n, max(256, n // 8)))
    f, P, dof, medcorr = _welch(rc, fs, Lp)
    df = f[1] - f[0]
    tot = float(P.sum())
    sizes = [s_ for s_ in (9, 31, 101, 301) if s_ <= max(9, P.size)]
    bgs = [_running_median(P, s_) / medcorr for s_ in sizes]
    for k in signal.find_peaks(np.concatenate([[0.0], P, [0.0]]))[0] - 1:
        if k < 2 or tot <= 0:
            continue
        fk = _peak_frequency(P, k, df)
        if ctx.f0 and round(fk / ctx.f0) >= 1 and abs(fk - ctx.f0 * round(fk / ctx.f0)) <= 0.3 * df + 0.1 * round(fk / ctx.f0) * fs / n:
            continue  # a harmonic: reported above
        j = max(i for i, s_ in enumerate(sizes) if s_ <= max(9, 0.5 * k))
        b0 = float(bgs[j][k])
        ratio = float(P[k] / b0) if b0 > 0 else math.inf
        thr = _peak_threshold(0.01 / P.size, dof, sizes[j])
        share = float(P[max(0, k - 2):k + 3].sum() / tot)
        if ratio > thr and share >= 0.01:
            peaks_out.append(Finding("spectrum", ch, f"spectral peak at {fk:.4g} Hz", share,
                                     "share of the residual power in this peak (±2 bins)",
                                     {"frequency_hz": fk, "ratio_to_background": ratio, "threshold_ratio": thr,
                                      "significant": True}))
    peaks_out.sort(key=lambda x: -x.strength)
    # coherence with each input
    Lc = int(min(n // 4, max(64, n // 8)))
    nd = n // Lc
    if nd >= 4:
        for k, u in ctx.inputs.items():
            if np.ptp(u) == 0:
                continue
            _, Pu = signal.welch(u, fs, nperseg=Lc)
            if not Pu.max() > 0:
                continue  # constant within every segment
            with np.errstate(divide="ignore", invalid="ignore"):
                fc, C = signal.coherence(u, rc, fs, nperseg=Lc)
            C = np.nan_to_num(C)
            _, Pr = signal.welch(rc, fs, nperseg=Lc)
            use = (Pu >= 1e-3 * Pu.max()) & (fc > 0)
            if not use.any() or Pr.sum() <= 0:
                continue
            share = float(np.sum(C[use] * Pr[use]) / Pr.sum())
            bias = float(np.sum(Pr[use]) / Pr.sum()) / nd
            cthr = 1 - (0.01 / use.sum()) ** (1 / (nd - 1))
            j = np.flatnonzero(use)[np.argmax(C[use])]
            coh_out.append(Finding("spectrum", ch, f"coherent with {k} (peak coherence {C[j]:.2f} at {fc[j]:.4g} Hz)", share,
                                   f"share of the residual power linearly coherent with {k} (noise alone gives about {bias:.2g})",
                                   {"input": k, "frequency_hz": float(fc[j]), "peak_coherence": float(C[j]),
                                    "coherence_threshold": float(cthr), "bias": bias,
                                    "significant": bool(C[j] > cthr and share - bias >= 0.05)}))
    return harm_out + sorted(coh_out + peaks_out, key=lambda x: -x.strength)


def _lags(ch, rc, ctx, sur_spec):
    """Cross-correlation with each input and its derivative; one threshold per input covers both and every lag."""
    n, dt = ctx.n, ctx.dt
    max_lag = int(min(n // 4, max(20, n // 10)))
    lags = np.arange(-max_lag, max_lag + 1)
    sd_r = float(rc.std())
    nfft = sfft.next_fast_len(2 * n)
    R = sfft.rfft(rc, nfft)
    out = []
    for k, u in ctx.inputs.items():
        cands, nulls = [], []
        for deriv in (False, True):
            x = np.gradient(u, dt) if deriv else u
            x = x - x.mean()
            sd_x = float(x.std())
            if not sd_x > 0:
                continue
            cc = sfft.irfft(R * np.conj(sfft.rfft(x, nfft)), nfft)
            cands.append((deriv, np.concatenate([cc[nfft - max_lag:], cc[:max_lag + 1]]) / (n * sd_r * sd_x)))
            ccs = sfft.irfft(sur_spec * np.conj(sfft.rfft(x)).astype(np.complex64)[None, :], n, axis=1)
            # circular correlation of the unit-variance surrogates
            nulls.append(np.maximum(np.abs(ccs[:, :max_lag + 1]).max(axis=1), np.abs(ccs[:, n - max_lag:]).max(axis=1)) / (n * sd_x))
        if not cands:
            continue
        thr = _gumbel_quantile(np.max(nulls, axis=0))
        for deriv, c in cands:
            j = int(np.argmax(np.abs(c)))
            frac = 0.0
            if 0 < j < c.size - 1:
                a, b, d = np.abs(c[j - 1:j + 2])
                den = a - 2 * b + d
                frac = 0.5 * (a - d) / den if den < 0 else 0.0
            lag = (lags[j] + frac) * dt
            name = f"d{k}/dt" if deriv else k
            rel = "follows" if lags[j] > 0 else "precedes" if lags[j] < 0 else "is in step with"
            sign = "" if c[j] > 0 else ", inverted"
            out.append(Finding("input_lag", ch, f"lag {_fmt_lag(lag)} (residual {rel} {name}{sign})", float(abs(c[j])),
                               f"peak of the normalised cross-correlation of the residual with {name} over lags "
                               f"±{max_lag * dt:.3g} s (noise reaches {thr:.3g})",
                               {"input": k, "derivative": deriv, "lag_s": float(lag), "lag_samples": int(lags[j]),
                                "correlation": float(c[j]), "correlation_at_zero": float(c[max_lag]), "threshold": thr,
                                "max_lag_s": float(max_lag * dt), "convention": "lag > 0: the residual follows (lags behind) the input",
                                "significant": bool(abs(c[j]) > thr)}))
    out.sort(key=lambda f: -f.strength / max(f.details["threshold"], 1e-12))
    return out


def _blocks(ctx, name):
    """(variable, kind, [(i0, i1, value)]) tuples for the input ``name``."""
    u, n, dt = ctx.inputs[name], ctx.n, ctx.dt
    if ctx.steps[name]:
        b = [0] + [i for i, _ in ctx.steps[name]] + [n]
        return [(f"|{name}|", "amplitude_scaling", [(i0, i1, abs(float(np.median(u[i0:i1])))) for i0, i1 in zip(b[:-1], b[1:])
                                                     if i1 - i0 >= 5])]
    L = max(20, n // 20)
    if ctx.f0 and ctx.f0_input == name:
        L = max(L, int(round(2 * ctx.fs / ctx.f0)))
    amp, rate = [], []
    for i0 in range(0, n - L // 2, L):
        i1 = min(n, i0 + L)
        x = u[i0:i1] - u[i0:i1].mean()
        s = float(x.std())
        if s > 0:
            amp.append((i0, i1, math.sqrt(2) * s))
            rate.append((i0, i1, float(np.sqrt(np.mean(np.diff(u[i0:i1]) ** 2)) / dt / s / (2 * np.pi))))
    return [(f"amplitude of {name}", "amplitude_scaling", amp), (f"rate of {name} [Hz]", "rate_scaling", rate)]


def _scaling(ch, r, ctx, sigma):
    out = []
    for name, u in ctx.inputs.items():
        if np.ptp(u) == 0:
            continue
        for var, kind, blocks in _blocks(ctx, name):
            vmax = max((b[2] for b in blocks), default=0.0)
            pts = []
            for i0, i1, v in blocks:
                ms = float(np.mean(r[i0:i1] ** 2)) - sigma**2
                if v > 0.05 * vmax and ms > 0:
                    pts.append((v, math.sqrt(ms)))
            if len(pts) < 3:
                continue
            v, s = np.log(np.array(pts)).T
            sv = np.sort(v)
            clusters = 1 + int(np.sum(np.diff(sv) > math.log(1.1)))
            if clusters < 2 or sv[-1] - sv[0] < math.log(1.5):
                continue
            A = np.column_stack([np.ones_like(v), v])
            coef, *_ = np.linalg.lstsq(A, s, rcond=None)
            res = s - A @ coef
            ss = float(np.sum((s - s.mean()) ** 2))
            r2 = 1 - float(res @ res) / ss if ss > 0 else 1.0
            dof = len(v) - 2
            se = math.sqrt(float(res @ res) / dof / float(np.sum((v - v.mean()) ** 2))) if dof > 0 else math.inf
            p = float(coef[1])
            sig = bool(r2 >= 0.5 and abs(p) >= 0.25 and (se == 0 or abs(p) >= 3 * se))
            what = "levels" if kind == "amplitude_scaling" and ctx.steps[name] else "blocks"
            out.append(Finding(kind, ch, f"residual RMS ∝ ({var})^{p:.2f} over {len(pts)} {what} ({clusters} distinct values)", p,
                               f"exponent of the power law fitted to residual RMS against {var} (log-log R² {r2:.2f})",
                               {"input": name, "variable": var, "exponent": p, "std_error": se, "r2": r2, "n_blocks": len(pts),
                                "distinct_values": clusters, "values": [float(x) for x in np.exp(v)],
                                "rms": [float(x) for x in np.exp(s)], "significant": sig}))
    out.sort(key=lambda f: -f.details["r2"])
    return out


def _whiteness(ch, rc, ctx):
    n = ctx.n
    h = int(min(20, max(1, n // 5)))
    rho = _acf(rc, h)[1:]
    Q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, h + 1))))
    p = float(stats.chi2.sf(Q, h))
    return [Finding("whiteness", ch, f"lags 1–{h} ({_fmt_lag(ctx.dt)[1:]}–{_fmt_lag(h * ctx.dt)[1:]})", Q,
                    f"Ljung-Box statistic over lags 1–{h} (a white residual gives about {h}); p = {p:.3g}",
                    {"statistic": Q, "p_value": p, "lags": h, "significant": bool(p < 0.01)})]


def _tail_fit(r, dt, starts, ends, null_series=None, skip=2):
    """Fit ``a_j exp(-(t - t_j)/τ) + c_j`` after each step j, one τ for all (variable projection: a_j, c_j are
    linear).  Fitting starts ``skip`` samples after the step, to ignore one-sample glitches at the edge.
    ``null_series`` (K, n): the best gain over the τ grid of each, for the significance threshold."""
    starts, ends = np.asarray(starts) + skip, np.asarray(ends)
    keep = ends - starts >= 5
    starts, ends = starts[keep], ends[keep]
    if not starts.size:
        return None
    lens = ends - starts
    m = starts.size
    offs = np.cumsum(lens) - lens
    pos = np.arange(lens.sum()) - np.repeat(offs, lens)
    where = np.repeat(starts, lens) + pos
    tl = (pos + skip) * dt
    seg = np.repeat(np.arange(m), lens)
    S1 = lens.astype(float)
    rows = r[None, where] if null_series is None else np.vstack([r[where], null_series[:, where].astype(float)])
    Sr = np.add.reduceat(rows, offs, axis=1)
    Srr = np.sum(rows * rows, axis=1)
    sse_c = Srr - np.sum(Sr**2 / S1, axis=1)

    def fit(tau, R=rows, Sr=Sr, Srr=Srr):
        e = np.exp(-tl / tau)
        See, Se = np.bincount(seg, e * e, m), np.bincount(seg, e, m)
        Ser = np.add.reduceat(R * e, offs, axis=1)
        det = See * S1 - Se**2
        ok = det > 1e-12 * See * S1
        a = np.where(ok, (S1 * Ser - Se * Sr) / np.where(ok, det, 1.0), 0.0)
        c = np.where(ok, (See * Sr - Se * Ser) / np.where(ok, det, 1.0), Sr / S1)
        return np.maximum(Srr - np.sum(a * Ser + c * Sr, axis=1), 0.0), a, c

    lo, hi = 2 * dt, 2 * float(lens.max() + skip) * dt
    grid = np.geomspace(lo, hi, 32)
    sse = np.array([fit(x)[0] for x in grid])  # (grid, rows)
    gains = (sse_c[None, :] - sse) / np.where(Srr > 0, Srr, 1.0)[None, :]
    k = int(np.argmin(sse[:, 0]))
    one = (rows[:1], Sr[:1], Srr[:1])
    a_, b_ = np.log(grid[max(k - 1, 0)]), np.log(grid[min(k + 1, grid.size - 1)])
    opt = optimize.minimize_scalar(lambda lt: fit(math.exp(lt), *one)[0][0], bounds=(a_, b_), method="bounded",
                                   options={"xatol": 1e-4})
    tau = math.exp(opt.x) if opt.fun <= sse[k, 0] else float(grid[k])
    sse_t, a, c = fit(tau, *one)
    S0 = float(Srr[0])
    return {"tau": tau, "at_bound": bool(k in (0, grid.size - 1)), "a": a[0], "c": c[0], "keep": keep,
            "gain": (float(sse_c[0]) - float(sse_t[0])) / S0 if S0 > 0 else 0.0, "grid_gain": float(gains[k, 0]),
            "null_gains": gains[:, 1:].max(axis=0), "r2": 1 - float(sse_t[0]) / S0 if S0 > 0 else 0.0, "tau_range": (lo, hi)}


def _drift(ch, r, ctx, sur=None, sur_spec=None):
    """Low-frequency share (against the spectrum just above the band and the surrogates) and exponential tails after steps
    (null: the tail fit's gain on 20 surrogates; the tails must also follow the steps' direction)."""
    n, dt, t = ctx.n, ctx.dt, ctx.t
    T = n * dt
    out = []
    fc = max(ctx.f_exc / 10 if ctx.f_exc else 0.0, 2.0 / T)
    w = np.full(n // 2 + 1, 2.0)
    w[0] = 1.0
    if n % 2 == 0:
        w[-1] = 1.0
    f = np.fft.rfftfreq(n, dt)
    low = f <= fc
    R = np.abs(np.fft.rfft(r)) ** 2
    tot = float(np.sum(w * R))
    if tot > 0:
        share = float(np.sum(w[low] * R[low]) / tot)
        expected = float(np.sum(w[low]) / np.sum(w))
        # the low band (without 0 Hz) must stand out of the spectrum just above it, or the mean (0 Hz) must stand out
        # of the lowest bins: F tests of mean periodogram densities at 1 %
        k_low = int(low.sum())
        high = (f > fc) & (f <= max(4 * fc, f[min(R.size - 1, 4 * k_low + 3)]))
        kh = max(1, int(high.sum()))
        ratio = float(R[1:k_low].mean() / max(R[high].mean(), 1e-300)) if k_low > 1 and high.any() else 0.0
        thr = float(stats.f.isf(0.01, 2 * max(1, k_low - 1), 2 * kh))
        ref = R[1:k_low + kh]
        ratio0 = float(R[0] / max(ref.mean(), 1e-300)) if ref.size else math.inf
        thr0 = float(stats.f.isf(0.01, 1, 2 * max(1, ref.size)))
        if sur_spec is not None:  # and the share of noise with the residual's smoothed spectrum
            S2 = sur_spec.real**2 + sur_spec.imag**2
            null = _gumbel_quantile(np.sum(w[low] * S2[:, low], axis=1) / np.sum(w * S2, axis=1))
        else:
            null = expected
        ms = float(np.mean(r**2))
        tt = t - t.mean()
        slope = float(np.sum(tt * r) / np.sum(tt * tt))
        why = f"a tenth of {ctx.f_exc_source}" if ctx.f_exc and fc > 2.0 / T else "a slow trend over the recording"
        out.append(Finding("drift", ch, f"energy below {fc:.3g} Hz ({why})", share,
                           f"share of the residual energy below {fc:.3g} Hz (white noise would put {expected:.2%} there)",
                           {"cutoff_hz": fc, "expected_white": expected, "density_ratio": ratio, "threshold_ratio": thr,
                            "offset_ratio": ratio0, "threshold_offset_ratio": thr0, "threshold_share": null,
                            "offset_share": float(np.mean(r) ** 2 / ms), "slope_per_s": slope,
                            "significant": bool(share >= 0.2 and share > null and (ratio > thr or ratio0 > thr0))}))
    if ctx.merged:
        starts = [i for i, _, _ in ctx.merged]
        fit = _tail_fit(r, dt, starts, starts[1:] + [n], None if sur is None else sur[:20])
        if fit is not None:
            kept = [m for m, k in zip(ctx.merged, fit["keep"]) if k]
            a = fit["a"]
            per_unit = a / np.array([j for _, _, j in kept])
            sgn = np.sign(np.median(per_unit))
            consistency = float(np.mean(np.sign(per_unit) == sgn))
            null = fit["null_gains"]
            thr = float(max(0.1, null.mean() + 3 * null.std())) if null.size else 0.1
            names = ", ".join(dict.fromkeys(name for _, name, _ in kept))
            tau = fit["tau"]
            sig = fit["grid_gain"] > thr and not fit["at_bound"] and (len(kept) < 4 or consistency >= 0.75)
            out.append(Finding("drift", ch, f"decaying tails after {len(kept)} steps of {names}, τ = {tau:.3g} s", fit["gain"],
                               "share of the residual energy after the steps explained by exponential tails "
                               f"a·exp(-(t - t_step)/τ) beyond a constant per step (noise reaches {thr:.2f})",
                               {"tau_s": tau, "tau_at_bound": fit["at_bound"], "tau_range_s": list(fit["tau_range"]),
                                "amplitude": float(np.median(np.abs(a))), "amplitudes": [float(x) for x in a[:50]],
                                "amplitude_per_unit_step": float(np.median(per_unit)), "sign_consistency": consistency,
                                "r2_with_offsets": fit["r2"], "n_steps": len(kept), "threshold": thr, "significant": bool(sig)}))
    out.sort(key=lambda x: -x.strength)
    return out


# -- entry points --------------------------------------------------------------------------------------------------
def locate(t, residuals: dict, features: dict, inputs: dict, *, noise_std: dict | None = None, velocities=(),
           max_findings_per_kind: int = 3, significant_only: bool = True, seed: int = 0) -> list[Finding]:
    """Locate where the residuals concentrate, what they depend on, and how they scale.

    Parameters
    ----------
    t : array_like
        Uniform time grid (n >= 16 samples).
    residuals : dict of str to array_like
        Output channel -> measured minus simulated.  A channel whose residual is zero gives no finding.
    features : dict of str to array_like
        Signals of the fitted nominal model along the recording (states, velocities, charges, input
        voltages...).  Names starting with ``"v:"`` are velocities.
    inputs : dict of str to array_like
        Applied inputs; steps, peaks, the excitation's fundamental and the levels are detected from them.
    noise_std : dict of str to float, optional
        Measurement-noise standard deviation per channel; subtracted from the energies of the time
        windows and the scaling fits.
    velocities : sequence of str
        Further feature names to treat as velocities.
    max_findings_per_kind : int
        Most findings of one kind per channel.
    significant_only : bool
        Keep only findings that beat their noise threshold (the whiteness finding is always kept).
    seed : int
        Seed of the noise surrogates (results are reproducible).

    Returns
    -------
    list of Finding
        Per channel, in the order of :data:`KINDS`, strongest first within a kind.

    Raises
    ------
    InputDataError
        Naming the signal that is not finite, has the wrong length, or is not a feature.

    Examples
    --------
    >>> t = np.arange(0, 4, 1e-3)
    >>> v = np.cos(2 * np.pi * t)                      # a velocity of the nominal model
    >>> r = 0.2 * np.sign(v) + 0.01 * np.random.default_rng(1).standard_normal(t.size)
    >>> found = locate(t, {"y": r}, {"x": np.sin(2 * np.pi * t), "v:v": v}, {"U": np.sin(2 * np.pi * t)})
    >>> best = next(f for f in found if f.kind == "feature")
    >>> best.where, round(best.strength, 2)
    ('residual ~ sign(v)', 1.0)
    """
    t, dt, res, feats, ins, vel, sig = _validate(t, residuals, features, inputs, velocities, noise_std)
    kmax = int(max_findings_per_kind)
    ctx = _prepare(t, dt, feats, ins, vel)
    out = []
    for ci, (ch, r) in enumerate(res.items()):
        ms = float(np.mean(r**2))
        if ms == 0:
            continue
        sigma = sig.get(ch, 0.0)
        rc = r - r.mean()
        found = []
        if rc.std() > 1e-9 * math.sqrt(ms):
            sur, sur_spec = _surrogates(rc, np.random.default_rng([seed, ci]))
            found += _time_windows(ch, rc, ctx, sigma, sur)
            found += _feature_findings(ch, r, rc, ctx, sur, sigma, kmax)
            found += _spectral(ch, rc, ctx)
            found += _lags(ch, rc, ctx, sur_spec)
            found += _scaling(ch, r, ctx, sigma)
            found += _whiteness(ch, rc, ctx)
            found += _drift(ch, r, ctx, sur, sur_spec)
        else:
            found += _drift(ch, r, ctx)
        for kind in KINDS:
            of = [f for f in found if f.kind == kind and (f.significant or not significant_only or kind == "whiteness")]
            out += of[:kmax]
    return out


def plot_findings(t, residuals: dict, features: dict, inputs: dict, findings, path) -> str:
    """Figure of the located mismatch, one row per channel, written atomically to ``path`` (.png, .svg, .pdf).

    Columns: residual against time with the found windows shaded and the input steps marked; residual
    against its best regressor with the fitted line; residual spectrum with the found frequencies;
    cross-correlation with the input of the strongest lag finding (or the first input) and its threshold.

    Returns
    -------
    str
        ``path``.

    Raises
    ------
    InputDataError
        For malformed signals, an unsupported extension or a missing directory (nothing is written).

    Examples
    --------
    >>> import tempfile, os
    >>> t = np.arange(0, 2, 1e-3); U = np.sign(np.sin(2 * np.pi * t))
    >>> r = 0.1 * U**3 + 0.01 * np.random.default_rng(0).standard_normal(t.size)
    >>> found = locate(t, {"y": r}, {}, {"U": U})
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = plot_findings(t, {"y": r}, {}, {"U": U}, found, os.path.join(d, "locate.png"))
    ...     os.path.getsize(p) > 1000
    True
    """
    t, dt, res, feats, ins, vel, _ = _validate(t, residuals, features, inputs)
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    if ext not in ("png", "svg", "pdf"):
        raise InputDataError(f"cannot write {os.fspath(path)!r}: the figure format must be .png, .svg or .pdf")
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    if not os.path.isdir(folder):  # checked before the (slow) drawing; write_atomic checks again
        raise InputDataError(f"cannot write {os.fspath(path)!r}: directory {folder!r} does not exist")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    steps = {k: _steps(u) for k, u in ins.items()}
    merged = _merge_steps(steps)
    chans = list(res) or ["(no residual)"]
    fig = Figure(figsize=(17, 3.2 * len(chans)), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(chans), 4, squeeze=False)
    f0 = next((f.details.get("fundamental_hz") for f in findings if f.kind == "harmonic"), None)
    for row, ch in enumerate(chans):
        ax = axes[row]
        r = res.get(ch, np.zeros_like(t))
        mine = [f for f in findings if f.channel == ch]
        ax[0].plot(t, r, lw=0.6, color="C0")
        for f in mine:
            if f.kind == "time_window":
                for a, b in f.details.get("windows", [])[:100]:
                    ax[0].axvspan(a, b, color="C3", alpha=0.2, lw=0)
        for i, _, _ in merged[:200]:
            ax[0].axvline(t[i], color="0.6", lw=0.5, ls=":")
        ax[0].set(title=f"{ch}: residual (shaded: concentrated energy)", xlabel="t [s]")
        feat = next((f for f in mine if f.kind == "feature"), None)
        known = feat is not None and (feat.details["source"] == "events" or feat.details["base"] in
                                      (ins if feat.details["source"] == "input" else feats)) \
            and feat.details.get("velocity") in (None, *feats)
        if known:
            x = _regressor(feat.details, t, feats, ins, merged)
            k = max(1, t.size // 4000)
            ax[1].plot(x[::k], r[::k], ".", ms=2, alpha=0.5)
            xs = np.linspace(x.min(), x.max(), 50)
            ax[1].plot(xs, feat.details["intercept"] + feat.details["coefficient"] * xs, "C3")
            ax[1].set(title=f"vs {feat.details['regressor']} (R² {feat.strength:.3f})", xlabel=feat.details["regressor"])
        else:
            ax[1].text(0.5, 0.5, "no significant feature" if feat is None else f"{feat.details['regressor']}: signal not given",
                       ha="center", va="center", transform=ax[1].transAxes)
        rc = r - r.mean()
        if np.any(rc):
            fw, P = signal.welch(rc, 1 / dt, nperseg=_welch_len(t.size, 1 / dt, f0))
            ax[2].semilogy(fw[1:], P[1:], lw=0.8)
            for f in mine:
                if f.kind in ("harmonic", "spectrum") and "frequency_hz" in f.details:
                    ax[2].axvline(f.details["frequency_hz"], color="C3" if f.kind == "harmonic" else "C2", lw=0.8, alpha=0.7)
        ax[2].set(title="residual spectrum (Welch)", xlabel="f [Hz]", xscale="log")
        lagf = next((f for f in mine if f.kind == "input_lag"), None)
        name = lagf.details["input"] if lagf else next((k for k, u in ins.items() if np.ptp(u) > 0), None)
        if name is not None and np.any(rc):
            x = np.gradient(ins[name], dt) if lagf and lagf.details["derivative"] else ins[name]
            x = x - x.mean()
            m = int(min(t.size // 4, max(20, t.size // 10)))
            if np.any(x):
                nfft = sfft.next_fast_len(2 * t.size)
                cc = sfft.irfft(sfft.rfft(rc, nfft) * np.conj(sfft.rfft(x, nfft)), nfft)
                c = np.concatenate([cc[nfft - m:], cc[:m + 1]]) / (t.size * rc.std() * x.std())
                ax[3].plot(np.arange(-m, m + 1) * dt, c, lw=0.8)
                if lagf:
                    th = lagf.details["threshold"]
                    ax[3].axhspan(-th, th, color="0.85")
                    ax[3].axvline(lagf.details["lag_s"], color="C3", lw=0.8)
                ax[3].set(title=f"cross-correlation with {'d' + name + '/dt' if lagf and lagf.details['derivative'] else name}")
        ax[3].set(xlabel="lag [s] (> 0: residual follows)")
        for a in ax:
            a.grid(True, alpha=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format=ext, dpi=90)
    write_atomic(path, buf.getvalue())
    return os.fspath(path)


__all__ = ["Finding", "KINDS", "locate", "plot_findings"]
