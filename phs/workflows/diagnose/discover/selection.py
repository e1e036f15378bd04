"""Choosing a sparse passive correction: screen the dictionary, add terms forward by BIC, refit jointly.

Every decision is taken on the output-error fit of the model, never on differentiated data:

1. **screen**: one simulation of the current model with every remaining term at zero and one per term
   with its coefficient nudged give each term's output sensitivity; with the sensitivities of the
   nominal free parameters projected out, ``(jᵀr)² / jᵀj`` is the share of the training residual the
   term could remove on its own (to first order); a nonnegative term whose best coefficient is
   negative is dropped;
2. **forward selection**: the most promising terms (and the best heated dissipation, whose screen cannot
   see its heat) are each fitted by output error together with the terms chosen so far and the nominal
   free parameters (:func:`~phs.workflows.diagnose.hypotheses.fit_augmented`, loosely); the best by BIC
   joins when it lowers BIC by :data:`~phs.workflows.diagnose.ranking.MIN_BIC_GAIN`, lowers the
   validation residual by :data:`~phs.workflows.diagnose.ranking.MIN_VALIDATION_GAIN` and its model passes
   the structural checks (H bounded below on the declared box, R ⪰ 0);
3. **refit**: the chosen terms and the nominal free parameters to convergence, never ending worse than
   the model before it.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from phs.workflows.diagnose.discover.dictionary import Discovered, Term, dictionary

SCREEN_TOP = 3
"""Terms fitted by output error at each forward step (the best screened ones).  Not chosen on a measurement."""
MAX_TERMS = 3
"""Most terms a discovered correction holds.  Not chosen on a measurement."""
MAX_SAMPLES = 5000
"""Training samples the forward selection fits on (the first ones; the chosen terms are then refitted on
the whole recording).  Not chosen on a measurement."""
NEGLIGIBLE = 1e-6
"""A coefficient at most this large (in units of its state's scale) after the joint refit: the term is dropped.
A numerical floor, not a measurement."""
NUDGE = 0.02
"""Coefficient used to measure a term's output sensitivity (the terms are scaled so 1 is a typical size).
Not chosen on a measurement."""


@dataclass
class Discovery:
    """Outcome of :func:`select`: the fitted correction (``scored``, None when nothing was found), its
    ``terms``, the model it extends (``base``), the forward ``steps`` (label, ΔBIC, validation gain,
    accepted) and the screening table (``screened``: label, first-order share)."""

    base: object
    scored: object = None
    terms: tuple = ()
    steps: list = field(default_factory=list)
    screened: list = field(default_factory=list)
    seconds: float = 0.0
    reason: str = ""
    described: list = field(default_factory=list)
    similar: list = field(default_factory=list)
    share: float = 0.0
    text: str = ""

    @property
    def found(self) -> bool:
        return self.scored is not None and bool(self.terms)

    def to_dict(self) -> dict:
        """The documented JSON of a discovery: ``found``, ``terms`` (per term: ``term``, ``state``,
        ``nature``, ``parameter``, ``coefficient``, ``words``), ``parameters`` (the fitted coefficients
        and the refitted nominal values), ``description``, ``explained_share``, ``resembles`` (library
        effect and signature cosine, best first), ``validation_fit_percent``, ``steps``, ``screened``
        (the ten best screened terms), ``seconds``, ``reason`` (why nothing was found)."""
        out = {"found": self.found, "seconds": self.seconds, "steps": self.steps,
               "screened": [{"term": lab, "share": g} for lab, g in self.screened[:10]]}
        if not self.found:
            return {**out, "reason": self.reason}
        return {**out, "terms": self.described, "parameters": dict(self.scored.values), "description": self.text,
                "explained_share": self.share, "resembles": [{"effect": e, "cosine": c} for e, c in self.similar],
                "validation_fit_percent": self.scored.validation_fit_percent, "fit_percent": self.scored.fit_percent}

    @property
    def values(self) -> dict:
        """Fitted coefficients by parameter name."""
        return {n: float(self.scored.values[n]) for t in self.terms for n in t.parameters} if self.found else {}


def _trajectory(h, data):
    from phs.workflows.diagnose.hypotheses import train_result

    res = train_result(h, data)
    return res, {n: np.asarray(res[n], float) for n in h.system.state_names}


def _scales(h, data, res):
    from components.candidates import Scales

    X = np.asarray(res.x)
    names = h.system.input_names
    U = np.column_stack([np.asarray(res[n]) for n in names]) if names else np.zeros((len(X), 0))
    return Scales.of(h.system, res.t, X, U, {ch: data.recording[ch] for ch in data.outputs})


def screen(current, chosen, terms, data, base_system, n_jobs: int = 1) -> list[tuple[Term, float, float]]:
    """First-order share of the training residual each of ``terms`` could remove next to ``chosen``
    and the nominal free parameters, best first (terms that cannot help are left out).

    The output sensitivities to every term's coefficient (at zero) and to the nominal free parameters
    come from one integration with CVODES forward sensitivities
    (:class:`~phs.workflows.identify.sensitivities._Problem`); when that integration fails, from one
    simulation per term with its coefficient nudged by :data:`NUDGE` (a term whose simulation fails is
    then left out alone).

    Parameters
    ----------
    current : Scored
        The model the terms would extend (holding ``chosen`` at their fitted values).
    chosen, terms : sequence of Term
    data : Data
    base_system : PHSystem
        The fitted model without any discovered term.

    Returns
    -------
    list of (Term, float, float)
        Each term with its first-order share and its first-order best coefficient (a fit's start).
    """
    from phs.workflows.diagnose.pool import run_forked

    groups = _groups(terms)
    out = [row for rows in run_forked(_screened, [(current, chosen, g, data, base_system) for g in groups], n_jobs)
           for row in rows]
    out.sort(key=lambda tg: -tg[1])
    return out


def _screened(current, chosen, group, data, base_system) -> list[tuple]:
    """:func:`_screen_group`, or nothing when the group's model cannot be integrated at all (the other groups
    are screened still)."""
    from phs.errors import PHSError

    try:
        return _screen_group(current, chosen, group, data, base_system)
    except (PHSError, RuntimeError, ValueError, np.linalg.LinAlgError):
        return []


def _groups(terms) -> list[list]:
    """``terms`` split into the groups screened in one model each: the terms on the model's own states
    together, and each kind of term that appends states (:data:`~phs.workflows.diagnose.discover.families.KINDS`)
    on its own.  All of them in one model would integrate every appended state at once (on the
    electrostatic actuator's 47 terms, 53 s against 6 s for the groups: the cost grows with states
    times parameters).  The groups are screened side by side (:func:`screen`'s ``n_jobs``).

    The own-state terms stay one group: screened in chunks of twelve on the lab recording
    ``esa:cubic_stiffness@500Hz`` (``examples.lab_protocols``), each chunk took a fifth of the whole group's
    4.8 s, but CVODES then stepped over an input edge the 36 directions' error test had held it to, and
    chunks holding a heated dissipation failed to integrate (the terms in them went unscreened and the
    rival correction changed).

    Examples
    --------
    >>> ts = [Term("energy", "x", f"s{k}") for k in range(30)] + [Term("drift", "x", "k")]
    >>> [len(g) for g in _groups(ts)]
    [30, 1]
    """
    from phs.workflows.diagnose.discover.families import KINDS

    own = [t for t in terms if t.kind not in KINDS]
    return [g for g in [own, *([t for t in terms if t.kind == k] for k in KINDS)] if g]


def _screen_group(current, chosen, terms, data, base_system) -> list[tuple]:
    """:func:`screen` of one group of terms (:func:`_groups`), unsorted."""
    from phs.errors import PHSError

    start = _start(current, chosen)
    cand = Discovered(list(chosen) + list(terms), start)
    system = cand.apply(base_system)
    p0 = {p.name: p.value for p in cand.params()}
    x0 = _x0(current, system)
    values = {k: float(current.values.get(k, system.param(k).value)) for k in data.free}
    try:
        r, A, cols = _sensitivity_columns(system, data, x0, {**p0, **values}, list(data.free), [t.parameter for t in terms])
    except (PHSError, RuntimeError, ValueError, np.linalg.LinAlgError):
        r, A, cols = _nudged_columns(system, data, x0, p0, values, [t.parameter for t in terms])
    Qa = np.linalg.qr(A)[0] if A.shape[1] else A
    out = []
    rr = float(r @ r) or 1.0
    for t, j in zip(terms, cols, strict=True):
        if t.kind == "limit":  # kept whatever its first-order column says: it acts only where the flow reaches it
            ok = j is not None and np.all(np.isfinite(j))
            jp = (j - Qa @ (Qa.T @ j) if A.shape[1] else j) if ok else None
            jj = float(jp @ jp) if ok else 0.0
            out.append((t, float(jp @ r) ** 2 / jj / rr if jj > 0 else 0.0, float(jp @ r) / jj if jj > 0 else 0.0))
            continue
        if j is None or not np.all(np.isfinite(j)):
            continue
        jp = j - Qa @ (Qa.T @ j) if A.shape[1] else j
        jj = float(jp @ jp)
        if jj <= 1e-30 * len(jp):
            continue
        coef = float(jp @ r) / jj
        if not t.signed and coef <= 0:
            continue
        out.append((t, float(jp @ r) ** 2 / jj / rr, coef))
    return out


def _channel_scales(data) -> dict:
    return {ch: float(np.std(data.recording[ch])) or 1.0 for ch in data.outputs}


def _sensitivity_columns(system, data, x0, values: dict, free: list, params: list):
    """The training residual ``r`` (measured minus simulated, each channel over its standard deviation,
    channels one after the other), the output sensitivities to the ``free`` parameters (columns of ``A``,
    in any scale: only their span is used) and one column per parameter of ``params`` (per unit of it),
    all at ``values`` from one integration with forward sensitivities."""
    from phs.workflows.identify.sensitivities import _Problem

    names = list(free) + list(params)
    # linear fit coordinates p = scale * theta: a parameter at zero gets scale 1 and theta 0, so its column
    # is the derivative per unit of it at zero
    at = {k: float(values.get(k, system.param(k).value)) for k in names}
    scale = {k: (v if v != 0.0 else 1.0) for k, v in at.items()}
    pvec = system.param_vector({**values, **scale}, signs=False)
    weights = {ch: 1.0 / sd for ch, sd in _channel_scales(data).items()}
    prob = _Problem(system, data.recording, names, [], data.outputs, weights, np.asarray(x0, float), [], data.rtol, None,
                    compile=False, params=pvec)
    z = np.array([1.0 if at[k] != 0.0 else 0.0 for k in names])
    res, J = prob.jac(z)
    if not (np.all(np.isfinite(res)) and np.all(np.isfinite(J))):
        raise RuntimeError("non-finite sensitivities")
    nf = len(free)
    return -res, J[:, :nf], [J[:, nf + k] / scale[name] for k, name in enumerate(params)]


def _nudged_columns(system, data, x0, p0: dict, values: dict, params: list):
    """As :func:`_sensitivity_columns`, by one simulation per parameter (free ones moved by 1e-3 of
    their value, the terms' coefficients by :data:`NUDGE`); a column whose simulation fails is None."""
    from codegen import Simulator
    from phs.errors import PHSError
    from phs.workflows.diagnose.hypotheses import _simulate

    sim = Simulator(system, energy=False)
    rec = data.recording
    scale = _channel_scales(data)

    def outputs(over):
        r = _simulate(system, rec, x0, params={**p0, **over}, sim=sim)
        return np.concatenate([np.asarray(r[ch], float) / scale[ch] for ch in data.outputs])

    y0 = outputs({})
    r = np.concatenate([np.asarray(rec[ch], float) / scale[ch] for ch in data.outputs]) - y0
    cols = []
    for k, v in values.items():
        dv = 1e-3 * (abs(v) or 1.0)
        cols.append((outputs({k: v + dv}) - y0) / dv)
    A = np.column_stack(cols) if cols else np.zeros((len(y0), 0))
    terms = []
    for k in params:
        try:
            terms.append((outputs({k: p0[k] + NUDGE}) - y0) / NUDGE)
        except (PHSError, RuntimeError):
            terms.append(None)
    return r, A, terms


UNRANKED = ("memory", "limit")
"""Term kinds the first-order screen cannot rank: a heated dissipation's heat acts at second order in its
coefficient (its first-order share is that of a constant dissipation), and a limit acts only where the flow
reaches it.  The best of each kind is fitted at every forward step."""


def _fitted(ranked, top: int) -> list:
    """The screened terms fitted at a forward step: the ``top`` best, and the best of each kind of
    :data:`UNRANKED` when none of that kind is among them."""
    out = list(ranked[:top])
    for kind in UNRANKED:
        rest = [r for r in ranked[top:] if r[0].kind == kind]
        if rest and not any(r[0].kind == kind for r in out):
            out.append(rest[0])
    return out


def _tuned(row, current, chosen, data, base_system) -> tuple:
    """A screened ``(term, share, coefficient)`` row; a mode's moved to the frequency its screen prefers
    (:func:`~phs.workflows.diagnose.discover.families.refine_mode`)."""
    from phs.workflows.diagnose.discover.families import refine_mode

    t = row[0]
    if t.kind != "mode":
        return row
    rows = {}

    def share(cand):
        found = screen(current, chosen, [cand], data, base_system)
        rows[cand] = found[0] if found else (cand, 0.0, 0.0)
        return rows[cand][1]

    best, g = refine_mode(t, share)
    return rows[best] if best in rows and g > row[1] else row


def _start(current, chosen) -> dict:
    """The fitted values in ``current`` of every parameter of the ``chosen`` terms."""
    return {n: float(current.values[n]) for t in chosen for n in t.parameters if n in current.values}


def _x0(current, system) -> list:
    """``current``'s initial states, the heat states ``system`` appends after them starting at zero."""
    x0 = [float(v) for v in current.x0]
    return x0 + [0.0] * (len(system.states) - len(x0))


def _window(data, base):
    """``data`` with its training recording cut to its first :data:`MAX_SAMPLES` samples and a separate
    validation recording to its leading part (:func:`~phs.workflows.diagnose.screening.validation_samples`)
    for the forward selection's fits; ``data`` itself when short enough or when its training recording is
    part of the validation one.  An input element of ``base`` is already in ``data``
    (:func:`~phs.workflows.diagnose.hypotheses.through_element`: applied to the whole recording, then cut)."""
    if data.train_mask is not None:
        return data
    from phs.workflows.diagnose.screening import validation_samples

    n = len(data.recording)
    return data.head(MAX_SAMPLES, validation_samples(base, data, None, MAX_SAMPLES / n) if n > MAX_SAMPLES else None)


def _rescore(h, data):
    """``h`` (its fitted system and values) scored on ``data``."""
    from phs.workflows.diagnose.hypotheses import score

    out = score(h.label, h.system, h.values, h.x0, h.n_params, data, augmentation=h.augmentation)
    out.stage = h.stage
    return out


def _refit(current, chosen, base, data, progress, joint=True):
    """``chosen`` refitted to convergence with the nominal free parameters, from ``current``'s values;
    ``current`` itself when the refit does not end better or fails the structural checks."""
    from phs.workflows.diagnose.screening import _run_all

    start = _start(current, chosen)
    aug = Discovered(chosen, start).augment(base.system, chosen[0].state, None)
    full = _run_all(current, [aug], data, 1, progress, "discover refit", joint=joint)[0]
    return full if full.ok and not full.no_improvement and full.rss <= current.rss and _passes(full) else current


def _out_of_reach(start: float, before: float, after: float, steps_left: int, need: float) -> bool:
    """Whether a forward selection whose last step lowered the validation residual from ``before`` to
    ``after`` (``start`` before the first step) cannot remove ``need`` of ``start`` in ``steps_left`` more
    steps, each removing at most what the last one did (a forward selection takes the largest gain first).

    Examples
    --------
    >>> _out_of_reach(1.0, 1.0, 0.9, 2, 0.5)   # 10 % so far, at most 30 % in all
    True
    >>> _out_of_reach(1.0, 1.0, 0.7, 2, 0.5)   # 30 % so far, up to 90 %
    False
    """
    if not (start > 0 and after <= before):
        return False
    return (start - after) + steps_left * (before - after) < need * start


def _passes(h) -> bool:
    try:
        return bool(h.system.check().ok)
    except Exception:  # a check that cannot run does not pass
        return False


def select(base, data, *, n_jobs: int = 1, progress: bool = False, max_terms: int = MAX_TERMS, top: int = SCREEN_TOP,
           need: float | None = None) -> Discovery:
    """A sparse passive correction of the fitted model ``base`` (a :class:`~phs.workflows.diagnose.hypotheses.Scored`).

    Parameters
    ----------
    base : Scored
        The fitted model to correct (the nominal model or the one with the accepted library effects).
    data : Data
        The diagnosis' data (its ``free`` parameters are refitted with the correction).
    n_jobs : int
        Processes fitting the terms of a forward step in parallel.
    progress : bool
        One line per step on stderr.
    max_terms, top : int
        Most terms chosen; terms fitted by output error at each step.
    need : float, optional
        The share of ``base``'s validation residual a correction must remove to matter (a rival of an
        accepted library effect, :data:`~phs.workflows.diagnose.run.RIVAL_MARGIN`): the forward selection
        stops, with nothing found, as soon as the terms left could not reach it even if each added as
        much as the last one did (:func:`_out_of_reach`).

    Returns
    -------
    Discovery
    """
    from phs.workflows.diagnose.hypotheses import through_element
    from phs.workflows.diagnose.ranking import MIN_BIC_GAIN, MIN_VALIDATION_GAIN, worsened
    from phs.workflows.diagnose.screening import _run_all

    wall = time.perf_counter()
    # an input element accepted last is applied by ``base``'s own scores only: the correction's models
    # (``base.system`` plus terms) read its signals from the data
    data = through_element(data, base)
    res, traj = _trajectory(base, data)
    terms = dictionary(base.system, _scales(base, data, res), traj, outputs=data.outputs)
    out = Discovery(base)
    full_data, data = data, _window(data, base)
    current, chosen = (base if data is full_data else _rescore(base, data)), []
    start_rss = current.validation_rss
    for step in range(max_terms):
        ranked = screen(current, chosen, [t for t in terms if t not in chosen], data, base.system, n_jobs)
        if step == 0:
            out.screened = [(t.label, g) for t, g, _ in ranked]
        if not ranked:
            break
        start = _start(current, chosen)
        # each fit starts from the chosen terms' values and the new term's first-order coefficient (a
        # coefficient starting at exactly zero gives the solver no scale to move it by)
        fitted = [_tuned(row, current, chosen, data, base.system) for row in _fitted(ranked, top)]
        terms += [t for t, _, _ in fitted if t not in terms]
        augs = [Discovered(chosen + [t], {**start, t.parameter: t.fit_start(c)}).augment(
            base.system, (chosen or [t])[0].state, None) for t, _, c in fitted]
        hyps = _run_all(current, augs, data, n_jobs, progress, f"discover step {step + 1}", joint=False)
        ok = sorted([h for h in hyps if h.ok and not h.no_improvement], key=lambda h: h.bic)
        taken = None
        for h in ok:
            dbic = h.bic - current.bic
            gain = (current.validation_rss - h.validation_rss) / current.validation_rss if current.validation_rss > 0 else 0.0
            # a term that lowers another channel's validation fit beyond its noise trades channels (ranking.worsened)
            worse = worsened(current, h, data) if -dbic >= MIN_BIC_GAIN and gain >= MIN_VALIDATION_GAIN else {}
            accept = -dbic >= MIN_BIC_GAIN and gain >= MIN_VALIDATION_GAIN and _passes(h) and not worse
            out.steps.append({"term": h.augmentation.component.split(" + ")[-1], "delta_bic": float(dbic), "validation_gain": float(gain),
                              "accepted": bool(accept), **({"worsens": {ch: list(v) for ch, v in worse.items()}} if worse else {})})
            if accept:
                taken = h
                break
        if taken is None:
            break
        by_label = {t.label: t for t in terms}  # in the order they were chosen (the heat states' order too)
        chosen = [by_label[lab] for lab in taken.augmentation.component.split(" + ")]
        previous, current = current, taken
        if progress:
            print(f"  discover: chose {', '.join(t.label for t in chosen)}", file=sys.stderr, flush=True)
        if need is not None and _out_of_reach(start_rss, previous.validation_rss, current.validation_rss, max_terms - step - 1, need):
            chosen = []
            out.reason = (f"the terms left could not remove the {100 * need:.0f} % of the validation residual a rival of the "
                          "accepted effect needs")
            break
    if chosen:  # the chosen terms refitted on the whole training recording
        short = data is not full_data
        data = full_data
        final = _refit(_rescore(current, data) if short else current, chosen, base, data, progress, joint=not short)
        kept = [t for t in chosen if abs(final.values[t.parameter]) > NEGLIGIBLE]
        if kept and len(kept) < len(chosen):  # a term the joint refit drove to zero is dropped, and the rest refitted
            pruned = _refit(final, kept, base, data, progress, joint=not short)
            if pruned.bic <= final.bic + MIN_BIC_GAIN:
                final, chosen = pruned, kept
        gain = (base.validation_rss - final.validation_rss) / base.validation_rss if base.validation_rss > 0 else 0.0
        if short and not (base.bic - final.bic >= MIN_BIC_GAIN and gain >= MIN_VALIDATION_GAIN):
            chosen = []
            out.reason = "the terms chosen on a window of the training recording did not hold on the whole of it"
        elif worse := worsened(base, final, data):
            chosen = []
            out.reason = ("the correction lowers " + ", ".join(f"{ch}'s validation fit {a:.2f} → {b:.2f} %" for ch, (a, b) in worse.items())
                          + " beyond what the noise allows")
    if chosen:
        final.stage = "full"
        # the input elements the model's inputs go through stay part of it (their parameters held)
        final.element_values = {k: v for values in data.carried.values() for k, v in values.items()}
        final.reference_rss, final.reference_bic = base.validation_rss, base.bic
        final.label = f"discovered@{chosen[0].state}"
        out.scored, out.terms = final, tuple(chosen)
    elif not out.reason:
        out.reason = "no dictionary term lowered BIC and the validation residual enough" if out.steps or out.screened else \
            "no dictionary term could change the outputs"
    out.seconds = time.perf_counter() - wall
    return out
