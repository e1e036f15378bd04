"""Model-mismatch diagnosis: where a model and a recording disagree, which physics is missing, and the fix.

:func:`diagnose` (1) fits the nominal model on the training recording, (2) locates the mismatch in the
residuals (:mod:`phs.workflows.diagnose.locate`: time windows, state/input features, spectrum,
lags, amplitude scaling, whiteness, drift), (3) attaches every candidate of the library
(:mod:`components.candidates`) at every place it fits, (4) fits each augmented model (the new
parameters together with the nominal free ones) and ranks them by validation fit and BIC, keeping the
simplest sufficient explanation and trying a second effect only when the first leaves a structured
residual, and (5) explains the verdict in words, with the augmented model's structural checks
(J skew, R positive semi-definite) and the fit before and after.

Acceptance rule of a hypothesis (documented in ``docs/workflows/diagnose.md``): its training BIC is at
least :data:`MIN_BIC_GAIN` below the nominal model's, and its validation residual (sum over channels of
RSS / variance) at least :data:`MIN_VALIDATION_GAIN` (relative) below the nominal model's.  Hypotheses
whose validation residual is within :data:`SUFFICIENT_MARGIN` of the best accepted one count as equally
good; among them the one with the fewest parameters wins (then BIC).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from phs.errors import InputDataError, ParameterError

MIN_BIC_GAIN = 10.0
"""Training BIC decrease needed to accept a hypothesis ("very strong" evidence on the Kass-Raftery scale)."""
MIN_VALIDATION_GAIN = 0.01
"""Relative decrease of the validation residual needed to accept a hypothesis."""
SUFFICIENT_MARGIN = 0.03
"""Hypotheses within this relative validation-residual margin of the best count as equally good."""
FRICTION_LIKE = 0.05
"""A hysteresis loop whose saturated deflection ``F_h / (k_h (1 + eta))`` is below this share of the
displacement's standard deviation is friction with a pre-sliding regime, not a loop of the material:
when smooth Coulomb friction at the same place is accepted too, it is the simpler explanation."""
SPLIT = 0.7
"""Share of a single recording used for training when no validation recording is given."""


def noise_level(y) -> float:
    """Standard deviation of white measurement noise estimated from second differences
    (``std(Δ²y)/√6``; smooth signal content sampled fast contributes little).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.linspace(0, 1, 5001)
    >>> round(noise_level(np.sin(2 * np.pi * t) + 0.01 * rng.standard_normal(t.size)), 3)
    0.01
    """
    y = np.asarray(y, float)
    return float(np.std(np.diff(y, 2)) / math.sqrt(6.0)) if y.size > 3 else 0.0


@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`: the nominal fit, the located mismatch, the ranked hypotheses,
    the accepted effects and the final model.  ``to_dict()`` is the documented JSON."""

    system: object
    outputs: list
    nominal: object
    findings: list
    hypotheses: list
    accepted: list
    final: object
    verdict: dict
    noise: dict
    seconds: float
    rounds: list = field(default_factory=list)
    data: object = None
    final_findings: list = field(default_factory=list)

    @property
    def effect(self) -> str:
        """The main effect's name, or ``"none"``."""
        return self.verdict["effect"]

    @property
    def final_system(self):
        """The final (augmented and fitted) model."""
        return self.final.system

    def structure_checks(self) -> dict:
        """Structural checks of the final model (J skew, R PSD, H bounded below, units)."""
        rep = self.final.system.check()
        return {"ok": bool(rep.ok), "report": str(rep)}

    def to_dict(self) -> dict:
        def hyp(h, rank):
            aug = h.augmentation
            return {
                "rank": rank, "effect": aug.effect, "component": aug.component, "attached_to": aug.attached_to,
                "parameters": {**{k: h.values.get(k) for k in aug.free}, **h.element_values},
                "fit_percent": h.fit_percent, "validation_fit_percent": h.validation_fit_percent,
                "criterion": {"bic": h.bic, "delta_bic": _delta_bic(self.nominal, h) if math.isfinite(h.bic) else None, "stage": h.stage,
                              "validation_residual": h.validation_rss,
                              "validation_gain": _gain(self.nominal, h)},
                "n_params": h.n_params, "accepted": any(h is a for a in self.accepted), "seconds": h.seconds,
                **({"error": h.error} if h.error else {}),
            }

        return {
            "system": self.system.name, "model_hash": self.system.model_hash(), "outputs": self.outputs,
            "baseline": {"fit_percent": self.nominal.fit_percent, "validation_fit_percent": self.nominal.validation_fit_percent,
                         "parameters": self.nominal.values, "bic": self.nominal.bic},
            "noise": self.noise,
            "mismatch": [f.to_dict() for f in self.findings],
            "hypotheses": [hyp(h, i + 1) for i, h in enumerate(self.hypotheses)],
            "verdict": self.verdict,
            "final": {"fit_percent": self.final.fit_percent, "validation_fit_percent": self.final.validation_fit_percent,
                      "parameters": {**self.final.values, **self.final.element_values},
                      "passive": self.structure_checks()["ok"]},
            "seconds": self.seconds,
        }

    def summary(self) -> str:
        v = self.verdict
        lines = [f"Diagnosis of {self.system.name!r} ({self.seconds:.1f} s): verdict {v['effect']}"
                 + (f" (effects: {', '.join(v['effects'])})" if len(v["effects"]) > 1 else "")
                 + f", confidence {v['confidence']:.2f}", "  " + v["explanation"]]
        lines.append("  fit % (training / validation):")
        for ch in self.outputs:
            lines.append(f"    {ch}: nominal {self.nominal.fit_percent[ch]:.2f} / {self.nominal.validation_fit_percent[ch]:.2f}"
                         f"  ->  final {self.final.fit_percent[ch]:.2f} / {self.final.validation_fit_percent[ch]:.2f}")
        lines.append("  located mismatch:")
        for f in self.findings[:8]:
            lines.append(f"    [{f.kind}] {f.channel}: {f.where} (strength {f.strength:.3g})")
        lines.append("  hypotheses (best first):")
        for h in self.hypotheses[:8]:
            if h.error:
                lines.append(f"    {h.label:<32} failed: {h.error}")
                continue
            vf = ", ".join(f"{k} {x:.2f}" for k, x in h.validation_fit_percent.items())
            lines.append(f"    {h.label:<32} validation fit {vf}; ΔBIC {_delta_bic(self.nominal, h):+.1f}; "
                         f"gain {100 * _gain(self.nominal, h):+.1f} %" + (" (screening)" if h.stage != "full" else "")
                         + ("  accepted" if any(h is a for a in self.accepted) else ""))
        return "\n".join(lines)

    __str__ = summary

    def write_report(self, directory) -> None:
        """HTML report with figures, and ``diagnosis.json``, into ``directory`` (written atomically)."""
        from phs.workflows.diagnose.report import write_report

        write_report(self, directory)


def _gain(nominal, h) -> float:
    """Relative decrease of the validation residual against the model it extends (scored on the same data)."""
    ref = h.reference_rss if h.reference_rss is not None else nominal.validation_rss
    if not math.isfinite(h.validation_rss) or ref <= 0:
        return -math.inf
    return float((ref - h.validation_rss) / ref)


def _delta_bic(nominal, h) -> float:
    ref = h.reference_bic if h.reference_bic is not None else nominal.bic
    return float(h.bic - ref)


def _accepted(nominal, h) -> bool:
    return h.ok and h.stage == "full" and -_delta_bic(nominal, h) >= MIN_BIC_GAIN and _gain(nominal, h) >= MIN_VALIDATION_GAIN


def _pick(nominal, hyps, data=None):
    """Best accepted hypothesis, preferring fewer parameters among the equally good ones, and Coulomb
    friction over a hysteresis element that only describes friction (see :data:`FRICTION_LIKE`)."""
    acc = [h for h in hyps if _accepted(nominal, h)]
    if not acc:
        return None
    best = min(h.validation_rss for h in acc)
    good = [h for h in acc if h.validation_rss <= best * (1 + SUFFICIENT_MARGIN) + 1e-300]
    pick = min(good, key=lambda h: (h.n_params, h.bic))
    if data is not None and pick.augmentation.effect == "hysteresis":
        share = presliding_share(nominal, pick, data)
        friction = [h for h in acc if h.augmentation.effect == "coulomb_friction"
                    and h.augmentation.attached_to == pick.augmentation.attached_to]
        if share is not None and share < FRICTION_LIKE and friction:
            f = friction[0]
            f.notes.append(f"A hysteresis element at {pick.augmentation.attached_to} fits a little better (validation residual "
                           f"{100 * _gain(nominal, pick):+.1f} % against {100 * _gain(nominal, f):+.1f} %), but its loop closes "
                           f"within {100 * share:.2g} % of the motion's standard deviation: that is the pre-sliding regime of "
                           f"friction, not a hysteresis of the material, and smooth Coulomb friction describes it with fewer parameters.")
            return f
    return pick


def presliding_share(nominal, h, data) -> float | None:
    """For a fitted ``hysteresis`` hypothesis: its saturated deflection ``F_h / (k_h (1 + eta))``
    divided by the standard deviation of the displacement its momentum moves (along the nominal
    fit: its velocity ∂H/∂p integrated); None for other effects or grouped attachments.
    Small (≪ 1): the loop closes within a tiny part of the motion — pre-sliding friction; of order
    one or more: the loop spans the motion — hysteresis of the material or the structure.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> from codegen import simulate
    >>> from phs.workflows.recording import Recording
    >>> t = np.linspace(0, 0.02, 401); u = np.where((t % 0.01) > 0.005, 1.0, 0.0)
    >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
    >>> d = diagnose(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"])
    >>> presliding_share(d.nominal, d.accepted[0], d.data) is None   # an offset, not a hysteresis
    True
    """
    from scipy.integrate import cumulative_trapezoid

    from phs.workflows.diagnose.hypotheses import train_result

    aug = h.augmentation
    if aug.effect != "hysteresis" or aug.attached_to.startswith("*."):
        return None
    k, F, eta = (h.values.get(f"hysteresis.{n}") for n in ("k_h", "F_h", "eta"))
    if k is None or F is None:
        return None
    eta = 0.0 if eta is None else eta
    if 1 + eta <= 0 or k <= 0:
        return math.inf
    # the displacement the momentum moves: its velocity ∂H/∂p integrated along the nominal fit
    s = nominal.system
    res = train_result(nominal, data)
    X = np.asarray(res.x)
    i = s.state_names.index(aug.attached_to)
    grad = s.with_params(nominal.values).lambdify(s.grad_H[i], with_u=False)
    v = np.broadcast_to(np.asarray(grad(X.T), dtype=float).reshape(-1), (len(X),)) if len(X) else np.zeros(0)
    disp = cumulative_trapezoid(v, np.asarray(res.t), initial=0.0)
    stroke = float(np.std(disp))
    return float(F / (k * (1 + eta)) / stroke) if stroke > 0 else math.inf


def _run_all(nominal, augs, data, n_jobs, progress, label, joint=True):
    import concurrent.futures as cf
    import multiprocessing as mp

    from phs.workflows.diagnose.hypotheses import fit_augmented

    light = replace(nominal, simulated={}, residuals={})
    out = []

    def done(k, h):  # every result is measured against the model it extends, scored on the same data
        h.reference_rss, h.reference_bic = nominal.validation_rss, nominal.bic
        _progress(progress, label, k, len(augs), h)

    if n_jobs > 1 and len(augs) > 1 and "fork" in mp.get_all_start_methods():
        # fork: workers inherit the loaded modules (no re-import of the user's script, no __main__ guard)
        try:
            with cf.ProcessPoolExecutor(max_workers=n_jobs, mp_context=mp.get_context("fork")) as ex:
                futs = [ex.submit(fit_augmented, light, a, data, joint) for a in augs]
                for k, f in enumerate(cf.as_completed(futs), 1):
                    out.append(f.result())
                    done(k, out[-1])
            return out
        except cf.process.BrokenProcessPool:  # a worker died (e.g. out of memory): finish serially
            out = []
    for k, a in enumerate(augs, 1):
        out.append(fit_augmented(light, a, data, joint))
        done(k, out[-1])
    return out


def _for_refit(h):
    """A screened hypothesis' augmentation, started from its screening values for the joint refit."""
    aug = h.augmentation
    if aug.element is None:
        aug = replace(aug, system=aug.system.with_params({k: v for k, v in h.values.items() if k in aug.system.param_names}),
                      starts=())
    return aug


def _refit_friction_rival(current, hyps, pick, data, progress, label):
    """When a friction-like hysteresis wins (:data:`FRICTION_LIKE`) and Coulomb friction at the same
    momentum was only screened, refit it jointly so that :func:`_pick` can weigh the two alike."""
    if pick is None or pick.augmentation.effect != "hysteresis":
        return False
    share = presliding_share(current, pick, data)
    if share is None or share >= FRICTION_LIKE:
        return False
    rivals = [h for h in hyps if h.ok and h.stage != "full" and h.augmentation.effect == "coulomb_friction"
              and h.augmentation.attached_to == pick.augmentation.attached_to]
    if not rivals:
        return False
    full = _run_all(current, [_for_refit(rivals[0])], data, 1, progress, label + " joint refit")[0]
    hyps[hyps.index(rivals[0])] = full
    return True


def _screen_and_refit(current, augs, data, n_jobs, progress, label, refit_top):
    """Screen every hypothesis by a loose joint fit (few iterations, input elements by their search alone),
    then refit the ``refit_top`` most promising to convergence."""
    if refit_top <= 0 or len(augs) <= refit_top:
        return _run_all(current, augs, data, n_jobs, progress, label)
    screened = _run_all(current, augs, data, n_jobs, progress, label + " screening", joint=False)
    screened.sort(key=lambda h: (not h.ok, -_gain(current, h)))
    top, seen = [], set()
    for h in screened:  # the most promising distinct effects (one attachment each)
        if h.ok and h.augmentation.effect not in seen and len(top) < refit_top:
            top.append(h)
            seen.add(h.augmentation.effect)
    refits = [_for_refit(h) for h in top]
    full = _run_all(current, refits, data, n_jobs, progress, label + " joint refit")
    done = {(f.augmentation.effect, f.augmentation.attached_to) for f in full}
    rest = [h for h in screened if (h.augmentation.effect, h.augmentation.attached_to) not in done]
    for h in rest:
        h.stage = "screening"
    return full + rest


def _progress(progress, label, k, n, h):
    if not progress:
        return
    state = f"failed ({h.error})" if h.error else "validation " + ", ".join(f"{c} {v:.1f} %" for c, v in h.validation_fit_percent.items())
    print(f"  {label} [{k}/{n}] {h.label}: {state} ({h.seconds:.1f} s)", file=sys.stderr, flush=True)


def _features(scored, system, data) -> tuple[dict, dict]:
    """Model signals along the training recording for locating: states, velocities (``v:`` + momentum
    state), inputs; and the inputs separately."""
    from components.candidates import momentum_states
    from phs.workflows.diagnose.hypotheses import train_result

    res = train_result(scored, data)
    feats = {name: np.asarray(res[name]) for name in system.state_names}
    inputs = {name: np.asarray(res[name]) for name in system.input_names}
    if momentum_states(system):
        grad = system.with_params(scored.values).lambdify(system.grad_H, with_u=False)
        X = np.asarray(res.x)
        G = np.array([np.asarray(grad(x), float).reshape(-1) for x in X])
        for p in momentum_states(system):
            feats[f"v:{p}"] = G[:, system.state_names.index(p)]
    return feats, inputs


def _locate(scored, system, data, noise):
    from phs.workflows.diagnose import locate as _loc

    feats, inputs = _features(scored, system, data)
    return _loc.locate(data.recording.t, scored.residuals, feats, inputs, noise_std=noise)


def diagnose(system, recording, *, validation=None, free=None, outputs=None, candidates=None, x0=None, bounds=None,
             log_scale=None, max_effects: int = 2, n_jobs: int | None = None, progress: bool = False, rtol: float = 1e-7,
             refit_top: int = 3, estimate_x0=()) -> Diagnosis:
    """Find where ``system`` and ``recording`` disagree, which physics is missing, and the fixed model.

    Parameters
    ----------
    system : PHSystem
        The nominal model (built from components by the user).
    recording : Recording
        Training recording (uniformly sampled) with every input and the fitted outputs.
    validation : Recording, optional
        Validation recording; default: the last 30 % of ``recording`` (fitted on the first 70 %).
    free : sequence of str, optional
        Nominal parameters refitted with every hypothesis (default: every parameter with a declared
        range, at most 8).
    outputs : sequence of str, optional
        Channels to fit (default: every measured output in the recording).
    candidates : sequence of Candidate, optional
        Default :data:`components.candidates.LIBRARY`; add your own :class:`components.candidates.Candidate`.
    x0 : dict, optional
        Initial state of the nominal model.
    estimate_x0 : sequence of str
        States whose initial values are estimated with the nominal fit (a recording that does not
        start at rest); every hypothesis then starts from them.
    bounds, log_scale : optional
        Passed to :func:`phs.identify` for the nominal parameters.
    max_effects : int
        Most effects accepted one after the other.
    n_jobs : int, optional
        Processes fitting hypotheses in parallel (default: the number of CPUs, at most 4).
    refit_top : int
        Every hypothesis is first screened by a loose fit (at most 10 evaluations); the ``refit_top``
        most promising are then refitted to convergence (0: every hypothesis is fitted to convergence).
    progress : bool
        Print one line per fitted hypothesis on stderr.

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> import numpy as np
    >>> from systems.examples import rc_circuit
    >>> from codegen import simulate
    >>> from phs.workflows.recording import Recording
    >>> t = np.linspace(0, 0.02, 401); u = np.where((t % 0.01) > 0.005, 1.0, 0.0)
    >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05   # a sensor offset
    >>> d = diagnose(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"])
    >>> d.effect
    'offset'
    """
    from components.candidates import LIBRARY, Scales
    from phs.workflows.diagnose.hypotheses import Data, fit_nominal, train_result

    wall = time.perf_counter()
    if n_jobs is None:
        import os

        n_jobs = max(1, min(4, os.cpu_count() or 1))
    _, outs = recording.check_for(system, outputs)
    if free is None:
        free = [p.name for p in system.params if p.range is not None and p.value not in (None, 0)][:8]
        if not free:
            raise ParameterError(f"diagnose: system {system.name!r} has no parameter with a declared range; give free=[...]")
    free = list(free)
    for k in free:
        system.param(k)
    if max_effects < 0:
        raise ParameterError(f"diagnose: max_effects must be >= 0, got {max_effects}")
    if validation is None:
        t = recording.t
        at = t[0] + SPLIT * (t[-1] - t[0])
        if len(recording) < 40:
            raise InputDataError(f"{recording.source}: too short to split into training and validation ({len(recording)} samples)")
        train = recording.window(t[0], at)
        data = Data(train, recording, t > at, t <= at, outs, free, dict(bounds or {}), list(log_scale or []), x0, rtol,
                    tuple(estimate_x0))
    else:
        validation.check_for(system, outs)
        data = Data(recording, validation, np.ones(len(validation), bool), None, outs, free, dict(bounds or {}),
                    list(log_scale or []), x0, rtol, tuple(estimate_x0))
    noise = {ch: noise_level(recording[ch]) for ch in outs}
    cands = list(LIBRARY if candidates is None else candidates)

    if progress:
        print(f"diagnose {system.name}: fitting the nominal model ({', '.join(free)})", file=sys.stderr, flush=True)
    nominal = fit_nominal(system, data)
    findings = _locate(nominal, system, data, noise)
    current, accepted, all_hyps, rounds = nominal, [], [], []
    pool = cands
    for round_ in range(max_effects):
        res = train_result(current, data)
        X = np.asarray(res.x)
        names = current.system.input_names
        U = np.column_stack([np.asarray(res[n]) for n in names]) if names else np.zeros((len(X), 0))
        scales = Scales.of(current.system.with_params(current.values), res.t, X, U,
                           {ch: data.recording[ch] for ch in outs})
        augs = []
        for c in pool:
            for w in c.attach_points(current.system):
                if c.kind == "input" and np.ptp(np.asarray(data.recording[w], float)) == 0:
                    continue  # a constant input: saturation, slew rate or delay change nothing
                if any(a.augmentation.effect == c.effect and a.augmentation.attached_to == w for a in accepted):
                    continue
                try:
                    aug = c.augment(current.system.with_params(current.values), w, scales)
                    augs.append(aug if aug.summary else replace(aug, summary=c.summary))
                except Exception as exc:  # a user candidate that cannot attach here is skipped, and said so
                    if progress:
                        print(f"  {c.effect}@{w}: cannot attach ({exc})", file=sys.stderr)
        if progress:
            print(f"diagnose {system.name}: round {round_ + 1}, {len(augs)} hypotheses", file=sys.stderr, flush=True)
        data_r = data if round_ == 0 or accepted[-1].augmentation.element is None else _through_element(data, accepted[-1])
        if round_ > 0:
            data_r = replace(data_r, free=list(dict.fromkeys(list(data_r.free) + [k for a in accepted for k in a.augmentation.free])))
        hyps = _screen_and_refit(current, augs, data_r, n_jobs, progress, f"round {round_ + 1}", refit_top)
        hyps.sort(key=lambda h: (not h.ok, h.stage != "full", -_gain(current, h)))
        rounds.append(hyps)
        if round_ == 0:
            all_hyps = hyps
        pick = _pick(current, hyps, data_r)
        if _refit_friction_rival(current, hyps, pick, data_r, progress, f"round {round_ + 1}"):
            hyps.sort(key=lambda h: (not h.ok, h.stage != "full", -_gain(current, h)))
            pick = _pick(current, hyps, data_r)
        if pick is not None:  # the chosen explanation heads the ranking (simplest sufficient, then by gain)
            hyps.remove(pick)
            hyps.insert(0, pick)
        if pick is None:
            break
        accepted.append(pick)
        current = pick
        data = data_r
        # a second effect only when the first leaves a structured residual well above the noise
        if not _structured(current, noise, outs):
            break
        # second round: the most promising other effects of round 1
        promising = [h.augmentation.effect for h in all_hyps if h.ok and h is not pick and _gain(nominal, h) > 0]
        pool = [c for c in cands if c.effect in promising[:6] and c.effect != pick.augmentation.effect]
        if not pool:
            break
    final_findings = _locate(current, current.system, data, noise) if accepted else findings
    verdict = _verdict(nominal, accepted, all_hyps, findings, outs)
    return Diagnosis(system, outs, nominal, findings, all_hyps, accepted, current, verdict, noise,
                     time.perf_counter() - wall, rounds, data, final_findings)


def _through_element(data, h):
    from phs.workflows.diagnose.hypotheses import _transformed

    el, where = h.augmentation.element, h.augmentation.attached_to
    theta = [h.element_values[f"{el.effect}.{s}"] for s in [p[0] for p in el.parameters(data.recording.t, data.recording[where])]]
    return replace(data, recording=_transformed(data.recording, el, where, theta),
                   validation=_transformed(data.validation, el, where, theta))


def _structured(h, noise, outs) -> bool:
    """Residual RMS above 1.5 times the noise in some channel."""
    for ch in outs:
        r = h.residuals.get(ch)
        if r is not None and noise.get(ch, 0) > 0 and float(np.sqrt(np.mean(r**2))) > 1.5 * noise[ch]:
            return True
    return False


def _verdict(nominal, accepted, hyps, findings, outs) -> dict:
    from phs.workflows.diagnose.report import explanation

    ok = [h for h in hyps if h.ok]
    if not accepted:
        best = ok[0] if ok else None
        g = _gain(nominal, best) if best else 0.0
        conf = float(np.clip(1.0 - max(g, 0.0) / (2 * MIN_VALIDATION_GAIN), 0.0, 1.0)) if best else 0.5
        conf = max(conf, 0.5) if (best is None or -_delta_bic(nominal, best) < MIN_BIC_GAIN) else conf
        return {"effect": "none", "effects": [], "explanation": explanation(nominal, [], findings, best, outs),
                "confidence": round(conf, 3)}
    main = accepted[0]
    rivals = [h for h in ok if h.augmentation.effect != main.augmentation.effect]
    g_main = _gain(nominal, main)
    g_rival = max([_gain(nominal, h) for h in rivals] + [0.0])
    sep = (g_main - g_rival) / g_main if g_main > 0 else 0.0
    conf = float(np.clip(0.5 + 0.5 * sep, 0.0, 1.0))
    return {"effect": main.augmentation.effect, "effects": [a.augmentation.effect for a in accepted],
            "explanation": explanation(nominal, accepted, findings, rivals[0] if rivals else None, outs),
            "confidence": round(conf, 3)}


__all__ = ["diagnose", "Diagnosis", "noise_level", "presliding_share", "MIN_BIC_GAIN", "MIN_VALIDATION_GAIN", "SUFFICIENT_MARGIN",
           "FRICTION_LIKE"]
