"""Consistency between locating and naming: what the located mismatch points at, and whether the verdict
agrees with it.

Some located features are the signature of a family of effects, whatever the model:

* the residual following the **sign of a velocity** (or a signal times it) is the signature of a force
  that flips with the direction of motion: dry friction or a friction-like hysteresis;
* power at the **odd harmonics** (3rd, 5th, ...) of a periodic excitation, more than at the even ones, is
  the signature of an odd-symmetric nonlinearity: dry friction, hysteresis, a hardening spring, fluid
  drag, a clipped or rate-limited drive.

When such a pointer is there and the verdict names none of its family (or ``none``), the two steps of the
diagnosis disagree: the family's hypotheses that were only screened get the full joint fit before the
choice (:func:`~phs.workflows.diagnose.screening._refit_pointed`), and if the verdict still names none
of them the report says so and the confidence is scaled by :data:`DISAGREE_FACTOR` (:func:`reconcile`).

Examples
--------
>>> from phs.workflows.diagnose.locate.finding import Finding
>>> f = Finding("feature", "force", "residual ~ sign(v)", 0.2, "R²",
...             {"transform": "sign(x)", "base": "v:cart.p", "velocity": None, "significant": True})
>>> [p.family for p in pointers([f], ["cart.p"])]
['dry friction']
"""

from __future__ import annotations

from dataclasses import dataclass

POINTER_SHARE = 0.05
"""Smallest share of a channel's residual (variance for a feature, power for the odd harmonics together) a
significant finding must carry to point at a family: a significant but minor feature (a few per cent of a
residual dominated by something else) says little about what is missing.
Not chosen on a measurement (no concealed case recorded)."""
DISAGREE_FACTOR = 0.6
"""Factor on the confidence of a verdict that names nothing of a family the located mismatch points at.
A ``none`` verdict (confidence 0.5 at best) then ends at 0.3, below any accepted effect's confidence, and
a named effect at 0.9 ends near the confidence of a verdict with a rival only screened.
Chosen by that ordering, not on a measurement: the stored calibration diagnoses do not record a
disagreement, so no held-out figure can be computed from them."""

FAMILIES = {
    "dry friction": ("coulomb_friction", "hysteresis"),
    "an odd-symmetric nonlinearity": ("coulomb_friction", "hysteresis", "cubic_stiffness", "quadratic_drag",
                                      "input_saturation", "slew_rate_limit"),
}
"""The effects of the library each pointer points at (by effect name)."""


@dataclass(frozen=True)
class Pointer:
    """A family of effects the located mismatch points at: its name, the effects, and the findings in words."""

    family: str
    effects: tuple
    evidence: tuple

    def sentence(self) -> str:
        return f"{self.family} ({'; '.join(self.evidence)})"


def _velocity(base, momenta) -> bool:
    return isinstance(base, str) and (base.startswith("v:") or base in momenta)


def pointers(findings, momenta) -> list[Pointer]:
    """The families of effects the located ``findings`` point at (see the module docstring); ``momenta``:
    the model's momentum states (the sign of a momentum is the sign of its velocity).

    Examples
    --------
    >>> from phs.workflows.diagnose.locate.finding import Finding
    >>> h = [Finding("harmonic", "y", f"{k}th harmonic", s, "share", {"order": k, "significant": True})
    ...      for k, s in ((3, 0.3), (5, 0.2))]
    >>> [p.family for p in pointers(h, [])]
    ['an odd-symmetric nonlinearity']
    >>> pointers(h[:1] + [Finding("harmonic", "y", "2nd", 0.4, "share", {"order": 2, "significant": True})], [])
    []
    """
    out = []
    dry = [f for f in findings if f.kind == "feature" and f.significant and f.strength >= POINTER_SHARE
           and ((f.details.get("transform") == "sign(x)" and _velocity(f.details.get("base"), momenta))
                or f.details.get("transform") == "x·sign(v)")]
    if dry:
        out.append(Pointer("dry friction", FAMILIES["dry friction"],
                           tuple(f"{f.channel}: {f.where}, R² {f.strength:.2f}" for f in dry[:2])))
    by_channel = {}
    for f in findings:
        if f.kind == "harmonic" and f.significant and int(f.details.get("order", 1)) >= 2:
            by_channel.setdefault(f.channel, []).append(f)
    for ch, hs in by_channel.items():
        odd = [f for f in hs if int(f.details["order"]) % 2 == 1]
        even = sum(f.strength for f in hs if int(f.details["order"]) % 2 == 0)
        share = sum(f.strength for f in odd)
        if odd and share >= POINTER_SHARE and share > even:
            orders = ", ".join(str(int(f.details["order"])) for f in sorted(odd, key=lambda f: f.details["order"]))
            out.append(Pointer("an odd-symmetric nonlinearity", FAMILIES["an odd-symmetric nonlinearity"],
                               (f"{ch}: odd harmonics {orders} of the excitation carry {100 * share:.0f} % of the residual's power",)))
            break
    return out


def unmatched(pointed: list[Pointer], effects) -> list[Pointer]:
    """The pointers none of whose effects is among ``effects`` (the verdict's).

    Examples
    --------
    >>> p = Pointer("dry friction", ("coulomb_friction", "hysteresis"), ("y: residual ~ sign(v)",))
    >>> [q.family for q in unmatched([p], ["time_delay"])], unmatched([p], ["hysteresis"])
    (['dry friction'], [])
    """
    return [p for p in pointed if not set(p.effects) & set(effects)]


def reconcile(verdict: dict, pointed: list[Pointer], tried=()) -> dict:
    """``verdict`` with what the located mismatch points at and the verdict does not name said in its
    explanation, recorded as ``verdict["disagrees_with_located"]``, and the confidence scaled by
    :data:`DISAGREE_FACTOR`; unchanged when the verdict names an effect of every pointed family.
    ``tried``: the labels (``effect@place``) of the hypotheses fitted, to say which of the family's were.

    Examples
    --------
    >>> p = Pointer("dry friction", ("coulomb_friction", "hysteresis"), ("force: residual ~ sign(v), R² 0.17",))
    >>> v = reconcile({"effect": "none", "effects": [], "confidence": 0.5, "explanation": "No effect."}, [p],
    ...               ["coulomb_friction@m.p", "time_delay@U"])
    >>> v["confidence"], v["disagrees_with_located"]
    (0.3, ['dry friction'])
    >>> v["explanation"].split("; ")[-1]
    'its hypotheses coulomb_friction@m.p were fitted in full and not named (confidence scaled by 0.6).'
    """
    missing = unmatched(pointed, verdict.get("effects") or [])
    if not missing:
        return verdict
    out = dict(verdict)
    named = "no effect" if verdict.get("effect", "none") == "none" else ", ".join(verdict.get("effects") or [verdict["effect"]])
    family = {e for p in missing for e in p.effects}
    fitted = [lab for lab in tried if lab.split("@", 1)[0] in family]
    how = (f"its hypotheses {', '.join(fitted)} were fitted in full and not named" if fitted else
           f"none of its effects ({', '.join(sorted(family))}) was among the candidates")
    out["confidence"] = round(float(verdict["confidence"]) * DISAGREE_FACTOR, 3)
    out["disagrees_with_located"] = [p.family for p in missing]
    out["explanation"] = (verdict["explanation"] + " The located mismatch points at "
                          + " and at ".join(p.sentence() for p in missing)
                          + f", which the verdict ({named}) does not name; {how} (confidence scaled by {DISAGREE_FACTOR}).")
    return out
