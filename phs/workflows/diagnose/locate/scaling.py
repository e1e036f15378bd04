"""Scaling findings: the exponent of the power law of the residual's RMS against an input's level (between its
steps, or over blocks of a smooth input) and against its rate."""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.locate.finding import Finding


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
