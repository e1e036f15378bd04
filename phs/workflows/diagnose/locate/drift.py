"""Drift findings: the share of the residual's energy below a tenth of the excitation frequency, and decaying
exponential tails after the input steps."""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, stats

from phs.workflows.diagnose.locate._common import _gumbel_quantile
from phs.workflows.diagnose.locate.finding import Finding


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
