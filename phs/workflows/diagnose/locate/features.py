"""Feature findings: the share of the residual's variance a straight line on one model signal explains.

The regressors are every feature and input through the transforms of :data:`_TRANSFORMS`, the features
and inputs times the sign of each velocity, each input's time derivative and the time since the last
input step; a regressor equal to an earlier one of the same signal is dropped.
"""

from __future__ import annotations

import numpy as np

from phs.workflows.diagnose.locate._common import N_SURROGATES, NULL_QUANTILE, _disp, _gumbel_quantile
from phs.workflows.diagnose.locate.finding import Finding

_TRANSFORMS = {"x": "{}", "|x|": "|{}|", "sign(x)": "sign({})", "x^2": "{}²", "x^3": "{}³", "x|x|": "{}·|{}|"}


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


def _regressor_matrix(t, feats, ins, vel, merged):
    """The regressors of the feature findings: their descriptions (``specs``), the standardized signals as rows
    of ``Z`` (single precision), and the means and standard deviations they were standardized with."""
    # every transform of every feature and input, products with sign(velocity), dU/dt, time since step
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
        return [specs[i] for i in keep], np.vstack([rows[i] for i in keep]), np.array(means)[keep], np.array(sds)[keep]
    return specs, None, None, None


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
