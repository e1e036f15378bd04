"""Saying what a discovered correction is: in words, which library effect it resembles, and how much it explains.

* :func:`describe`: per term, the storage or port it acts on, whether it is conservative (an added
  energy, its force through the model's own ``J``) or dissipative (an added ``R ⪰ 0``), and how it
  depends on the state ("a stiffness that rises with the square of the deflection");
* :func:`resemblance`: the correction's signature (what it changes in the validation outputs, each
  channel over its spread) against each fitted library hypothesis' signature: the cosine of the two,
  the best of them named when it reaches :data:`RESEMBLES`;
* :func:`explained_share`: the validation-fit gain of a model against what remains above the noise
  floor (the residual a perfect model would leave, from :func:`~phs.workflows.diagnose.mismatch.noise_level`);
  :func:`channel_shares` and :func:`balanced_share` the same per channel, and their mean.
"""

from __future__ import annotations

import math

import numpy as np

RESEMBLES = 0.8
"""Cosine between signatures from which a discovered correction is said to resemble a library effect.
Not chosen on a measurement."""


def explained_share(reference, h, data, noise: dict) -> float:
    """Share of what ``reference`` misses above the noise floor that ``h`` explains, in [0, 1].

    ``(ρ_ref − ρ_h) / (ρ_ref − ρ_noise)`` with ``ρ`` the validation residual (sum over channels of
    weighted RSS, by default over the channel's variance) and ``ρ_noise = Σ_ch n σ_ch² w_ch²`` what white noise of std
    ``σ_ch`` alone leaves; 0 when ``reference`` is already at the noise floor.  ``σ_ch`` is the validation
    recording's own noise: the smallest of its noise level (:func:`~phs.workflows.diagnose.mismatch.noise_level`,
    the smaller of the standard-deviation and median estimates from its second differences: steps and fast
    transients inflate the first, not the second) and the noise level of either model's validation residual
    (a signal sampled slowly against its own motion has large second differences; a good model's residual
    does not): the lowest floor, so the share is never overstated.  Not the training recording's noise
    (``noise``, which only says whether a channel has a floor at all): a validation recording may be
    noisier (on the lab protocols of ``examples/lab_protocols.py`` the validation position's noise is 1.7
    times the training's, 1 % of a wider range), and its floor read from the training's would count most of
    that noise as mismatch no effect can explain (a concealed leakage behind an offset then added 0.011 of
    it, under ``LATER_SHARE``).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> import numpy as np
    >>> t = np.linspace(0, 6, 1000)
    >>> y = np.sin(t) + np.random.default_rng(0).normal(0.0, 0.1, t.size)   # validation noise 0.1
    >>> data = NS(validation={"y": y}, val_mask=np.ones(t.size, bool), outputs=["y"])
    >>> floor = t.size * 0.0973**2 / np.var(y)   # its noise level (0.0973) over its variance, per sample
    >>> float(round(floor, 1))
    17.8
    >>> round(explained_share(NS(validation_rss=floor + 20), NS(validation_rss=floor + 10), data, {"y": 0.05}), 3)
    0.5
    """
    from phs.workflows.diagnose.mismatch import noise_level

    floor = 0.0
    for ch in data.outputs:
        y = np.asarray(data.validation[ch], float)[data.val_mask]
        weights = getattr(data, "weights", None)  # the scores' channel weights (default 1 / std)
        w2 = weights[ch] ** 2 if isinstance(weights, dict) else 1.0 / (float(np.var(y)) or 1.0)
        sigma = min([noise_level(y)] + [_residual_noise(m, ch, y, data.val_mask) for m in (reference, h)])
        sigma = sigma if noise.get(ch) else 0.0
        floor += len(y) * sigma**2 * w2
    room = reference.validation_rss - floor
    if not (math.isfinite(room) and room > 0 and math.isfinite(h.validation_rss)):
        return 0.0
    return float(np.clip((reference.validation_rss - h.validation_rss) / room, 0.0, 1.0))


def channel_shares(reference, h, data, noise: dict, relevant: float = 0.0) -> dict:
    """Per output channel, the share of what ``reference`` misses there above the channel's noise floor that
    ``h`` explains: ``(RSS_ref − RSS_h) / (RSS_ref − n σ²)`` over the validation samples, within [−1, 1]
    (negative where ``h`` misses more).  ``RSS`` from the validation fits (``validation_fit_percent``, NRMSE
    over ``data.val_mask``), ``σ`` the channel's lowest noise floor as in :func:`explained_share`.  Only the
    channels where ``reference`` misses something: its residual's RMS above
    :data:`~phs.workflows.diagnose.mismatch.STRUCTURED` times ``σ`` and at least ``relevant`` of the channel's
    standard deviation (a channel fitted to its noise has no room to share).

    Each channel's share is its own, whatever the channels' weights: in :func:`explained_share` a channel the
    reference misses badly (a capacitor's current at every step of a delayed command) outweighs one it
    misses less (the position), and what a second effect explains of the position vanishes in the sum.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> t = np.linspace(0, 6, 1000)
    >>> rng = np.random.default_rng(0)
    >>> data = NS(validation={"a": np.sin(t) + 0.01 * rng.standard_normal(t.size),
    ...                       "b": np.cos(3 * t) + 0.01 * rng.standard_normal(t.size)},
    ...           val_mask=np.ones(t.size, bool), outputs=["a", "b"])
    >>> ref = NS(validation_fit_percent={"a": 50.0, "b": 90.0})
    >>> shares = channel_shares(ref, NS(validation_fit_percent={"a": 95.0, "b": 90.0}), data, {"a": 0.01, "b": 0.01})
    >>> {ch: round(v, 3) for ch, v in shares.items()}
    {'a': 0.991, 'b': 0.0}
    >>> channel_shares(ref, NS(validation_fit_percent={"a": 50.0, "b": 99.6}), data, {"a": 0.01, "b": 0.01})["b"] > 0.9
    True
    """
    from phs.workflows.diagnose.mismatch import STRUCTURED, noise_level

    mask = np.asarray(data.val_mask, bool)
    out = {}
    for ch in data.outputs:
        y = np.asarray(data.validation[ch], float)[mask]
        spread = float(np.sum((y - y.mean()) ** 2)) if y.size else 0.0
        fr = (getattr(reference, "validation_fit_percent", None) or {}).get(ch)
        fh = (getattr(h, "validation_fit_percent", None) or {}).get(ch)
        if not spread > 0 or fr is None or fh is None or not (math.isfinite(fr) and math.isfinite(fh)):
            continue
        rss_ref, rss_h = (1.0 - fr / 100.0) ** 2 * spread, (1.0 - fh / 100.0) ** 2 * spread
        sigma = min([noise_level(y)] + [_residual_noise(m, ch, y, mask) for m in (reference, h)]) if noise.get(ch) else 0.0
        rms = math.sqrt(rss_ref / y.size)
        if not rms > STRUCTURED * sigma or rms < relevant * math.sqrt(spread / y.size):
            continue
        room = rss_ref - y.size * sigma**2
        out[ch] = float(np.clip((rss_ref - rss_h) / room, -1.0, 1.0))
    return out


def balanced_share(reference, h, data, noise: dict, relevant: float = 0.0) -> float:
    """The mean over channels of :func:`channel_shares`: what ``h`` explains of what ``reference`` misses, every
    channel that misses something counted alike; 0 when none does.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> t = np.linspace(0, 6, 1000)
    >>> data = NS(validation={"a": np.sin(t), "b": np.cos(3 * t)}, val_mask=np.ones(t.size, bool), outputs=["a", "b"])
    >>> ref = NS(validation_fit_percent={"a": 50.0, "b": 90.0})
    >>> round(balanced_share(ref, NS(validation_fit_percent={"a": 100.0, "b": 90.0}), data, {}), 3)
    0.5
    """
    shares = channel_shares(reference, h, data, noise, relevant)
    return float(np.mean(list(shares.values()))) if shares else 0.0


def _residual_noise(model, ch, y, mask) -> float:
    from phs.workflows.diagnose.mismatch import noise_level

    try:
        r = y - np.asarray(model.simulated["validation"][ch], float)[mask]
    except (AttributeError, KeyError, TypeError):
        return math.inf
    return noise_level(r)


def _signature(h, ref, data) -> list | None:
    """Per channel, what ``h`` changes in the validation outputs against ``ref`` (in units of the channel's
    standard deviation), over the validation samples both were scored on: a screened hypothesis is scored
    on the leading part of a separate validation recording only (:func:`~phs.workflows.diagnose.screening.screening_samples`)."""
    try:
        parts = []
        for ch in data.outputs:
            y = np.asarray(data.validation[ch], float)[data.val_mask]
            a, b = np.asarray(h.simulated["validation"][ch], float), np.asarray(ref.simulated["validation"][ch], float)
            m = min(len(a), len(b))
            mask = np.asarray(data.val_mask)[:m]
            parts.append((a[:m][mask] - b[:m][mask]) / (float(np.std(y)) or 1.0))
        return parts
    except (KeyError, TypeError):
        return None


def _cosine(a: list, b: list) -> float:
    """Cosine between two per-channel signatures over the samples both hold."""
    m = [min(len(x), len(y)) for x, y in zip(a, b, strict=True)]
    u = np.concatenate([x[:k] for x, k in zip(a, m, strict=True)])
    v = np.concatenate([y[:k] for y, k in zip(b, m, strict=True)])
    nu, nv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    return float(u @ v / (nu * nv)) if nu > 0 and nv > 0 else 0.0


def resemblance(discovered, base, nominal, hypotheses, data) -> list[tuple[str, float]]:
    """Cosine between the discovered correction's output signature (against ``base``, the model it
    extends) and each library hypothesis' (against ``nominal``), best first, one entry per effect.

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> import numpy as np
    >>> data = NS(outputs=["y"], validation={"y": np.arange(4.0)}, val_mask=np.ones(4, bool))
    >>> run = lambda y: NS(simulated={"validation": {"y": np.asarray(y, float)}}, ok=True, no_improvement=False)
    >>> lib = run([0, 2, 0, 2]); lib.augmentation = NS(effect="offset")
    >>> [(e, round(c, 6)) for e, c in resemblance(run([0, 1, 0, 1]), run([0, 0, 0, 0]), run([0, 0, 0, 0]), [lib], data)]
    [('offset', 1.0)]
    """
    sig = _signature(discovered, base, data)
    if sig is None or not any(np.any(p) for p in sig):
        return []
    best = {}
    for h in hypotheses:
        if not h.ok or h.augmentation is None or h.no_improvement:
            continue
        other = _signature(h, nominal, data)
        if other is None or not any(np.any(p) for p in other):
            continue
        cos = _cosine(sig, other)
        eff = h.augmentation.effect
        best[eff] = max(best.get(eff, -1.0), cos)
    return sorted(best.items(), key=lambda kv: -kv[1])


def describe(terms, values: dict, system) -> list[dict]:
    """Per term: ``term``, ``state`` (the state it acts on, or for an input gain or a sensor term the
    state it depends on), ``nature`` (``conservative``, ``dissipative``, ``input map``, ``sensor``, ``mode``,
    ``drift``, ``port limit``),
    ``parameter``, ``coefficient`` and ``words``; ``input`` or ``sensor`` (the input or measured output)
    for those terms, ``memory`` (the heat state's name, ``sensitivity``, ``tau``) for a heated dissipation.

    Examples
    --------
    >>> from systems.examples import mass_spring_damper
    >>> from phs.workflows.diagnose.discover.dictionary import Term
    >>> t = Term("energy", "k.l", "quartic")
    >>> d = describe([t], {t.parameter: 2.0}, mass_spring_damper())[0]
    >>> d["nature"], d["words"].split(" (")[0]
    ('conservative', 'a stiffness that rises with the square of the deflection')
    """
    out = []
    for t in terms:
        theta = float(values.get(t.parameter, 0.0))
        nature, what = _NATURE[t.kind]
        state = t.via if t.kind in ("input", "sensor") else t.state
        entry = {"term": t.label, "state": state, "nature": nature, "parameter": t.parameter, "coefficient": theta,
                 "words": f"{t.words(system, theta, values)} ({nature}: {what.format(t.state)})"}
        if t.kind in ("input", "sensor"):
            entry[t.kind] = t.state
        if t.kind == "memory":
            entry["memory"] = {"state": t.heat_state, **{n.split(".", 1)[1].split("_", 1)[0]: float(values.get(n, 0.0))
                                                        for n in t.parameters[1:]}}
        out.append(entry)
    return out


_NATURE = {
    "energy": ("conservative", "an added energy on {0}"),
    "damping": ("dissipative", "an added dissipation R ≥ 0 on {0}"),
    "memory": ("dissipative", "an added dissipation R ≥ 0 on {0} with its own heat storage, fed by the power it dissipates"),
    "input": ("input map", "a state-dependent gain of input {0}, a modulated transformer at the port"),
    "sensor": ("sensor", "a correction of the measured output {0}, not of a power port"),
    "mode": ("mode", "an added storage pair (a mass and a spring, with a damper) joined to {0}"),
    "drift": ("drift", "a slow state of its own scaling a parameter of {0}"),
    "limit": ("port limit", "a nonlinear resistance in series with input {0}"),
}
"""Per term kind: its nature and what it adds (``{0}``: where)."""


def sentence(described: list[dict], similar: list[tuple[str, float]], share: float) -> str:
    """The discovered correction in one paragraph.

    Examples
    --------
    >>> sentence([{"words": "a damping that rises with speed"}], [("quadratic_drag", 0.93)], 0.45)[:80]
    'Discovered correction: a damping that rises with speed. It resembles the library'
    """
    parts = "; ".join(d["words"] for d in described)
    if similar and similar[0][1] >= RESEMBLES:
        like = f" It resembles the library's {similar[0][0]} (signature cosine {similar[0][1]:.2f})."
    elif similar:
        like = f" It resembles none of the library's effects (closest: {similar[0][0]}, signature cosine {similar[0][1]:.2f})."
    else:
        like = " No library effect could be compared with it."
    return (f"Discovered correction: {parts}.{like} It explains {100 * share:.0f} % of what the model it extends misses "
            f"above the noise floor.")
