"""Fitting the hypotheses of one round: in parallel processes, screened by a loose fit and the most promising
refitted to convergence, each measured against the model it extends."""

from __future__ import annotations

import sys
from dataclasses import replace

from phs.workflows.diagnose.ranking import FRICTION_LIKE, _gain, presliding_share


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
    """A screened hypothesis' augmentation, started from its screening values (inside the new parameters'
    bounds: a neutral point may lie outside them) for the joint refit."""
    aug = h.augmentation
    if aug.element is None:
        values = {k: v for k, v in h.values.items() if k in aug.system.param_names}
        values.update({k: min(max(v, aug.bounds[k][0]), aug.bounds[k][1]) for k, v in values.items() if k in aug.bounds})
        aug = replace(aug, system=aug.system.with_params(values), starts=())
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
