"""Words, figures and files of a diagnosis: the explanation, the HTML report and the JSON."""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os

import numpy as np

from phs.io import write_all_atomic, write_atomic
from phs.workflows.diagnose.mismatch import _features
from phs.workflows.diagnose.ranking import FAILED_FACTOR, MIN_VALIDATION_GAIN, _accepted, _delta_bic, _gain, residual_change

# which located findings speak for which effect (used to say where an effect showed)
_EVIDENCE = {
    "charge_retention": ("drift", "time_window"),
    "leakage": ("drift", "feature"),
    "series_resistance": ("time_window", "input_lag"),
    "coulomb_friction": ("feature", "harmonic"),
    "viscoelastic_creep": ("drift", "time_window"),
    "cubic_stiffness": ("feature", "amplitude_scaling", "harmonic"),
    "hysteresis": ("feature", "harmonic"),
    "quadratic_drag": ("feature", "rate_scaling"),
    "added_mass": ("spectrum", "time_window"),
    "input_saturation": ("amplitude_scaling", "feature"),
    "slew_rate_limit": ("time_window", "input_lag"),
    "time_delay": ("input_lag", "time_window"),
    "offset": ("feature", "drift"),
}


def _fmt_params(values: dict) -> str:
    return ", ".join(f"{k.split('.', 1)[-1]} = {v:.3g}" for k, v in values.items())


def _fits(nominal, h, outs) -> str:
    parts = []
    for ch in outs:
        parts.append(f"{ch} {nominal.fit_percent[ch]:.1f} → {h.fit_percent[ch]:.1f} % (training), "
                     f"{nominal.validation_fit_percent[ch]:.1f} → {h.validation_fit_percent[ch]:.1f} % (validation)")
    return "; ".join(parts)


NONE_FOUND = "No missing physics found: no candidate improves the fit beyond what noise explains. The best,"
"""How a ``none`` verdict's explanation opens when no candidate passes the fit rule (reworded by a discovery)."""
NONE_TRADED = "No missing physics accepted: the best candidate,"
"""How it opens when the best candidate passes the fit rule but lowers another channel's validation fit."""
NONE_FITTED = "No candidate could be fitted; the nominal model stands."
"""How it opens when no candidate could be fitted."""


def explanation(nominal, accepted, findings, rival, outs) -> str:
    """Plain-language verdict (see :func:`phs.diagnose`)."""
    if not accepted:
        if rival is None:
            return NONE_FITTED
        g = _gain(nominal, rival)
        white = [f for f in findings if f.kind == "whiteness"]
        tail = (" The residual " + ("looks white" if all(f.details.get("p_value", 0) > 0.01 for f in white) else "keeps some structure")
                + " (" + "; ".join(f"{f.channel}: {f.where}" for f in white) + ").") if white else ""
        if getattr(rival, "worsens", None) and _accepted(nominal, rival):  # it pays, but at another channel's cost
            return (f"{NONE_TRADED} {rival.augmentation.effect} at "
                    f"{rival.augmentation.attached_to}, improves the fit (validation residual {residual_change(g)}, ΔBIC "
                    f"{_delta_bic(nominal, rival):+.1f}) only by lowering another channel's.{tail}")
        return (f"{NONE_FOUND} "
                f"{rival.augmentation.effect} at {rival.augmentation.attached_to}: validation residual "
                f"{residual_change(g)}, ΔBIC {_delta_bic(nominal, rival):+.1f} (acceptance needs −1 % and −10 or lower).{tail}")
    from components.candidates import LIBRARY

    summaries = {c.effect: c.summary for c in LIBRARY}
    out = []
    for k, h in enumerate(accepted):
        aug = h.augmentation
        what = aug.summary or summaries.get(aug.effect, aug.component or aug.effect)
        ev = [f for f in findings if f.kind in _EVIDENCE.get(aug.effect, ())][:2]
        where = "; ".join(f"{f.channel}: {f.where}" for f in ev)
        derived = aug.element.derived(list(h.element_values.values())) if aug.element is not None and h.element_values else {}
        params = _fmt_params({**{p: h.values[p] for p in aug.free if p in h.values}, **h.element_values, **derived})
        lead = "Missing physics" if k == 0 else "A second effect"
        out.append(f"{lead}: {what} — {aug.effect} at {aug.attached_to} ({aug.component}; {params})."
                   + (f" It showed as {where}." if where else "")
                   + f" Fit: {_fits(nominal if k == 0 else accepted[k - 1], h, outs)}."
                   + "".join(f" {n}" for n in h.notes))
    if rival is not None:
        g = _gain(nominal, rival)
        out.append(f"Next best explanation: {rival.augmentation.effect} at {rival.augmentation.attached_to}; its "
                   f"validation residual {residual_change(g)}.")
    return " ".join(out)


def discovery_lines(discovery) -> list[str]:
    """Summary lines of a discovery: the chosen terms with their words, or why nothing was found."""
    if not discovery.found:
        return [f"  discovery ({discovery.seconds:.1f} s): nothing found ({discovery.reason})"]
    out = [f"  discovered correction ({discovery.seconds:.1f} s), explains {100 * discovery.share:.0f} % of what the model it "
           "extends misses:"]
    out += [f"    {d['term']:<32} {d['parameter'].split('.', 1)[-1]} = {d['coefficient']:.4g}: {d['words']}" for d in discovery.described]
    if discovery.similar:
        e, c = discovery.similar[0]
        out.append(f"    closest library effect: {e} (signature cosine {c:.2f})")
    return out


def worsening_sentence(hyps) -> str:
    """What the explanation says of hypotheses that were not accepted because they lower a channel's
    validation fit beyond what its noise allows (``Scored.worsens``; empty when none did).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> h = NS(augmentation=NS(effect="slew_rate_limit", attached_to="V"), worsens={"x": (94.4, 92.9)},
    ...        validation_fit_percent={"x": 92.9, "i": 80.0})
    >>> worsening_sentence([h])
    " Not accepted, because it lowers another channel's validation fit beyond what that channel's noise allows: slew_rate_limit at V (x 94.40 → 92.90 %)."
    """
    bad = [h for h in hyps if getattr(h, "worsens", None)]
    if not bad:
        return ""
    parts = [f"{h.augmentation.effect} at {h.augmentation.attached_to} ("
             + ", ".join(f"{ch} {a:.2f} → {b:.2f} %" for ch, (a, b) in h.worsens.items()) + ")" for h in bad]
    return (f" Not accepted, because {'it lowers' if len(bad) == 1 else 'each lowers'} another channel's validation fit beyond "
            f"what that channel's noise allows: {'; '.join(parts)}.")


def small_share_sentence(hyps, least: float) -> str:
    """What the explanation says of later-round hypotheses that passed the acceptance rule but were not
    named, because beyond the accepted effects they explain less than ``least`` of what the nominal model
    misses above the noise (``Scored.later_share``; empty when none).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> h = NS(augmentation=NS(effect="hysteresis", attached_to="m.p"), later_share=0.0225)
    >>> s = small_share_sentence([h], 0.1)
    >>> s.startswith(" Also fitted after the accepted effects but not named: hysteresis at m.p adds 2.2 % of what")
    True
    >>> s.endswith("(a named effect adds at least 10 %).")
    True
    """
    if not hyps:
        return ""
    parts = [f"{h.augmentation.effect} at {h.augmentation.attached_to} adds {100 * h.later_share:.2g} %" for h in hyps]
    return (f" Also fitted after the accepted effects but not named: {'; '.join(parts)} of what the nominal model misses "
            f"(a named effect adds at least {100 * least:.2g} %).")


def failed_sentence(failed, scale: float) -> str:
    """What the explanation says of hypotheses whose fit failed (empty when none did)."""
    if not failed:
        return ""
    which = "; ".join(f"{h.augmentation.effect} at {h.augmentation.attached_to} ({h.error})" for h in failed)
    return (f" Not ranked, because their fit failed after every retry: {which}. Any of them might explain the mismatch "
            f"as well; the confidence is scaled by {scale:.3g} ({FAILED_FACTOR:g} per failed hypothesis).")


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return buf.getvalue()


def figure_fits(d) -> bytes:
    """Measured vs nominal vs final model on the validation data, and residuals before/after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = d.data
    t = np.asarray(data.validation.t)
    mask = data.val_mask
    fig, axes = plt.subplots(2 * len(d.outputs), 1, figsize=(9, 2.4 * 2 * len(d.outputs)), sharex=True, squeeze=False)
    for k, ch in enumerate(d.outputs):
        y = np.asarray(data.validation[ch])
        yn = np.asarray(d.nominal.simulated["validation"][ch])
        yf = np.asarray(d.final.simulated["validation"][ch])
        ax = axes[2 * k, 0]
        ax.plot(t[mask], y[mask], lw=0.8, color="0.4", label="measured")
        ax.plot(t[mask], yn[mask], lw=1, label=f"nominal ({d.nominal.validation_fit_percent[ch]:.1f} %)")
        ax.plot(t[mask], yf[mask], lw=1, label=f"{d.verdict['effect']} ({d.final.validation_fit_percent[ch]:.1f} %)")
        ax.set_ylabel(ch)
        ax.legend(fontsize=7, loc="upper right")
        ax = axes[2 * k + 1, 0]
        ax.plot(t[mask], (y - yn)[mask], lw=0.7, label="residual, nominal")
        ax.plot(t[mask], (y - yf)[mask], lw=0.7, label="residual, final")
        ax.set_ylabel(f"{ch} residual")
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t [s] (validation)")
    fig.tight_layout()
    return _png(fig)


def figure_hypotheses(d) -> bytes:
    """Validation gain and ΔBIC of every hypothesis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hs = [h for h in d.hypotheses if h.ok]
    fig, ax = plt.subplots(figsize=(8, 0.3 * max(len(hs), 4) + 1))
    changes = [-100 * _gain(d.nominal, h) for h in hs]  # against the model each extends, on the data it was scored on
    colors = ["tab:green" if any(h is a for a in d.accepted) else "tab:gray" for h in hs]
    ax.barh([h.label for h in hs][::-1], changes[::-1], color=colors[::-1])
    ax.axvline(-100 * MIN_VALIDATION_GAIN, color="k", lw=0.8, ls="--")
    ax.set_xlabel("validation residual change [%] (negative: it fell; dashed: acceptance threshold)")
    fig.tight_layout()
    return _png(fig)


def figure_locate(d) -> bytes | None:
    import phs.workflows.diagnose.locate as loc

    if not hasattr(loc, "plot_findings"):
        return None
    feats, inputs = _features(d.nominal, d.system, d.data)
    buf = io.BytesIO()
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        p = os.path.join(tmp, "locate.png")
        loc.plot_findings(d.data.recording.t, d.nominal.residuals, feats, inputs, d.findings, p)
        with open(p, "rb") as fh:
            buf.write(fh.read())
    return buf.getvalue()


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def to_json(d) -> str:
    """The diagnosis as JSON text (non-finite numbers become null)."""
    def clean(o):
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, (list, tuple)):
            return [clean(v) for v in o]
        if isinstance(o, (float, np.floating)):
            return float(o) if math.isfinite(o) else None
        return o

    return json.dumps(clean(d.to_dict()), indent=2, default=_json_default)


def figures(d) -> dict:
    """The diagnosis' figures as PNG bytes: ``fits``, ``hypotheses`` and, when something was located,
    ``locate``."""
    figs = {"fits": figure_fits(d), "hypotheses": figure_hypotheses(d)}
    loc = figure_locate(d)
    if loc:
        figs["locate"] = loc
    return figs


def write_figures(d, directory, prefix: str) -> list[str]:
    """Write :func:`figures` as ``{prefix}_{name}.png`` into ``directory`` (created if missing; each
    file written under a temporary name and renamed into place); returns the paths."""
    directory = os.fspath(directory)
    os.makedirs(directory, exist_ok=True)
    paths = []
    for name, png in figures(d).items():
        path = os.path.join(directory, f"{prefix}_{name}.png")
        write_atomic(path, png)
        paths.append(path)
    return paths


def _report_files(d) -> dict:
    """The files of the report, rendered in memory: ``{name: text or PNG bytes}`` for ``index.html``
    (figures embedded), ``fits.png``, ``hypotheses.png``, ``locate.png`` (when something was located),
    ``diagnosis.json`` and ``summary.txt``."""
    figs = {f"{name}.png": png for name, png in figures(d).items()}
    text = d.summary()
    js = to_json(d)
    checks = d.structure_checks()
    page = ["<!doctype html><meta charset='utf-8'><title>Diagnosis of " + html.escape(d.system.name) + "</title>",
            "<style>body{font-family:sans-serif;max-width:1000px;margin:2em auto}td,th{padding:2px 8px}"
            "table{border-collapse:collapse}tr:nth-child(even){background:#f4f4f4}</style>",
            f"<h1>Diagnosis of {html.escape(d.system.name)}</h1>",
            f"<p><b>Verdict: {html.escape(d.verdict['effect'])}</b> (confidence {d.verdict['confidence']:.2f})</p>",
            f"<p>{html.escape(d.verdict['explanation'])}</p>",
            f"<p>The named effect explains {100 * d.verdict.get('explained_share', 0.0):.0f} % of what the nominal model misses "
            "above the noise floor.</p>",
            "<h2>Fit before and after</h2><table><tr><th>channel</th><th>nominal training</th><th>nominal validation</th>"
            "<th>final training</th><th>final validation</th></tr>"]
    for ch in d.outputs:
        page.append(f"<tr><td>{html.escape(ch)}</td><td>{d.nominal.fit_percent[ch]:.2f} %</td>"
                    f"<td>{d.nominal.validation_fit_percent[ch]:.2f} %</td><td>{d.final.fit_percent[ch]:.2f} %</td>"
                    f"<td>{d.final.validation_fit_percent[ch]:.2f} %</td></tr>")
    page.append("</table>")
    page.append(f"<h2>Final model</h2><p>structural checks: {'all passed (passive)' if checks['ok'] else 'FAILED'}</p>"
                f"<pre>{html.escape(checks['report'])}</pre>")
    for name, title in (("fits.png", "Measured, nominal and final (validation)"), ("locate.png", "Where the nominal model misses"),
                        ("hypotheses.png", "Hypotheses")):
        if name in figs:
            b64 = base64.b64encode(figs[name]).decode()
            page.append(f"<h2>{title}</h2><img src='data:image/png;base64,{b64}' style='max-width:100%'>")
    page.append("<h2>Located mismatch</h2><table><tr><th>kind</th><th>channel</th><th>where</th><th>strength</th><th>meaning</th></tr>")
    for f in d.findings:
        page.append(f"<tr><td>{html.escape(f.kind)}</td><td>{html.escape(f.channel)}</td><td>{html.escape(f.where)}</td>"
                    f"<td>{f.strength:.4g}</td><td>{html.escape(f.meaning)}</td></tr>")
    page.append("</table>")
    if d.discovery is not None:
        page.append("<h2>Discovered correction</h2><pre>" + html.escape("\n".join(discovery_lines(d.discovery))) + "</pre>")
        if d.discovery.found:
            page.append("<p>" + html.escape(d.discovery.text) + "</p>")
    failed = d.verdict.get("failed", [])
    if failed:
        page.append("<h2>Failed hypotheses (missing from the ranking)</h2><table><tr><th>hypothesis</th><th>reason</th></tr>")
        page += [f"<tr><td>{html.escape(f['hypothesis'])}</td><td>fit failed: {html.escape(f['error'])}</td></tr>" for f in failed]
        page.append("</table>")
    page.append("<h2>Summary</h2><pre>" + html.escape(text) + "</pre>")
    return {**figs, "diagnosis.json": js, "summary.txt": text + "\n", "index.html": "\n".join(page)}


def write_report(d, directory) -> None:
    """Write :func:`_report_files` into ``directory`` all or nothing (:func:`phs.io.write_all_atomic`;
    the directory is created if missing, and removed again when the writing fails)."""
    directory = os.fspath(directory)
    write_all_atomic({os.path.join(directory, n): data for n, data in _report_files(d).items()}, create=[directory])
