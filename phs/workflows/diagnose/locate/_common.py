"""Helpers shared by the locators: the noise surrogates and their thresholds, signal names, number formats."""

from __future__ import annotations

import math

import numpy as np
import scipy.fft as sfft
from scipy import signal

N_SURROGATES = 100
"""Noise surrogates per channel for the significance thresholds.  Not chosen on a measurement."""
NULL_QUANTILE = 0.99
"""Quantile of the surrogates' best value used as the significance threshold.
A convention (1 % false alarms per test), not a measurement."""


def _disp(key: str) -> str:
    return key[2:] if key.startswith("v:") else key


def _fmt_lag(s):
    if abs(s) < 1:
        return f"{s * 1e3:+.3g} ms"
    return f"{s:+.3g} s"


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


def _gumbel_quantile(maxima) -> float:
    """:data:`NULL_QUANTILE` of a Gumbel law fitted by moments to the surrogates' maxima (steadier than
    the empirical quantile of 100 values)."""
    m = np.asarray(maxima, dtype=float)
    beta = float(m.std()) * math.sqrt(6) / math.pi
    return float(m.mean() - 0.5772156649 * beta - beta * math.log(-math.log(NULL_QUANTILE)))
