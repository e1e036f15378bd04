"""Discovery: a passive port-Hamiltonian correction found when no library candidate explains the residual.

When the library (:data:`components.candidates.LIBRARY`) leaves a structured residual,
:func:`discover` fits a correction with port-Hamiltonian structure built in, sparse over a dictionary
built from the model itself (:mod:`~phs.workflows.diagnose.discover.dictionary`: added energies on
single states, added dissipation ``R ⪰ 0`` on an effort), chosen by output error
(:mod:`~phs.workflows.diagnose.discover.selection`), names it
(:mod:`~phs.workflows.diagnose.discover.naming`) and writes it as a candidate class the user keeps
(:mod:`~phs.workflows.diagnose.discover.emission`).  ``docs/workflows/discover.md`` states the method,
the dictionaries and the passivity argument.
"""

from __future__ import annotations

from phs.workflows.diagnose.discover.dictionary import Discovered, Term, dictionary
from phs.workflows.diagnose.discover.emission import source, write_source
from phs.workflows.diagnose.discover.naming import RESEMBLES, describe, explained_share, resemblance, sentence
from phs.workflows.diagnose.discover.selection import Discovery, select


def discover(current, nominal, data, noise: dict, hypotheses=(), *, n_jobs: int = 1, progress: bool = False,
             need: float | None = None) -> Discovery:
    """Select, fit and name a passive correction of the fitted model ``current``.

    Parameters
    ----------
    current : Scored
        The model to correct (the nominal fit, or the model with the accepted library effects).
    nominal : Scored
        The nominal fit (the library hypotheses' reference).
    data : Data
        The diagnosis' data.
    noise : dict
        Noise std per channel (:func:`~phs.workflows.diagnose.mismatch.noise_level`).
    hypotheses : sequence of Scored
        The fitted library hypotheses the correction is compared with.
    n_jobs, progress
        As for :func:`~phs.workflows.diagnose.diagnose`.
    need : float, optional
        The share of ``current``'s validation residual the correction must remove to matter
        (:func:`~phs.workflows.diagnose.discover.selection.select`).

    Returns
    -------
    Discovery
        With ``described`` (per term), ``similar`` (library effects by signature cosine), ``share``
        (:func:`explained_share` against ``current``) and ``text`` (one paragraph) when a correction
        was found.
    """
    d = select(current, data, n_jobs=n_jobs, progress=progress, need=need)
    if d.found:
        d.described = describe(d.terms, d.values, current.system)
        d.similar = resemblance(d.scored, current, nominal, hypotheses, data)
        d.share = explained_share(current, d.scored, data, noise)
        d.text = sentence(d.described, d.similar, d.share)
    return d


def without_library(found, nominal, data, noise: dict, hypotheses=(), *, progress: bool = False) -> Discovery | None:
    """The correction ``found`` (discovered after accepted library effects) refitted on the nominal model
    alone, named, as a :class:`Discovery`; None when its terms need a state only the library effects added
    or the refit does not improve on the nominal model.

    A library effect accepted first may only stand in for part of what the correction models (a sensor
    offset for the mean of a leakage that grows with heat): with the correction found, the effect must
    earn its place again by the library's own acceptance rule, against the correction alone
    (:func:`phs.workflows.diagnose.run.diagnose` drops it otherwise)."""
    from phs.workflows.diagnose.discover.selection import _passes
    from phs.workflows.diagnose.screening import _run_all

    if found is None or not found.found:
        return None
    terms = list(found.terms)
    start = {n: float(found.scored.values[n]) for t in terms for n in t.parameters if n in found.scored.values}
    try:  # a term on a state only the library effects added does not attach to the nominal model
        aug = Discovered(terms, start).augment(nominal.system, terms[0].state, None)
    except Exception:  # noqa: BLE001 - any failure to attach means: no correction alone
        return None
    alone = _run_all(nominal, [aug], data, 1, progress, "discover without the library")[0]
    if not alone.ok or alone.no_improvement or not _passes(alone):
        return None
    alone.stage = "full"
    alone.reference_rss, alone.reference_bic = nominal.validation_rss, nominal.bic
    alone.label = f"discovered@{found.terms[0].state}"
    d = Discovery(nominal, alone, tuple(found.terms), list(found.steps), list(found.screened), found.seconds)
    d.described = describe(d.terms, d.values, nominal.system)
    d.similar = resemblance(alone, nominal, nominal, hypotheses, data)
    d.share = explained_share(nominal, alone, data, noise)
    d.text = sentence(d.described, d.similar, d.share)
    return d


def amend_verdict(verdict: dict, discovery, scale: float = 1.0, library_share: float | None = None, lead_below: float = 0.5) -> dict:
    """The verdict with the discovered correction: effect ``discovered`` when no library effect was
    accepted, ``discovered`` appended to ``effects``, its paragraph appended to the explanation and
    ``verdict["discovered"]`` (see :meth:`Discovery.to_dict`).  A verdict led by the correction has
    confidence ``0.5 + 0.5 × explained share`` (times ``scale``, the failed hypotheses' factor).

    When library effects were accepted but explain less than ``lead_below`` of the mismatch
    (``library_share``) and the correction explains at least ``lead_below`` of what they leave, the
    correction leads: effect ``discovered``, then the library effects (they stay in the model, refitted
    with it).

    Examples
    --------
    >>> v = {"effect": "none", "effects": [], "explanation": "", "confidence": 0.9, "failed": []}
    >>> amend_verdict(v, None) is v   # nothing discovered: the verdict stands
    True
    """
    if discovery is None or not discovery.found:
        return verdict
    out = dict(verdict)
    leads = verdict["effect"] != "none" and library_share is not None and library_share < lead_below <= discovery.share
    if verdict["effect"] == "none":
        out["effect"] = "discovered"
        from phs.workflows.diagnose.report import NONE_FITTED, NONE_FOUND, NONE_TRADED

        library = (verdict["explanation"]
                   .replace(NONE_FOUND, "No library candidate explains it: the best,")
                   .replace(NONE_TRADED, "No library candidate is accepted: the best,")
                   .replace(NONE_FITTED, "No library candidate could be fitted."))
        out["explanation"] = discovery.text + " " + library
        out["confidence"] = round((0.5 + 0.5 * discovery.share) * scale, 3)
    elif leads:
        out["effect"] = "discovered"
        out["explanation"] = (discovery.text + f" It leads the verdict: the library's effects explain {100 * library_share:.0f} % of "
                              "the mismatch and stay in the model, refitted with it. " + verdict["explanation"])
        out["confidence"] = round((0.5 + 0.5 * discovery.share) * scale, 3)
    else:
        out["explanation"] = verdict["explanation"] + " " + discovery.text
    out["effects"] = (["discovered"] + list(verdict["effects"])) if leads else (list(verdict["effects"]) + ["discovered"])
    out["discovered"] = discovery.to_dict()
    return out


__all__ = ["discover", "without_library", "amend_verdict", "select", "Discovery", "Discovered", "Term", "dictionary", "describe",
           "resemblance", "explained_share", "sentence", "source", "write_source", "RESEMBLES"]
