"""Time-window findings: where the residual's energy concentrates, in single windows and in windows locked to
events (after each input step, around each velocity reversal or input peak)."""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.locate._common import _disp, _gumbel_quantile
from phs.workflows.diagnose.locate.finding import Finding


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
