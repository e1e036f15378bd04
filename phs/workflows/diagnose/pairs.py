"""The first of a pair on trial, chosen again once its second is known.

An effect that trades channels (it passes the acceptance rule but lowers another channel's validation fit)
is accepted only as the first of a pair whose second, of the next round, makes the pair whole
(``run._traded``, :func:`_whole`).  The first is the trading hypothesis of largest validation gain *alone*;
with the second beside it another trading hypothesis of the same round may make the better pair (an offset
of the position and a viscoelastic creep both take up the slow part of a motion whose drive also
saturates: alone the offset fits better, with the saturation the creep).  :func:`other_first` fits the
second's effect on each other trading first that was fitted in full, and keeps the pair the library's
choice prefers (:func:`~phs.workflows.diagnose.ranking.simplest`)."""

from __future__ import annotations

from dataclasses import replace

from phs.workflows.diagnose.hypotheses import through_element
from phs.workflows.diagnose.ranking import _accepted, _gain, simplest, worsened
from phs.workflows.diagnose.screening import _run_all, scales_of


def other_first(trial, pick, alone, trial_round, cands, data_r, progress=False, label=""):
    """The pair on trial with another first when it is the better pair: ``(first, pair, data)``, the other
    first, the second's effect fitted on it and the data the pair was fitted on; ``None`` when the pair of
    ``trial.first`` and ``pick`` (fitted on ``data_r``) stays.

    The other firsts are the hypotheses of ``trial_round`` fitted in full that pass the acceptance rule
    against the model before the pair (``trial.before``) but lower another channel's validation fit, as the
    trial's first does.  On each, the second's effect at the same place is fitted in full from the second's
    values; a pair counts when it is whole (:func:`_whole`) and its first earns its place beside the second
    fitted ``alone`` (:func:`_earns`; ``alone`` is ``None`` when it has no fit).  The choice among the pairs
    is the library's own (:func:`~phs.workflows.diagnose.ranking.simplest`)."""
    before, first = trial.before, trial.first
    others = [h for h in trial_round if h is not first and h.ok and h.stage == "full" and h.worsens
              and _accepted(before, h) and h.augmentation.effect != pick.augmentation.effect]
    cand = next((c for c in cands if c.effect == pick.augmentation.effect), None)
    if not others or cand is None:
        return None
    pairs, said = [], []
    others.sort(key=lambda h: -_gain(before, h))
    for h, pair, data_h in _on_firsts(others, first, pick, cand, trial.data, data_r, progress, label):
        whole = _whole(before, pair, trial.data)
        if whole and (alone is None or _earns(pair, alone)):
            pairs.append((h, pair, data_h))
        else:
            said.append(f"With {h.label} as its first instead, the pair "
                        + ("fit failed" if not pair.ok else "does not earn its place" if whole else "is not whole") + ".")
    best = simplest([pick] + [p for _, p, _ in pairs])
    chosen = next(((h, p, d) for h, p, d in pairs if p is best), None)
    if chosen is not None:
        said.insert(0, f"{chosen[0].label} was chosen as the first of the pair over {first.label}, which fits better alone: "
                       f"with {pick.augmentation.effect} the pair with {chosen[0].label} is the better (validation residual "
                       f"{best.validation_rss:.4g} against {pick.validation_rss:.4g}, BIC {best.bic - pick.bic:+.1f}).")
    said += [f"With {h.label} as its first instead the pair fits no better (validation residual {p.validation_rss:.4g}, "
             f"BIC {p.bic - best.bic:+.1f} against this pair's)." for h, p, _ in pairs if p is not best]
    best.notes.extend(said)
    return chosen


def _on_firsts(others, first, second, cand, data_before, data_r, progress=False, label=""):
    """``(h, pair, data)`` for each hypothesis ``h`` of ``others`` (fitted in full, in the round of ``first``):
    the effect of ``second`` (a hypothesis of the next round, fitted on ``first``; ``cand`` its candidate)
    attached at the same place on ``h`` and fitted in full from the second's values, and the data the pair
    was fitted on (``data_before``, the data before ``first``, with the free parameters of ``data_r`` but
    ``first``'s own replaced by ``h``'s, through ``h``'s input element).  A second that cannot attach on
    ``h`` gives no pair; largest gain over ``first``'s round first."""
    out = []
    for h in others:
        free = [k for k in data_r.free if k not in first.augmentation.free] + list(h.augmentation.free)
        data_h = through_element(replace(data_before, free=list(dict.fromkeys(free))), h)  # (which keeps ``free``)
        try:
            aug = cand.augment(h.system.with_params(h.values), second.augmentation.attached_to, scales_of(h, data_h))
        except Exception:  # noqa: BLE001 - a second that cannot attach on this first: no such pair
            continue
        aug = aug if aug.summary else replace(aug, summary=cand.summary)
        if aug.element is not None:  # searched around the second's values first
            aug = replace(aug, starts=(dict(second.element_values),) if second.element_values else ())
        else:
            values = {k: second.values[k] for k in aug.free if k in second.values}
            values = {k: min(max(v, aug.bounds[k][0]), aug.bounds[k][1]) if k in aug.bounds else v for k, v in values.items()}
            aug = replace(aug, system=aug.system.with_params(values), starts=())
        out.append((h, _run_all(h, [aug], data_h, 1, progress, f"{label} {h.label} as the first")[0], data_h))
    return out


def first_for_small(first, second, alone, before, first_round, cands, data_before, data_r, adds, progress=False, label=""):
    """The first effect chosen again when the best second fitted on it adds too small a share: ``(first', pair,
    data)``, another first of ``first``'s round, the second's effect fitted on it and the data the pair was
    fitted on; ``None`` when ``first`` stays alone.

    ``second`` is the hypothesis of the next round the library would choose on ``first`` but for the share a
    later effect must add (``adds(first, second)`` is false).  ``first`` may have taken up part of the second's
    effect with part of its own (a hysteresis loop fitted where a creep and a cubic stiffness act): on each
    other hypothesis of ``first_round`` fitted in full that passes the acceptance rule against ``before`` (the
    model before ``first``) and lowers no channel, the second's effect at the same place is fitted in full.
    A pair counts when the second adds its share beyond its first (``adds``), the pair passes the acceptance
    rule against ``first`` alone (it is better than the best single effect) lowering none of its channels,
    and its first earns its place beside the second fitted alone (:func:`_earns`; ``alone()`` gives that fit,
    ``None`` when there is none, and is called only once a pair passed the other tests).
    The choice among the pairs that count is the library's own
    (:func:`~phs.workflows.diagnose.ranking.simplest`)."""
    others = [h for h in first_round if h is not first and h.ok and h.stage == "full" and not h.worsens
              and _accepted(before, h) and h.augmentation.effect != second.augmentation.effect]
    cand = next((c for c in cands if c.effect == second.augmentation.effect), None)
    if not others or cand is None or first.validation_rss <= 0:
        return None
    pairs, said, second_alone = [], [], []
    others.sort(key=lambda h: -_gain(before, h))
    for h, pair, data_h in _on_firsts(others, first, second, cand, data_before, data_r, progress, label):
        if not pair.ok:
            said.append(f"With {h.label} as its first instead, the pair's fit failed.")
            continue
        share = adds(h, pair)
        better = pair.stage == "full" and _passes(first, pair) and not worsened(first, pair, data_h)
        if share and better and not second_alone:
            second_alone.append(alone())
        if share and better and (second_alone[0] is None or _earns(pair, second_alone[0])):
            pairs.append((h, pair, data_h))
        else:
            said.append(f"With {h.label} as its first instead, the pair "
                        + ("adds too small a share beyond its first" if not share
                           else "is no better than " + first.label + " alone" if not better else "does not earn its place")
                        + f" (validation residual {pair.validation_rss:.4g} against {first.validation_rss:.4g}).")
    if not pairs:
        second.notes.extend(said)
        return None
    best = simplest([p for _, p, _ in pairs])
    chosen = next((h, p, d) for h, p, d in pairs if p is best)
    said.insert(0, f"{chosen[0].label} was chosen as the first of the pair over {first.label}, which fits better alone: "
                   f"{second.augmentation.effect} adds {second.later_share:.3f} of the nominal model's mismatch beyond "
                   f"{first.label}, {best.later_share:.3f} beyond {chosen[0].label} (validation residual "
                   f"{best.validation_rss:.4g} against {first.validation_rss:.4g} for {first.label} alone).")
    said += [f"With {h.label} as its first instead the pair fits no better (validation residual {p.validation_rss:.4g}, "
             f"BIC {p.bic - best.bic:+.1f} against this pair's)." for h, p, _ in pairs if p is not best]
    best.notes.extend(said)
    return chosen


def _earns(with_library, alone) -> bool:
    """Whether accepted library effects earn their place next to a discovered correction: the model with
    them (``with_library``) passes the library's acceptance rule against the correction alone (BIC
    ``MIN_BIC_GAIN`` lower, validation residual ``MIN_VALIDATION_GAIN`` lower)."""
    return alone.validation_rss <= 0 or _passes(alone, with_library)


def _whole(before, h, data) -> bool:
    """Whether ``h``, the second of a pair whose first was on trial, passes with it the acceptance rule
    against ``before`` (the model without either: BIC :data:`~phs.workflows.diagnose.ranking.MIN_BIC_GAIN`
    lower, validation residual :data:`~phs.workflows.diagnose.ranking.MIN_VALIDATION_GAIN` lower) and lowers
    none of its channels' validation fits (:func:`~phs.workflows.diagnose.ranking.worsened`)."""
    if not (h.ok and h.stage == "full") or before.validation_rss <= 0:
        return False
    return _passes(before, h) and not worsened(before, h, data)


def _passes(ref, h) -> bool:
    """Whether ``h`` passes the acceptance rule against ``ref``, whatever model ``h`` was fitted from: BIC
    :data:`~phs.workflows.diagnose.ranking.MIN_BIC_GAIN` lower and validation residual
    :data:`~phs.workflows.diagnose.ranking.MIN_VALIDATION_GAIN` lower than ``ref``'s (``ref``'s validation
    residual positive).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> ref = NS(validation_rss=1.0, bic=0.0)
    >>> _passes(ref, NS(validation_rss=0.5, bic=-100.0)), _passes(ref, NS(validation_rss=0.999, bic=-100.0))
    (True, False)
    """
    from phs.workflows.diagnose.ranking import MIN_BIC_GAIN, MIN_VALIDATION_GAIN

    gain = (ref.validation_rss - h.validation_rss) / ref.validation_rss
    return ref.bic - h.bic >= MIN_BIC_GAIN and gain >= MIN_VALIDATION_GAIN
