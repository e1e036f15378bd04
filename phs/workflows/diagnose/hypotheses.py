"""Fitting and scoring hypotheses: the nominal model and each model augmented with a candidate."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from codegen import Simulator
from phs.errors import PHSError
from phs.signals import Sampled
from phs.workflows.identify import identify, nrmse_fit
from phs.workflows.recording import Recording


@dataclass
class Scored:
    """One fitted model: its parameter values, trajectories and scores.

    ``fit_percent`` / ``validation_fit_percent``: NRMSE fit % per channel on the training and
    validation parts; ``rss`` / ``validation_rss``: per-channel residual sums of squares divided by
    the channel's variance (so channels in different units add); ``bic``: Bayesian information
    criterion on the training part (Gaussian residuals, one variance per channel).
    """

    label: str
    system: object
    values: dict
    x0: np.ndarray
    n_params: int
    fit_percent: dict
    validation_fit_percent: dict
    rss: float
    validation_rss: float
    bic: float
    residuals: dict
    simulated: dict
    seconds: float
    augmentation: object = None
    element_values: dict = field(default_factory=dict)
    error: str = ""
    stage: str = "full"                  # "screening": fitted and scored on subsampled data only
    reference_rss: float | None = None   # validation residual of the model this one extends, same data
    reference_bic: float | None = None
    notes: list = field(default_factory=list)  # sentences for the explanation (why it was chosen)

    @property
    def ok(self) -> bool:
        return not self.error


@dataclass(frozen=True)
class Data:
    """What every fit needs: the full recording, which samples train and which validate, channels."""

    recording: Recording       # training recording (fitting)
    validation: Recording      # scored recording (may be the full recording when split)
    val_mask: np.ndarray       # samples of ``validation`` that count for validation scores
    train_mask: np.ndarray     # samples of ``validation`` that are the training part (split mode) or None
    outputs: list
    free: list
    bounds: dict
    log_scale: list
    x0: dict | None
    rtol: float = 1e-7
    estimate_x0: tuple = ()

    @property
    def n_train(self) -> int:
        return len(self.recording) * len(self.outputs)


def _transformed(rec: Recording, element, where: str, theta) -> Recording:
    if element is None:
        return rec
    sig = dict(rec.signals)
    sig[where] = element.transform(rec.t, np.asarray(rec[where], float), theta)
    return Recording(rec.t, sig, rec.source, rec.units)


def _simulate(system, rec: Recording, x0, params=None, sim=None):
    u = {n: Sampled(tuple(rec.t), tuple(rec[n])) for n in system.input_names}
    sim = sim or Simulator(system, energy=False)
    return sim.run(rec.t, u=u, x0=x0, params=params)


def _channel_rss(rec: Recording, sims: dict, outputs, mask=None) -> tuple[float, dict]:
    tot, per = 0.0, {}
    for ch in outputs:
        y, yh = np.asarray(rec[ch]), np.asarray(sims[ch])
        if mask is not None:
            y, yh = y[mask], yh[mask]
        var = float(np.var(y)) or 1.0
        per[ch] = float(np.sum((y - yh) ** 2))
        tot += per[ch] / var
    return tot, per


def bic(per_channel_rss: dict, n_samples: int, n_params: int) -> float:
    """BIC of Gaussian residuals with one variance per channel: ``Σ_ch N ln(RSS_ch/N) + k ln(N·n_ch)``.

    Examples
    --------
    >>> round(bic({"y": 1.0}, 100, 2), 3)
    -451.307
    """
    n_ch = max(len(per_channel_rss), 1)
    s = sum(n_samples * math.log(max(v, 1e-300) / n_samples) for v in per_channel_rss.values())
    return float(s + n_params * math.log(n_samples * n_ch))


def score(label, system, values, x0, n_params, data: Data, *, augmentation=None, element=None, where="", theta=(),
          element_values=None, seconds=0.0, train_residuals=None) -> Scored:
    """Simulate the fitted model on training and validation data and compute every score.

    With ``train_residuals`` (from the fit) the training simulation is not repeated; the full
    training trajectory is then simulated on demand (:func:`train_result`)."""
    fitted = system.with_params({k: v for k, v in values.items() if k in system.param_names})
    rec = _transformed(data.recording, element, where, theta)
    val = _transformed(data.validation, element, where, theta)
    sim = Simulator(fitted, energy=False)
    if train_residuals is not None:
        tr = None
        sims = {ch: np.asarray(rec[ch]) - np.asarray(train_residuals[ch]) for ch in data.outputs}
    else:
        tr = _simulate(fitted, rec, x0, sim=sim)
        sims = {ch: tr[ch] for ch in data.outputs}
    rss, per = _channel_rss(rec, sims, data.outputs)
    if val is rec or data.validation is data.recording:
        vsims = sims
    else:
        vr = _simulate(fitted, val, x0, sim=sim)
        vsims = {ch: vr[ch] for ch in data.outputs}
    vrss, _ = _channel_rss(val, vsims, data.outputs, data.val_mask)
    fits = {ch: nrmse_fit(rec[ch], sims[ch]) for ch in data.outputs}
    vfits = {ch: nrmse_fit(np.asarray(val[ch])[data.val_mask], np.asarray(vsims[ch])[data.val_mask]) for ch in data.outputs}
    res = {ch: np.asarray(rec[ch]) - sims[ch] for ch in data.outputs}
    return Scored(label, fitted, dict(values), np.asarray(x0, float), n_params, fits, vfits, rss, vrss,
                  bic(per, len(rec), n_params), res, {"train": tr, "validation": vsims}, seconds, augmentation,
                  dict(element_values or {}))


def fit_nominal(system, data: Data, progress=None) -> Scored:
    t0 = time.perf_counter()
    fit = identify(system, data.recording, data.free, bounds=data.bounds or None, x0=data.x0, outputs=data.outputs,
                   log_scale=data.log_scale or None, rtol=data.rtol, max_iter=60, estimate_x0=data.estimate_x0)
    return score("nominal", system, fit.values, fit.x0, len(data.free), data, seconds=time.perf_counter() - t0,
                 train_residuals=fit.residuals)


def train_result(h: Scored, data: Data):
    """The full simulated training trajectory of a scored model (simulated once, then kept)."""
    if h.simulated.get("train") is None:
        el = h.augmentation.element if h.augmentation is not None else None
        theta = list(h.element_values.values())
        rec = _transformed(data.recording, el, h.augmentation.attached_to if el else "", theta)
        h.simulated["train"] = _simulate(h.system, rec, h.x0)
    return h.simulated["train"]


def fit_augmented(nominal: Scored, aug, data: Data, joint: bool = True) -> Scored:
    """Fit the augmentation's parameters, together with the nominal free parameters when ``joint``,
    starting from the nominal fit."""
    t0 = time.perf_counter()
    label = f"{aug.effect}@{aug.attached_to}"
    try:
        if aug.element is not None:
            return _fit_input_element(nominal, aug, data, t0, joint)
        system = aug.system.with_params({k: v for k, v in nominal.values.items() if k in aug.system.param_names})
        # screening fits the nominal parameters too (a new element often takes over part of what they
        # did: stiffness, damping), but loosely: it only has to rank the hypotheses
        free = list(data.free) + list(aug.free)
        x0 = dict(zip(nominal.system.state_names, map(float, nominal.x0), strict=True))
        x0.update(aug.x0)
        bounds = {**(data.bounds or {}), **aug.bounds}
        # nominal parameters keep the nominal fit's log scaling; the new ones the candidate's choice
        nominal_log = list(data.log_scale) if data.log_scale else _default_log(system, data.free)
        log_scale = nominal_log + list(aug.log_scale)
        # screening needs the gain to a few per cent, not the optimum to eight digits; parameters whose
        # plausible values span decades are screened from each of the candidate's starts
        best = None
        for start in [{}] + [dict(st) for st in aug.starts]:
            try:
                # the estimated initial states are estimated again: a new element changes what start explains the data
                fit = identify(system.with_params(start) if start else system, data.recording, free, bounds=bounds, x0=x0,
                               outputs=data.outputs, log_scale=log_scale, rtol=data.rtol, max_iter=30 if joint else 10,
                               ftol=1e-6 if joint else 1e-3, compile=None if joint else False, estimate_x0=data.estimate_x0)
            except (PHSError, RuntimeError) as exc:
                if best is None and start == {} and not aug.starts:
                    raise
                last_error = exc
                continue
            if best is None or fit.cost < best.cost:
                best = fit
        if best is None:
            raise last_error
        return score(label, system, best.values, best.x0, len(data.free) + len(aug.free), data, augmentation=aug,
                     seconds=time.perf_counter() - t0, train_residuals=best.residuals)
    except (PHSError, RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return Scored(label, aug.system, {}, nominal.x0, 0, {}, {}, math.inf, math.inf, math.inf, {}, {},
                      time.perf_counter() - t0, aug, {}, msg)


def _default_log(system, free) -> list:
    out = []
    for k in free:
        p = system.param(k)
        if p.value > 0 and p.range and p.range[0] > 0 and p.range[1] / p.range[0] >= 10**1.5:
            out.append(k)
    return out


def _fit_input_element(nominal: Scored, aug, data: Data, t0: float, joint: bool = True) -> Scored:
    """Input elements: a bounded search of the element's parameters with the nominal parameters at their
    fit (one simulation per trial), then a refit of the nominal parameters through the element."""
    import scipy.optimize

    el, where = aug.element, aug.attached_to
    rec = data.recording
    specs = el.parameters(rec.t, np.asarray(rec[where], float))
    sim = Simulator(nominal.system, energy=False)
    outs = data.outputs
    var = {ch: float(np.var(rec[ch])) or 1.0 for ch in outs}

    def cost(theta):
        r = _transformed(rec, el, where, theta)
        try:
            s = _simulate(nominal.system, r, nominal.x0, sim=sim)
        except (PHSError, RuntimeError):
            return math.inf
        return sum(float(np.sum((np.asarray(r[ch]) - s[ch]) ** 2)) / var[ch] for ch in outs)

    theta = [s[1] for s in specs]
    for k, (_name, _start, lo, hi) in enumerate(specs):
        # coarse grid (log-spaced where the range is positive) then bounded refinement
        grid = np.geomspace(max(lo, 1e-3 * hi), hi, 9) if lo >= 0 else np.linspace(lo, hi, 9)
        if lo == 0:
            grid = np.concatenate([[0.0], grid])
        vals = []
        for g in grid:
            th = list(theta)
            th[k] = g
            vals.append(cost(th))
        b = int(np.argmin(vals))
        a, c = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]

        def f1(v, k=k):
            th = list(theta)
            th[k] = v
            return cost(th)

        if c > a:
            r = scipy.optimize.minimize_scalar(f1, bounds=(a, c), method="bounded", options={"xatol": 1e-3 * (c - a), "maxiter": 8})
            theta[k] = float(r.x) if r.fun <= vals[b] else float(grid[b])
        else:
            theta[k] = float(grid[b])
    transformed = _transformed(rec, el, where, theta)
    ev = {f"{el.effect}.{s[0]}": float(v) for s, v in zip(specs, theta, strict=True)}
    if not data.free and not data.estimate_x0:  # nothing of the model to refit through the element
        values, x0 = dict(nominal.values), nominal.x0
    else:
        fit = identify(nominal.system, transformed, data.free, bounds=data.bounds or None, x0=dict(
            zip(nominal.system.state_names, map(float, nominal.x0), strict=True)), outputs=outs,
            log_scale=data.log_scale or None, rtol=data.rtol, max_iter=30 if joint else 10, ftol=1e-6 if joint else 1e-3,
            compile=None if joint else False, estimate_x0=data.estimate_x0)
        values, x0 = fit.values, fit.x0
    return score(f"{aug.effect}@{where}", nominal.system, values, x0, len(data.free) + len(specs), data,
                 augmentation=aug, element=el, where=where, theta=theta, element_values=ev, seconds=time.perf_counter() - t0)
