"""Fitting the hypotheses of one round: in parallel processes, screened by a loose fit and the most promising
refitted to convergence, each measured against the model it extends."""

from __future__ import annotations

import math
import sys
from dataclasses import replace

import numpy as np

from phs.workflows.diagnose.pool import run_forked
from phs.workflows.diagnose.ranking import FRICTION_LIKE, _gain, presliding_share

SCREEN_SHARE = 1 / 3
"""Share of a long training recording the screening fits run on (its leading part, see
:func:`screening_samples`); the most promising hypotheses are then refitted on the whole recording.
A screening fit only ranks the hypotheses, and its cost grows with the recording's length.
Not chosen on a measurement."""
SCREEN_MIN_SAMPLES = 3000
"""Fewest training samples a screening fit runs on (a recording shorter than twice this is screened whole).
Not chosen on a measurement."""


def _run_all(nominal, augs, data, n_jobs, progress, label, joint=True, ordered=False, ftols=None):
    """Fit ``augs`` (in parallel with ``n_jobs``; the costliest-looking first unless ``ordered``), each
    measured against ``nominal``; ``ftols``: each joint fit's tolerance (default ``REFIT_FTOL``)."""
    from phs.workflows.diagnose.hypotheses import fit_augmented

    light = replace(nominal, simulated={}, residuals={})

    def done(k, _i, h):  # every result is measured against the model it extends, scored on the same data
        h.reference_rss, h.reference_bic = nominal.validation_rss, nominal.bic
        _progress(progress, label, k, len(augs), h)

    jobs = list(zip(augs, ftols if ftols is not None else [None] * len(augs), strict=True))
    if n_jobs > 1 and not ordered:  # the costliest-looking first (new states, starts, parameters): the last to finish is short
        jobs = sorted(jobs, key=lambda j: _expected_cost(j[0]), reverse=True)
    return run_forked(fit_augmented, [(light, a, data, joint, None, f) for a, f in jobs], n_jobs, done)


def _polished(current, h, data, progress=False, label=""):
    """``h`` refitted on to ``REFIT_FTOL`` when its refit stopped looser (a hypothesis screened below the
    :data:`TIGHT_REFITS` best, refitted to :data:`~phs.workflows.diagnose.hypotheses.RIVAL_FTOL`, that was
    chosen), from where it stopped; ``h`` itself when it needs no polish or when the polish fails, and ``h`` marked tight when the
    polish ends no lower on the training data (it was converged already)."""
    from phs.workflows.diagnose.hypotheses import REFIT_FTOL

    if h.ftol is None or h.ftol <= REFIT_FTOL or h.stage != "full" or not h.ok:
        return h
    p = _run_all(current, [_for_refit(h)], data, 1, progress, label + " polish")[0]
    if not p.ok:
        return h
    if p.rss >= h.rss:
        h.ftol = REFIT_FTOL
        return h
    p.notes, p.same_physics = list(h.notes), list(h.same_physics)
    return p


def _expected_cost(aug) -> tuple:
    """A rough order of a hypothesis fit's cost among those of one round (they extend the same model):
    its states (a new state, often stiff, costs most; an input element's search counts one per parameter,
    each searched by about as many simulations as a new state's fit costs), then starts, then free
    parameters.  (EMPS, second round: the two-parameter input saturation's screening took 5.2 s, a creep's
    new state 3.1 s, a delay's one parameter 1.4 s.)"""
    if aug.element is not None:
        try:
            searched = len(aug.element.parameters(np.array([0.0, 1.0]), np.array([0.0, 1.0])))
        except Exception:  # an element that cannot size itself on a stand-in command counts as one
            searched = 1
        return (len(aug.system.states) + searched, len(aug.starts), len(aug.free))
    return (len(aug.system.states), len(aug.starts), len(aug.free))


def scales_of(h, data):
    """The scales a candidate is attached with (:meth:`components.candidates.Scales.of`) on the fitted model
    ``h``: its states, inputs and recorded outputs along its simulation of ``data``'s training recording."""
    import numpy as np

    from components.candidates import Scales
    from phs.workflows.diagnose.hypotheses import train_result

    res = train_result(h, data)
    X = np.asarray(res.x)
    names = h.system.input_names
    U = np.column_stack([np.asarray(res[n]) for n in names]) if names else np.zeros((len(X), 0))
    return Scales.of(h.system.with_params(h.values), res.t, X, U, {ch: data.recording[ch] for ch in data.outputs})


def _for_refit(h):
    """A screened hypothesis' augmentation, started from its screening values (inside the new parameters'
    bounds: a neutral point may lie outside them) for the joint refit; an input element's refit searches
    first around its screened parameters (its only start)."""
    aug = h.augmentation
    if aug.element is not None:
        return replace(aug, starts=(dict(h.element_values),) if h.element_values else ())
    values = {k: v for k, v in h.values.items() if k in aug.system.param_names}
    values.update({k: min(max(v, aug.bounds[k][0]), aug.bounds[k][1]) for k, v in values.items() if k in aug.bounds})
    return replace(aug, system=aug.system.with_params(values), starts=())


def _friction_loops(current, top, data) -> list:
    """The hysteresis hypotheses among ``top`` whose screened loop closes in the pre-sliding regime of
    friction (:func:`~phs.workflows.diagnose.ranking.presliding_share` below :data:`FRICTION_LIKE`) while
    Coulomb friction at the same momentum is refitted too: when the friction is accepted they are the
    same physics with more parameters (:func:`~phs.workflows.diagnose.ranking._pick`), so their refit
    (a stiff pre-sliding state: 67 s of the 20 s LuGre case's 101) waits for the choice
    (:func:`_refit_deferred`)."""
    out = []
    for h in top:
        if h.augmentation.effect != "hysteresis":
            continue
        if not any(f.augmentation.effect == "coulomb_friction" and f.augmentation.attached_to == h.augmentation.attached_to for f in top):
            continue
        share = presliding_share(current, h, data)
        if share is not None and share < FRICTION_LIKE:
            out.append(h)
    return out


def _refit_deferred(current, hyps, pick, data, progress, label) -> bool:
    """Refit the hypotheses whose refit waited for the choice (:func:`_friction_loops`) when the choice is
    not the Coulomb friction at their place; whether any was refitted."""
    waiting = [h for h in hyps if h.ok and h.deferred and h.stage != "full"]
    if pick is not None and pick.augmentation.effect == "coulomb_friction":
        waiting = [h for h in waiting if h.augmentation.attached_to != pick.augmentation.attached_to]
    if not waiting:
        return False
    _refit_in_place(current, hyps, waiting, data, progress, label + " deferred refit")
    return True


def _refit_in_place(current, hyps, screened, data, progress, label) -> None:
    """Refit the ``screened`` hypotheses jointly (side by side) and put each refit in its place in ``hyps``."""
    full = _run_all(current, [_for_refit(h) for h in screened], data, len(screened), progress, label, ordered=True)
    for h, f in zip(screened, full, strict=True):
        hyps[hyps.index(h)] = f


def _refit_pointed(current, hyps, pick, data, pointed, progress, label, named=()) -> bool:
    """When the located mismatch points at a family of effects (:mod:`~phs.workflows.diagnose.consistency`)
    and neither the choice ``pick`` (or no choice) nor an effect accepted in an earlier round (``named``) is
    of it, refit the family's hypotheses that were only screened jointly to convergence, so that the choice
    weighs them on a full fit (a screening that ended at the nominal model is refitted from its own starts);
    whether any was refitted."""
    from phs.workflows.diagnose.consistency import unmatched

    missing = unmatched(pointed, ([pick.augmentation.effect] if pick is not None else []) + list(named))
    family = {e for p in missing for e in p.effects}
    waiting = [h for h in hyps if h.ok and h.stage != "full" and h.augmentation.effect in family]
    if not waiting:
        return False
    augs = [h.augmentation if h.no_improvement else _for_refit(h) for h in waiting]
    full = _run_all(current, augs, data, len(augs), progress, label + " refit of the located family", ordered=True)
    for h, f in zip(waiting, full, strict=True):
        hyps[hyps.index(h)] = f
    return True


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
    _refit_in_place(current, hyps, rivals[:1], data, progress, label + " joint refit")
    return True


def leading_samples(n: int) -> int:
    """The leading window of a training recording of ``n`` samples that screening starts from:
    :data:`SCREEN_SHARE` of it, at least :data:`SCREEN_MIN_SAMPLES`; all ``n`` when a window would save
    less than half.

    Examples
    --------
    >>> leading_samples(30000), leading_samples(9000), leading_samples(5000)
    (10000, 3000, 5000)
    """
    m0 = max(SCREEN_MIN_SAMPLES, math.ceil(SCREEN_SHARE * n))
    return n if 2 * m0 > n else m0


def screening_samples(current, data, noise: dict | None = None) -> int:
    """Leading training samples the screening fits run on: :data:`SCREEN_SHARE` of the recording, at least
    :data:`SCREEN_MIN_SAMPLES` (the whole recording when that is more than half of it), extended until the
    window holds at least half its share in time of the mismatch above the noise (``Σ_ch w_ch² (r_ch² − σ_ch²)``
    of ``current``'s training residual), so that a mismatch that builds up late in the recording is screened
    where it shows.

    Examples
    --------
    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> from phs.workflows.recording import Recording
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> t = np.arange(30000) * 1e-3
    >>> rec = Recording.from_arrays(t, {"y": np.sin(t)})
    >>> data = Data(rec, rec, np.ones(len(t), bool), None, ["y"], [], {}, [], None)
    >>> even = SimpleNamespace(residuals={"y": 0.1 * np.sin(50 * t)})
    >>> late = SimpleNamespace(residuals={"y": np.where(t > 25, 0.1, 0.0)})
    >>> screening_samples(even, data), screening_samples(late, data)
    (10000, 27274)
    """
    n = len(data.recording)
    m0 = leading_samples(n)
    if m0 == n:
        return n
    return _mismatch_extent(getattr(current, "residuals", None) or {}, data.recording, data, noise, m0)


def validation_samples(current, data, noise: dict | None, share: float) -> int:
    """Leading samples of a separate validation recording that the discovery's forward selection scores on
    (:func:`~phs.workflows.diagnose.discover.selection._window`): ``share`` of it (the training window's),
    extended like the training window (:func:`screening_samples`) until it holds at least half its share in
    time of ``current``'s validation mismatch above the noise, so that the
    window does not leave out the part of the validation program where the model fails.  A split
    recording's validation part is kept whole (it lies at the end of the recording).

    Examples
    --------
    >>> import numpy as np
    >>> from types import SimpleNamespace as NS
    >>> from phs.workflows.recording import Recording
    >>> val = Recording.from_arrays(np.arange(9000) * 1e-3, {"y": np.zeros(9000)})
    >>> separate = NS(validation=val, train_mask=None, outputs=["y"], weights=None)
    >>> split = NS(validation=val, train_mask=np.ones(9000, bool), outputs=["y"], weights=None)
    >>> late = NS(simulated={"validation": {"y": np.where(np.arange(9000) > 8000, 0.1, 0.0)}})
    >>> [validation_samples(NS(simulated={}), d, None, 1 / 3) for d in (separate, split)], validation_samples(late, separate, None, 1 / 3)
    ([3000, 9000], 8472)
    """
    val = data.validation
    n = len(val)
    m0 = min(n, max(3, math.ceil(share * n)))
    if data.train_mask is not None or m0 >= n:
        return n
    sims = (getattr(current, "simulated", None) or {}).get("validation") or {}
    try:
        res = {ch: np.asarray(val[ch], float) - np.asarray(sims[ch], float) for ch in data.outputs}
    except (KeyError, ValueError):
        return m0
    return _mismatch_extent(res, val, data, noise, m0)


def _mismatch_extent(res: dict, rec, data, noise: dict | None, m0: int) -> int:
    """The fewest leading samples, at least ``m0``, of ``rec`` that hold at least half their share in time
    of the mismatch above the noise, ``Σ_ch w_ch² (r_ch² − σ_ch²)`` of the residuals ``res``; ``m0`` when
    the residuals are missing or nothing is above the noise."""
    n = len(rec)
    if any(ch not in res or len(res[ch]) != n for ch in data.outputs):
        return m0
    from phs.workflows.diagnose.hypotheses import weight_squared

    excess = np.zeros(n)
    for ch in data.outputs:
        sigma = (noise or {}).get(ch, 0.0)
        w2 = weight_squared(data.weights, ch, rec[ch])
        excess += w2 * (np.asarray(res[ch], float) ** 2 - sigma**2)
    total = float(np.sum(np.clip(excess, 0.0, None)))
    if total <= 0.0:
        return m0
    share = np.cumsum(np.clip(excess, 0.0, None)) / total  # share of the mismatch in the first k + 1 samples
    ok = np.nonzero(share[m0 - 1:] >= 0.5 * np.arange(m0, n + 1) / n)[0]
    return int(m0 + ok[0]) if ok.size else n


def refit_alone(current, data, joint: bool = True):
    """``current`` (a fitted model: the nominal one with accepted effects) refitted by itself, nothing added:
    its free parameters ``data.free`` (and estimated states) from its own values, with a screening fit's
    budget (``joint=False``: :data:`~phs.workflows.diagnose.hypotheses.SCREEN_ITER` evaluations at
    :data:`~phs.workflows.diagnose.hypotheses.SCREEN_RTOL`) or a joint refit's (to
    :data:`~phs.workflows.diagnose.hypotheses.REFIT_FTOL`), scored on ``data``; ``None`` when the fit fails.
    What a hypothesis of a later round gains by moving the parameters it shares with ``current`` alone:
    a fit that stopped where its integration no longer resolves the cost's decrease (a flat valley, as
    when the library's law only approximates the truth's) moves on along the valley in any refit, with or
    without a new element.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from systems.examples import rc_circuit
    >>> from phs.workflows.recording import Recording
    >>> from phs.workflows.diagnose.hypotheses import Data, score
    >>> t = np.linspace(0, 0.02, 401); u = np.where((t % 0.01) > 0.005, 1.0, 0.0)
    >>> rec = Recording.from_arrays(t, {"U": u, "v_C": simulate(rc_circuit(R=2e3), t, u={"U": u})["v_C"]})
    >>> data = Data(rec, rec, np.ones(401, bool), None, ["v_C"], ["R.R"], {}, [], None)
    >>> m = rc_circuit(R=1.5e3)
    >>> h = refit_alone(score("start", m, {"R.R": 1.5e3}, [0.0], 1, data), data)
    >>> round(h.values["R.R"]), h.rss < 1e-6
    (2000, True)
    """
    from phs.workflows.diagnose.hypotheses import REFIT_FTOL, SCREEN_ITER, _default_log, _fit_rtol, _fixed, score
    from phs.workflows.diagnose.retry import RECOVERABLE
    from phs.workflows.identify import identify

    free = [k for k in data.free if k in current.system.param_names]
    if not free and not data.estimate_x0:
        return None
    log_scale = [k for k in (data.log_scale or []) if k in free] or _default_log(current.system, free)
    try:
        fit = identify(current.system.with_params(current.values), data.recording, free, bounds=data.bounds or None,
                       x0=dict(zip(current.system.state_names, map(float, current.x0), strict=True)), outputs=data.outputs,
                       log_scale=log_scale or None, rtol=_fit_rtol(data, joint), max_iter=30 if joint else SCREEN_ITER,
                       ftol=REFIT_FTOL if joint else 1e-3, compile=None if joint else False, estimate_x0=data.estimate_x0,
                       weights=_fixed(data.weights))
        return score(current.label, current.system, fit.values, fit.x0, current.n_params, data,
                     augmentation=current.augmentation, element_values=current.element_values, train_residuals=fit.residuals)
    except RECOVERABLE:
        return None


def _screen_and_refit(current, augs, data, n_jobs, progress, label, refit_top, noise=None, worth=None):
    """Screen every hypothesis by a loose joint fit (few iterations, input elements by their search alone)
    on the leading part of the training recording (:func:`screening_samples`), scored on the whole
    validation, then refit the ``refit_top`` most promising to convergence and score them on all of both.
    On a window the screened hypotheses are measured against the model they extend refitted alone on the same
    window with the same budget (:func:`refit_alone`), not at its values fitted on the whole recording: a
    window that holds only part of the program moves the shared parameters of every screening fit the same
    way (on the lab protocols' Coulomb friction + input saturation, 1 kHz, the leading third holds rests and
    squares and no staircase, chirp or PRBS, and every screened hypothesis, the neutral ones too, fitted the
    validation 33-35 % worse than the nominal model: none had a gain, and the truths were not refitted).
    ``worth(h, alone)`` (a later round): whether a screened hypothesis may be refitted, given ``alone``,
    the model it extends refitted by itself with the same budget on the same samples (:func:`refit_alone`,
    ``None`` when that fails); none is refitted when none is worth it."""
    if refit_top <= 0 or len(augs) <= refit_top:
        return _run_all(current, augs, data, n_jobs, progress, label)
    from phs.workflows.diagnose.hypotheses import score

    m = screening_samples(current, data, noise)
    # scored on the whole validation recording: the window's fits are ranked on every part of the program (a
    # leading window of it ranked the lab charge retention below a series resistance once the current's
    # noise level was read right: the window's end moved off the program's part where the two differ)
    short = data.head(m)
    base = current
    if short is not data:  # the model the hypotheses extend, scored on the same window
        from phs.workflows.diagnose.retry import RECOVERABLE

        try:
            base = score(current.label, current.system, current.values, current.x0, current.n_params, short,
                         augmentation=current.augmentation, element_values=current.element_values)
        except RECOVERABLE:  # its simulation on the window fails where the whole one passed: screen on the whole
            short = data
    screened = _run_all(base, augs, short, n_jobs, progress, label + " screening", joint=False)
    alone = refit_alone(base, short, joint=False) if worth is not None or short is not data else None
    if alone is not None and short is not data:  # measured against the model they extend fitted the same way
        for h in screened:
            h.reference_rss, h.reference_bic = alone.validation_rss, alone.bic
    screened.sort(key=lambda h: (not h.ok, -_gain(current, h)))
    top, seen = [], set()
    for h in screened:  # the most promising distinct effects (one attachment each); beyond the best, only with a gain
        if worth is not None and not (h.ok and worth(h, alone)):
            continue
        if h.ok and h.augmentation.effect not in seen and len(top) < refit_top and (not top or _evidence(base, h)):
            top.append(h)
            seen.add(h.augmentation.effect)
    top = _with_best_fit(base, top, screened, alone, worth)
    for h in _friction_loops(current, top, data):  # refitted only if the friction is not chosen
        top.remove(h)
        h.deferred = ("its screened loop closes in the pre-sliding regime of friction; refitted only if Coulomb friction "
                      "at the same place is not chosen")
    # longest screening first: with fewer workers than refits the longest must not start last; beyond the
    # TIGHT_REFITS best screened, to RIVAL_FTOL (polished if chosen; an input element's alternating refit
    # always to REFIT_FTOL: polishing it would repeat its searches)
    from phs.workflows.diagnose.hypotheses import REFIT_FTOL, RIVAL_FTOL

    order = sorted(top, key=lambda h: -h.seconds)
    tight = top[:TIGHT_REFITS]
    ftols = [REFIT_FTOL if any(h is t for t in tight) or h.augmentation.element is not None else RIVAL_FTOL for h in order]
    # an input element's joint refit alternates on the screening's window before the whole recording
    refit_data = replace(data, window=len(short.recording)) if short is not data else data
    full = _run_all(current, [_for_refit(h) for h in order], refit_data, n_jobs, progress, label + " joint refit", ordered=True,
                    ftols=ftols)
    done = {(f.augmentation.effect, f.augmentation.attached_to) for f in full}
    rest = [h for h in screened if (h.augmentation.effect, h.augmentation.attached_to) not in done]
    for h in rest:
        h.stage = "screening"
    return full + rest


TIGHT_REFITS = 2
"""The best screened hypotheses whose joint refits run to ``REFIT_FTOL`` (the one reported); the others to
``RIVAL_FTOL`` (they only rank) and on to ``REFIT_FTOL`` only when chosen (:func:`_polished`, after the
other refits: a wait).  Two, not one: on the 20 s charge-retention case the window's screening ranks the
viscoelastic creep first and the refits choose the charge retention, whose polish then took 4 s after the
others; the third there, the stiff hysteresis, stops after 10 evaluations of 1.6 s instead of 14.
Chosen on that case (seed 1)."""

def _with_best_fit(base, top, screened, alone=None, worth=None):
    """The refitted few ``top`` (the screening's best validation gains) and the screening's best training
    fit: the screened hypothesis of least BIC on the window, when it lowered the validation residual (and
    in a later round is worth a refit), is refitted too when no hypothesis of its effect is (one refit more).

    The two rankings disagree where the validation gains are close: on the 20 s viscoelastic creep + added
    mass pair (seed 1), the added mass's screening had the least BIC of all (1582 below the next, an input
    saturation's) and the fourth validation residual (270.6, behind the saturation's 267.1, the creep's and
    an offset's 269.6); refitted without it, the saturation was accepted, a false effect, and neither truth
    was named.  Refitted too, the added mass is accepted and the creep after it."""
    fits = [h for h in screened if h.ok and _evidence(base, h) and (worth is None or worth(h, alone))]
    if not fits or not top:
        return top
    best = min(fits, key=lambda h: h.bic)
    if any(h.augmentation.effect == best.augmentation.effect for h in top):
        return top
    return top + [best]


def _evidence(base, h) -> bool:
    """Whether a screened hypothesis beyond the best is worth a refit: its screening lowered the validation
    residual.  A screening ΔBIC threshold beside it (refit only when the screening fit pays for its new
    parameters) was removed: on the 40 held-out concealed cases (seed 4) it got one verdict fewer right and a
    Brier score of 0.057 against 0.037 without it (``python bench/held_out_rules.py``)."""
    return _gain(base, h) > 0


def _progress(progress, label, k, n, h):
    if not progress:
        return
    state = f"failed ({h.error})" if h.error else "validation " + ", ".join(f"{c} {v:.1f} %" for c, v in h.validation_fit_percent.items())
    print(f"  {label} [{k}/{n}] {h.label}: {state} ({h.seconds:.1f} s)", file=sys.stderr, flush=True)
