"""Spectral findings: the residual power at the harmonics of a periodic excitation, in other spectral peaks,
and coherent with an input."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, signal, stats

from phs.workflows.diagnose.locate._common import _welch_len
from phs.workflows.diagnose.locate.finding import Finding


def _ordinal(k):
    return f"{k}{'th' if 10 <= k % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(k % 10, 'th')}"


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
