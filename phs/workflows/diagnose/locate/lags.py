"""Lag findings: the peak of the residual's cross-correlation with each input and its derivative, and at
which lag."""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft

from phs.workflows.diagnose.locate._common import _fmt_lag, _gumbel_quantile
from phs.workflows.diagnose.locate.finding import Finding


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
