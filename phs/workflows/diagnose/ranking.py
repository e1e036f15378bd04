"""Scoring, accepting and choosing hypotheses.

Every fitted hypothesis is measured against the model it extends, scored on the same data: the relative
decrease of its validation residual and its change of BIC.  The acceptance rule and the preference for
the simplest sufficient explanation are stated in :mod:`phs.workflows.diagnose`.
"""

from __future__ import annotations

import math

import numpy as np

from phs.workflows.diagnose.calibration import reported

MIN_BIC_GAIN = 10.0
"""Training BIC decrease needed to accept a hypothesis ("very strong" evidence on the Kass-Raftery scale).
A convention, not a measurement."""
MIN_VALIDATION_GAIN = 0.01
"""Relative decrease of the validation residual needed to accept a hypothesis.  Not chosen on a measurement."""
SUFFICIENT_MARGIN = 0.03
"""Hypotheses within this relative margin of the best validation residual and of the best training residual
count as equally good (:func:`_pick`).  Not chosen on a measurement."""
FAILED_FACTOR = 0.9
"""Each hypothesis whose fit failed (every retry included) multiplies the verdict's confidence by this:
it is a rival that could not be weighed, so a verdict with a failed hypothesis never reports 1.
A convention, not a measurement (no stored calibration diagnosis had a failed hypothesis)."""
CALIBRATION: dict = {
    "effect": ((0.523, 0.938),),
    "none": ((0.982, 0.75),),
}
"""Knots ``(raw score, share of right verdicts)`` of the confidence's calibration, for verdicts naming an
effect (``"effect"``) and for ``"none"``: :func:`~phs.workflows.diagnose.calibration.fit_calibration` of every
stored diagnosis in ``bench/calibration_data.jsonl`` (``bench/calibrate_confidence.py``: 80 diagnoses of the
electrostatic actuator's concealed effects at 0.35, 0.6 and 1 times their tuned strength, 3 s recordings,
noise seeds other than the tests', collected with the screening, refit and deferral rules of
``phs.workflows.diagnose.screening``).  A fit, not a threshold: the held-out cases
(:func:`~phs.workflows.diagnose.calibration.is_held_out`) are among the diagnoses it is fitted on, and it is
judged by cross-validation instead.  On that set a verdict naming an effect was right 74 times in 78 (the
four wrong ones: weak slew-rate limits, which never act on the recorded commands, named ``quadratic_drag``
and scaled by the share rule) and a ``none``
2 times in 2, the controls (``none`` means "nothing the library can detect in this recording", not "no
missing physics"); the raw score does not rank right verdicts above wrong ones (the wrong ones score 0.86
and 0.98), so every verdict naming an effect is one level.  In sample its Brier score is 0.049 (raw score
0.117) and its reliability 0.017; fitted without the concealed effect it is scored on (14 groups), 0.056
and 0.018 (``calibration.cross_validate``, ``python bench/calibrate_confidence.py --fit
bench/calibration_data.jsonl``).  The shares hold for effects of the library's kind, at these strengths.
Verdicts that explain less than half of the mismatch and leave structure are scaled further
(:data:`PARTIAL_BELOW`)."""
HELD_OUT_CALIBRATION: dict = {
    "effect": ((0.523, 0.938),),
    "none": ((0.982, 0.75),),
}
"""Knots ``(confidence of CALIBRATION, share right held out)``: what each confidence of :data:`CALIBRATION` was
worth on concealed effects it was not fitted on (:func:`~phs.workflows.diagnose.calibration.held_out_knots`
of the stored diagnoses, grouped by concealed effect: each verdict's confidence from a calibration fitted
without its effect, then the share right of the verdicts at each such confidence, fitted as
:data:`CALIBRATION` is).  Where the held-out reliability is worse than the in-sample one, the diagnosis
reports this held-out figure.  On the stored set it is hardly worse (0.018 against 0.017) and the held-out
knots are the calibration's own levels: a verdict naming an effect reports 0.938 whatever its raw score
above 0.523 (below it, the raw score), a ``none`` 0.75 above 0.982 (below it, the raw score up to 0.75).
Held out its Brier score is 0.056, as :data:`CALIBRATION`'s; scaled by :data:`PARTIAL_BELOW`, 0.008."""
SCREENED_CAP = 0.9
"""Highest confidence of a verdict while a rival that explains part of the mismatch was only screened
(a loose fit: its gain after a fit to convergence is not known).  Not chosen on a measurement; it binds
below the level of :data:`HELD_OUT_CALIBRATION` for a verdict naming an effect (0.938)."""
FRICTION_LIKE = 0.05
"""A hysteresis loop whose saturated deflection ``F_h / (k_h (1 + eta))`` is below this share of the
displacement's standard deviation is friction with a pre-sliding regime, not a loop of the material:
when smooth Coulomb friction at the same place is accepted too, it is the simpler explanation.
Not chosen on a measurement."""


def calibrated(score: float, kind: str = "effect") -> float:
    """The confidence of a verdict of raw ``score`` (``kind``: ``"effect"`` or ``"none"``): the share of
    right verdicts at that score on the concealed cases (:data:`CALIBRATION`: each knot starts a level
    that holds up to the next; below the first knot, the raw score if lower than the first level), read
    through what that share was worth on concealed effects it was not fitted on (:data:`HELD_OUT_CALIBRATION`;
    :func:`~phs.workflows.diagnose.calibration.reported`).

    Examples
    --------
    >>> calibrated(0.7), calibrated(0.99), calibrated(0.3), calibrated(0.99, "none"), calibrated(0.9, "none")
    (0.938, 0.938, 0.3, 0.75, 0.75)
    """
    return reported(CALIBRATION.get(kind, ()), HELD_OUT_CALIBRATION.get(kind, ()), score)


PARTIAL_BELOW = 0.5
"""A verdict naming an effect that explains less than this share of what the nominal model misses above
the noise floor (``verdict.explained_share``), and leaves a residual still above the noise or coloured
(``verdict.residual_above_noise``), names a part of the missing physics at best: its confidence is
multiplied by ``share / PARTIAL_BELOW`` (:func:`partial`).  The calibration (:data:`CALIBRATION`) holds
effects of the library's kind, which the verdict explains whole or down to the noise; a verdict that
explains a small share and leaves structure is most often a library effect imitating a little of physics
the library lacks.  A weak effect near the noise can explain a small share of a mismatch that is itself
mostly noise but leaves no structure: its confidence stands.  Chosen on an earlier collection of the
stored calibration diagnoses, before the held-out cases were set apart (so the held-out figure below is
not independent of the choice).  On the stored diagnoses as collected again (the code of
:data:`CALIBRATION`) that are not held out the rule scales three verdicts: two weak slew-rate limits named
``quadratic_drag`` at a share of 2 % (wrong: 0.938 → 0.032) and a weak leakage named right at 41 % (0.938 →
0.768); the Brier score of the reported confidence falls from 0.049 to 0.006.  Held out (the held-out
cases' confidences from a calibration fitted on the others only) it scales two verdicts, both wrong, and
the Brier score falls from 0.051 to 0.008 (``tests/workflows/test_confidence_calibration.py``); at 0.25 it
would score 0.008 there (0.005 on the others), at 1 0.020 (0.023)."""


def partial(verdict: dict) -> dict:
    """``verdict`` with its confidence scaled down when the named effect explains less than
    :data:`PARTIAL_BELOW` of the mismatch above the noise floor and leaves a residual above the noise,
    and the explanation saying so; ``none`` verdicts and the others are returned as they are.

    Examples
    --------
    >>> v = {"effect": "cubic_stiffness", "confidence": 0.9, "explanation": "Missing physics: ...", "explained_share": 0.05,
    ...      "residual_above_noise": True}
    >>> partial(v)["confidence"]
    0.09
    >>> partial({**v, "explained_share": 0.8})["confidence"], partial({**v, "residual_above_noise": False})["confidence"]
    (0.9, 0.9)
    """
    share = float(verdict.get("explained_share", 1.0))
    if verdict.get("effect", "none") == "none" or share >= PARTIAL_BELOW or not verdict.get("residual_above_noise", True):
        return verdict
    factor = max(share, 0.0) / PARTIAL_BELOW
    out = dict(verdict)
    out["confidence"] = round(float(verdict["confidence"]) * factor, 3)
    out["explanation"] = (verdict["explanation"] + f" It explains only {100 * share:.0f} % of what the nominal model misses above "
                          f"the noise floor: most of the missing physics is not identified (confidence scaled by {factor:.2f}).")
    return out


WORSE_Z = 2.0
"""A hypothesis lowers a channel's validation fit beyond what the noise allows when the channel's validation
residual sum of squares rises by more than this many standard deviations of the part the noise alone moves,
and by more than this many standard deviations of the sum itself across draws of the noise.  With ``δ`` the
change of the channel's simulated course, ``σ`` its noise level
(:func:`~phs.workflows.diagnose.mismatch.noise_level`) and ``n`` its validation samples,
``RSS_after − RSS_before = |δ|² − 2 e·δ`` where the noise's share of ``e·δ`` has standard deviation ``σ|δ|``: a
rise above ``WORSE_Z · 2σ|δ|`` is the model's own (significant).  The noise alone spreads the sum by at least
``σ² √(2n)``: a rise below ``WORSE_Z`` times that is one that another recording of the same program would show
as often as not the other way (immaterial; on 4 000 validation samples 4.5 % of the noise's own sum).  A
refit of the nominal parameters beside a new element moves every channel a little; with many samples a
systematic shift of 0.004 fit points is significant but not material (a leakage behind Coulomb friction,
4 s: a rise of 0.06 of the sum's noise spread).  A convention (about 2.3 % of rises that the noise alone
makes are taken as the model's, fewer after the materiality floor), not a measurement."""


def worsened(reference, h, data) -> dict:
    """The channels whose validation fit ``h`` lowers beyond what their noise allows (significantly and
    materially, :data:`WORSE_Z`) against the model it extends (``reference``), as
    ``{channel: (fit % before, fit % after)}``; empty when either has no validation course.  A hypothesis
    that does is not accepted (:func:`_pick`): it trades one channel for another, which is not the missing
    physics of both.

    Examples
    --------
    >>> import numpy as np
    >>> from types import SimpleNamespace as NS
    >>> t = np.linspace(0, 1, 1001); rng = np.random.default_rng(0)
    >>> y = {"a": np.sin(6 * t) + 0.01 * rng.standard_normal(t.size), "b": np.cos(6 * t) + 0.01 * rng.standard_normal(t.size)}
    >>> data = NS(outputs=["a", "b"], validation=y, val_mask=np.ones(t.size, bool))
    >>> ref = NS(simulated={"validation": {"a": 0.9 * np.sin(6 * t), "b": np.cos(6 * t)}}, validation_fit_percent={"a": 90.0, "b": 99.0})
    >>> better_a = NS(simulated={"validation": {"a": np.sin(6 * t), "b": np.cos(6 * t) + 1e-4}}, validation_fit_percent={"a": 99.0, "b": 98.99})
    >>> worse_b = NS(simulated={"validation": {"a": np.sin(6 * t), "b": 0.95 * np.cos(6 * t)}}, validation_fit_percent={"a": 99.0, "b": 95.0})
    >>> worsened(ref, better_a, data), list(worsened(ref, worse_b, data))
    ({}, ['b'])
    """
    from phs.workflows.diagnose.mismatch import noise_level

    before, after = (getattr(reference, "simulated", {}) or {}).get("validation"), (getattr(h, "simulated", {}) or {}).get("validation")
    if not before or not after:
        return {}
    out = {}
    mask = data.val_mask
    for ch in data.outputs:
        if ch not in before or ch not in after:
            continue
        y = np.asarray(data.validation[ch], float)[mask]
        a, b = np.asarray(before[ch], float)[mask], np.asarray(after[ch], float)[mask]
        rise = float(np.sum((y - b) ** 2) - np.sum((y - a) ** 2))
        sigma = noise_level(y)  # significant (the noise's share along the change) and material (the sum's own spread)
        if rise > WORSE_Z * max(2.0 * sigma * float(np.linalg.norm(b - a)), sigma**2 * math.sqrt(2.0 * y.size)):
            out[ch] = (float(reference.validation_fit_percent[ch]), float(h.validation_fit_percent[ch]))
    return out


def _gain(nominal, h) -> float:
    """Relative decrease of the validation residual against the model it extends (scored on the same data)."""
    ref = h.reference_rss if h.reference_rss is not None else nominal.validation_rss
    if not math.isfinite(h.validation_rss) or ref <= 0:
        return -math.inf
    return float((ref - h.validation_rss) / ref)


def residual_change(gain: float) -> str:
    """A relative change of a validation residual as the reports print it, from its relative decrease
    ``gain`` (:func:`~phs.workflows.diagnose.ranking._gain`): a rise with "+" and "rose", a fall with "−"
    and "fell".

    Examples
    --------
    >>> residual_change(-0.02), residual_change(0.153), residual_change(0.0)
    ('+2.0 % (rose)', '−15.3 % (fell)', '0.0 % (unchanged)')
    """
    change = -100.0 * float(gain)
    if math.isnan(change):
        return "not finite"
    if round(change, 1) == 0:
        return "0.0 % (unchanged)"
    return f"+{change:.1f} % (rose)" if change > 0 else f"−{-change:.1f} % (fell)"


def _delta_bic(nominal, h) -> float:
    ref = h.reference_bic if h.reference_bic is not None else nominal.bic
    return float(h.bic - ref)


def _accepted(nominal, h) -> bool:
    return h.ok and h.stage == "full" and -_delta_bic(nominal, h) >= MIN_BIC_GAIN and _gain(nominal, h) >= MIN_VALIDATION_GAIN


def undetermined_effect(h) -> bool:
    """Whether the identifiability analysis of ``h``'s fit puts every new parameter of ``h`` along a
    direction the data do not determine beyond the nominal ones (``Scored.undetermined``: a rank test of
    their sensitivities with the nominal ones projected out).  Reported, not a reason to refuse the effect.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> aug = SimpleNamespace(free=["added_mass.mu"], element=None)
    >>> undetermined_effect(SimpleNamespace(augmentation=aug, undetermined=["added_mass.mu"]))
    True
    >>> undetermined_effect(SimpleNamespace(augmentation=aug, undetermined=[]))
    False
    """
    aug = h.augmentation
    free = list(getattr(aug, "free", ()) or ())
    return bool(free) and aug.element is None and set(free) <= set(getattr(h, "undetermined", ()) or ())


def simplest(hyps):
    """The simplest sufficient of ``hyps`` (fitted on the same recordings): of those within
    :data:`SUFFICIENT_MARGIN` of the best validation residual and, among them, of the best training residual
    (on thousands of samples a parameter more does not buy a lower training residual by overfitting: a
    simpler hypothesis that leaves much more of it misses structure the validation recording excites
    less), the one with fewest parameters, then least BIC.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> a = NS(validation_rss=1.00, rss=1.0, n_params=4, bic=-10.0)
    >>> b = NS(validation_rss=1.02, rss=1.0, n_params=3, bic=-9.0)   # as good, one parameter fewer
    >>> c = NS(validation_rss=0.50, rss=0.6, n_params=5, bic=-30.0)  # clearly better
    >>> simplest([a, b]) is b, simplest([a, b, c]) is c
    (True, True)
    """
    best = min(h.validation_rss for h in hyps)
    good = [h for h in hyps if h.validation_rss <= best * (1 + SUFFICIENT_MARGIN) + 1e-300]
    best_train = min(h.rss for h in good)
    good = [h for h in good if h.rss <= best_train * (1 + SUFFICIENT_MARGIN) + 1e-300]
    return min(good, key=lambda h: (h.n_params, h.bic))


def _pick(nominal, hyps, data=None):
    """Best accepted hypothesis, preferring fewer parameters among the equally good ones, and Coulomb
    friction over a hysteresis element that only describes friction (see :data:`FRICTION_LIKE`); with
    ``data``, none that lowers a channel's validation fit beyond its noise (:func:`worsened`, recorded in
    ``Scored.worsens``)."""
    acc = [h for h in hyps if _accepted(nominal, h)]
    if data is not None:  # none that lowers another channel's validation fit beyond its noise (worsened)
        for h in acc:
            h.worsens = worsened(nominal, h, data)
        acc = [h for h in acc if not h.worsens]
    if not acc:
        return None
    pick = simplest(acc)
    if data is not None and pick.augmentation.effect == "hysteresis":
        share = presliding_share(nominal, pick, data)
        friction = [h for h in acc if h.augmentation.effect == "coulomb_friction"
                    and h.augmentation.attached_to == pick.augmentation.attached_to]
        if share is not None and share < FRICTION_LIKE and friction:
            f = friction[0]
            f.same_physics.append(pick.label)
            f.notes.append(f"A hysteresis element at {pick.augmentation.attached_to} fits a little better (validation residual "
                           f"{residual_change(_gain(nominal, pick))} against {residual_change(_gain(nominal, f))}), but its loop closes "
                           f"within {100 * share:.2g} % of the motion's standard deviation: that is the pre-sliding regime of "
                           f"friction, not a hysteresis of the material, and smooth Coulomb friction describes it with fewer parameters.")
            pick = f
    if data is not None and pick.augmentation.effect == "coulomb_friction":
        # a hysteresis element at the same place whose loop closes in the pre-sliding regime is the same
        # physics described with more parameters: not a rival of the friction
        for h in hyps:
            if (h.ok and h.augmentation.effect == "hysteresis" and h.augmentation.attached_to == pick.augmentation.attached_to
                    and h.label not in pick.same_physics):
                share = presliding_share(nominal, h, data)
                if share is not None and share < FRICTION_LIKE:
                    pick.same_physics.append(h.label)
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
    >>> from phs.workflows.diagnose import diagnose
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
