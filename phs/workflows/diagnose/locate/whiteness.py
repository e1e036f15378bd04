"""The whiteness finding: the Ljung-Box statistic of the residual's autocorrelation (reported for every channel)."""

from __future__ import annotations

import numpy as np
import scipy.fft as sfft
from scipy import stats

from phs.workflows.diagnose.locate._common import _fmt_lag
from phs.workflows.diagnose.locate.finding import Finding


def _acf(x, maxlag):
    n = x.size
    maxlag = int(min(maxlag, n - 1))
    nfft = sfft.next_fast_len(2 * n)
    X = sfft.rfft(x, nfft)
    a = sfft.irfft(X * np.conj(X), nfft)[:maxlag + 1]
    return a / a[0] if a[0] > 0 else np.zeros(maxlag + 1)


def _whiteness(ch, rc, ctx):
    n = ctx.n
    h = int(min(20, max(1, n // 5)))
    rho = _acf(rc, h)[1:]
    Q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, h + 1))))
    p = float(stats.chi2.sf(Q, h))
    return [Finding("whiteness", ch, f"lags 1–{h} ({_fmt_lag(ctx.dt)[1:]}–{_fmt_lag(h * ctx.dt)[1:]})", Q,
                    f"Ljung-Box statistic over lags 1–{h} (a white residual gives about {h}); p = {p:.3g}",
                    {"statistic": Q, "p_value": p, "lags": h, "significant": bool(p < 0.01)})]
