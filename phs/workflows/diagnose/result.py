"""The outcome of a diagnosis: :class:`Diagnosis`, with its verdict, its JSON and its report."""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

import phs.workflows.diagnose.refusal as refusal
import phs.workflows.diagnose.report as report
from phs._results import ResultMixin, finish, panels, require_pandas
from phs.workflows.diagnose.ranking import (
    FAILED_FACTOR,
    MIN_BIC_GAIN,
    MIN_VALIDATION_GAIN,
    SCREENED_CAP,
    _delta_bic,
    _gain,
    calibrated,
    undetermined_effect,
)

if TYPE_CHECKING:
    from phs.system import PHSystem


@dataclass(repr=False)
class Diagnosis(ResultMixin):
    """Outcome of :func:`~phs.workflows.diagnose.diagnose`: the nominal fit, the located mismatch, the ranked hypotheses,
    the accepted effects and the final model.  ``to_dict()`` is the documented JSON.

    ``bool(diagnosis)`` is True when the model passes: nothing significant is missing (:attr:`effect` is
    ``"none"``); it is False when an effect was named or the model cannot describe the recording (:attr:`refused`).
    :meth:`summary` is the readable report, ``repr`` one line, :meth:`plot` the fit before and after on the
    validation data, :meth:`to_pandas` one row per hypothesis.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from components.candidates import Offset
    >>> from phs.workflows.diagnose import diagnose
    >>> from phs.workflows.recording import Recording
    >>> from systems.examples import rc_circuit
    >>> t = np.linspace(0, 0.02, 401); u = np.sin(2 * np.pi * 150 * t)
    >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05   # a sensor offset
    >>> d = diagnose(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"], candidates=[Offset()],
    ...              n_jobs=1)
    >>> bool(d), d  # doctest: +ELLIPSIS
    (False, Diagnosis('rc', verdict offset, confidence ...; fit v_C ... -> 100.0 % (validation), 1 hypotheses))
    """

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
    discovery: object = None
    """The correction found outside the library (:class:`~phs.workflows.diagnose.discover.Discovery`), or
    None when discovery did not run."""

    @property
    def effect(self) -> str:
        """The main effect's name, ``"none"``, or ``"model_cannot_describe"`` (:attr:`refused`)."""
        return self.verdict["effect"]

    @property
    def weights(self) -> dict:
        """The channel weights every fit and score used (see ``diagnose(weights=)``): ``1 / std`` of each
        training channel by default, ``1 / sigma`` (the nominal fit's residual RMS, floored) with ``"ml"``."""
        if self.data is None:
            return {}
        w = self.data.weights
        if isinstance(w, dict):
            return dict(w)
        return {ch: 1.0 / (float(np.std(np.asarray(self.data.recording[ch], float))) or 1.0) for ch in self.outputs}

    @property
    def final_system(self) -> PHSystem:
        """The final (augmented and fitted) model."""
        return self.final.system

    def discovered_source(self) -> str:
        """Python source of a :class:`~components.candidates.Candidate` subclass holding the discovered
        correction with its fitted parameters (see :mod:`phs.workflows.diagnose.discover.emission`).

        Raises
        ------
        PHSError
            When no correction was discovered.
        """
        from phs.errors import PHSError
        from phs.workflows.diagnose.discover import source

        if self.discovery is None or not self.discovery.found:
            raise PHSError(f"diagnosis of {self.system.name!r}: no correction was discovered"
                           + (f" ({self.discovery.reason})" if self.discovery is not None and self.discovery.reason else ""))
        return source(self.discovery, self.discovery.text, self.discovery.share)

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
                              "validation_gain": _gain(self.nominal, h),
                              **({"ftol": h.ftol} if h.stage == "full" and h.ftol is not None else {})},
                "n_params": h.n_params, "accepted": any(h is a for a in self.accepted), "seconds": h.seconds,
                "no_improvement": h.no_improvement, "undetermined": list(h.undetermined),
                **({"error": h.error} if h.error else {}), **({"recovery": h.recovery} if h.recovery else {}),
                **({"deferred": h.deferred} if h.deferred and h.stage != "full" else {}),
            }

        return {
            "system": self.system.name, "model_hash": self.system.model_hash(), "outputs": self.outputs,
            "baseline": {"fit_percent": self.nominal.fit_percent, "validation_fit_percent": self.nominal.validation_fit_percent,
                         "parameters": self.nominal.values, "bic": self.nominal.bic, "starts": self.nominal.starts},
            "noise": self.noise,
            "weights": self.weights,
            "mismatch": [f.to_dict() for f in self.findings],
            "hypotheses": [hyp(h, i + 1) for i, h in enumerate(self.hypotheses)],
            "verdict": self.verdict,
            "final": {"fit_percent": self.final.fit_percent, "validation_fit_percent": self.final.validation_fit_percent,
                      "parameters": {**self.final.values, **self.final.element_values},
                      "passive": self.structure_checks()["ok"]},
            "discovered": self.discovery.to_dict() if self.discovery is not None else None,
            "seconds": self.seconds,
        }

    @property
    def refused(self) -> bool:
        """The nominal model cannot describe the recording: no effect was named
        (:mod:`~phs.workflows.diagnose.refusal`)."""
        return self.verdict["effect"] == refusal.REFUSED

    def summary(self) -> str:
        v = self.verdict
        if self.refused:
            return refusal.summary(self)
        lines = [f"Diagnosis of {self.system.name!r} ({self.seconds:.1f} s): verdict {v['effect']}"
                 + (f" (effects: {', '.join(v['effects'])})" if len(v["effects"]) > 1 else "")
                 + f", confidence {v['confidence']:.2f}", "  " + v["explanation"],
                 (f"  the named effect explains {100 * v.get('explained_share', 0.0):.0f} % of what the nominal model misses "
                  "(above the noise floor)" if v["effect"] != "none" else "  no effect named (explained share 0 %)")]
        lines.append("  fit % (training / validation):")
        for ch in self.outputs:
            lines.append(f"    {ch}: nominal {self.nominal.fit_percent[ch]:.2f} / {self.nominal.validation_fit_percent[ch]:.2f}"
                         f"  ->  final {self.final.fit_percent[ch]:.2f} / {self.final.validation_fit_percent[ch]:.2f}")
        st = self.nominal.starts
        if st:
            from phs.workflows.diagnose.nominal import check_words

            lines.append(f"  nominal fit: {st['agreed']} of {st['tried']} starts agree (training cost within 1 %), "
                         f"best from {st['best']}" + (f"; {check_words(st['check'])}" if st.get("check") else ""))
        if self.weights:
            lines.append("  channel weights: "
                         + ", ".join(f"{ch} {w:.3g}" for ch, w in self.weights.items()))
        lines.append("  located mismatch:")
        for f in self.findings[:8]:
            lines.append(f"    [{f.kind}] {f.channel}: {f.where} (strength {f.strength:.3g})")
        lines.append("  hypotheses (best first):")
        for h in [h for h in self.hypotheses if h.ok][:8]:
            vf = ", ".join(f"{k} {x:.2f}" for k, x in h.validation_fit_percent.items())
            lines.append(f"    {h.label:<32} validation fit {vf}; ΔBIC {_delta_bic(self.nominal, h):+.1f}; "
                         f"validation residual {report.residual_change(_gain(self.nominal, h))}"
                         + (" (screening)" if h.stage != "full" else "")
                         + (" (no improvement: the fit ended at the nominal model)" if h.no_improvement else "")
                         + (f" (the data do not determine {', '.join(h.undetermined)} separately)"
                            if undetermined_effect(h) else "")
                         + ("  accepted" if any(h is a for a in self.accepted) else ""))
        if self.discovery is not None:
            lines += report.discovery_lines(self.discovery)
        failed = self.verdict.get("failed", [])
        if failed:
            lines.append("  failed hypotheses (missing from the ranking):")
            lines += [f"    {f['hypothesis']:<32} fit failed: {f['error']}" for f in failed]
        return "\n".join(lines)

    __str__ = summary

    def _repr_html_(self) -> str:
        """Jupyter: the verdict, the fit before and after, and the ranked hypotheses as small HTML tables
        (every string escaped)."""
        from codegen.tables import html_table

        v = self.verdict
        head = f"Diagnosis of {self.system.name!r}: verdict {v['effect']}, confidence {v['confidence']:.2f}"
        fits = [(ch, self.nominal.fit_percent[ch], self.nominal.validation_fit_percent[ch], self.final.fit_percent[ch],
                 self.final.validation_fit_percent[ch]) for ch in self.outputs]
        hyps = [(h.label, ", ".join(f"{k} {x:.2f}" for k, x in h.validation_fit_percent.items()),
                 _delta_bic(self.nominal, h), report.residual_change(_gain(self.nominal, h)),
                 "yes" if any(h is a for a in self.accepted) else "") for h in self.hypotheses if h.ok][:8]
        return (html_table(["output", "nominal fit %", "nominal validation %", "final fit %", "final validation %"],
                           fits, caption=head)
                + f"<p>{html.escape(v['explanation'])}</p>"
                + html_table(["hypothesis", "validation fit %", "ΔBIC", "validation residual change", "accepted"], hyps))

    def __bool__(self) -> bool:
        return self.verdict["effect"] == "none"

    def _headline(self) -> str:
        v = self.verdict
        fits = ", ".join(f"{ch} {self.nominal.validation_fit_percent[ch]:.1f} -> {self.final.validation_fit_percent[ch]:.1f} %"
                         for ch in self.outputs[:3])
        return (f"{self.system.name!r}, verdict {v['effect']}, confidence {v['confidence']:.2f}; fit {fits} (validation), "
                f"{len(self.hypotheses)} hypotheses")

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """One row per ranked hypothesis (best first): its effect, where it attaches, validation fit % per channel,
        ΔBIC against the nominal model, validation residual gain, stage and whether it was accepted.

        Needs pandas (``pip install "phs[pandas]"``); without it, an ImportError of one line says so.

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from components.candidates import Offset
        >>> from phs.workflows.diagnose import diagnose
        >>> from phs.workflows.recording import Recording
        >>> from systems.examples import rc_circuit
        >>> t = np.linspace(0, 0.02, 401); u = np.sin(2 * np.pi * 150 * t)
        >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
        >>> d = diagnose(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"], candidates=[Offset()],
        ...              n_jobs=1)
        >>> bool(d.to_pandas().loc["offset@v_C", "accepted"])  # doctest: +SKIP
        True
        """
        pd = require_pandas("Diagnosis.to_pandas()")
        hs = self.hypotheses
        cols = {"effect": [h.augmentation.effect for h in hs], "attached_to": [h.augmentation.attached_to for h in hs]}
        for ch in self.outputs:
            cols[f"validation_fit_{ch}"] = [h.validation_fit_percent.get(ch, np.nan) if h.ok else np.nan for h in hs]
        cols["delta_bic"] = [_delta_bic(self.nominal, h) if h.ok and math.isfinite(h.bic) else np.nan for h in hs]
        cols["validation_gain"] = [_gain(self.nominal, h) if h.ok else np.nan for h in hs]
        cols["stage"] = [h.stage for h in hs]
        cols["accepted"] = [any(h is a for a in self.accepted) for h in hs]
        cols["error"] = [h.error or "" for h in hs]
        df = pd.DataFrame(cols, index=pd.Index([h.label for h in hs], name="hypothesis"))
        df.attrs["verdict"] = self.verdict["effect"]
        return df

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """Measured, nominal and final model on the validation data, and the residuals before and after: two
        panels per fitted channel.

        Parameters
        ----------
        path : str or path, optional
            Write the figure there (atomically, in the format of its suffix).
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes, two per channel.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> import numpy as np
        >>> from codegen import simulate
        >>> from components.candidates import Offset
        >>> from phs.workflows.diagnose import diagnose
        >>> from phs.workflows.recording import Recording
        >>> from systems.examples import rc_circuit
        >>> t = np.linspace(0, 0.02, 401); u = np.sin(2 * np.pi * 150 * t)
        >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"] + 0.05
        >>> d = diagnose(rc_circuit(), Recording.from_arrays(t, {"U": u, "v_C": y}), free=["R.R"], candidates=[Offset()],
        ...              n_jobs=1)
        >>> [a.get_ylabel() for a in d.plot().axes]
        ['v_C', 'v_C residual']
        """
        if self.data is None:
            from phs.errors import PHSError

            raise PHSError(f"diagnosis of {self.system.name!r}: plot() needs the recordings, which this diagnosis does not hold")
        data = self.data
        t = np.asarray(data.validation.t)
        mask = data.val_mask
        fig, grid = panels(ax, 2 * len(self.outputs), figsize=(9, 4.8 * len(self.outputs)), sharex=True,
                           what="Diagnosis.plot")
        axes = grid[:, 0]
        for k, ch in enumerate(self.outputs):
            y = np.asarray(data.validation[ch])
            yn = np.asarray(self.nominal.simulated["validation"][ch])
            yf = np.asarray(self.final.simulated["validation"][ch])
            a = axes[2 * k]
            a.plot(t[mask], y[mask], lw=0.8, color="0.4", label="measured")
            a.plot(t[mask], yn[mask], lw=1, label=f"nominal ({self.nominal.validation_fit_percent[ch]:.1f} %)")
            a.plot(t[mask], yf[mask], lw=1, label=f"{self.effect} ({self.final.validation_fit_percent[ch]:.1f} %)")
            a.set_ylabel(ch)
            a.legend(fontsize=7, loc="upper right")
            a = axes[2 * k + 1]
            a.plot(t[mask], (y - yn)[mask], lw=0.7, label="residual, nominal")
            a.plot(t[mask], (y - yf)[mask], lw=0.7, label="residual, final")
            a.set_ylabel(f"{ch} residual")
            a.legend(fontsize=7, loc="upper right")
        axes[-1].set_xlabel("t [s] (validation)")
        fig.suptitle(f"{self.system.name}: verdict {self.effect}")
        return finish(fig, path, dpi=90)

    def write_report(self, directory) -> None:
        """HTML report with figures, and ``diagnosis.json``, into ``directory`` (written atomically)."""
        report.write_report(self, directory)


def _verdict(nominal, accepted, hyps, findings, outs, failed=()) -> dict:
    """The verdict: effect, effects, explanation, confidence and the ``failed`` hypotheses (every round's;
    each multiplies the confidence by :data:`~phs.workflows.diagnose.ranking.FAILED_FACTOR`)."""
    ok = [h for h in hyps if h.ok]
    failed = list(failed) or [h for h in hyps if not h.ok]
    lost = [{"hypothesis": h.label, "effect": h.augmentation.effect, "attached_to": h.augmentation.attached_to, "error": h.error}
            for h in failed]
    scale = FAILED_FACTOR ** len(lost)
    tail = report.failed_sentence(failed, scale)
    if not accepted:
        best = ok[0] if ok else None
        g = _gain(nominal, best) if best else 0.0
        conf = float(np.clip(1.0 - max(g, 0.0) / (2 * MIN_VALIDATION_GAIN), 0.0, 1.0)) if best else 0.5
        conf = max(conf, 0.5) if (best is None or -_delta_bic(nominal, best) < MIN_BIC_GAIN) else conf
        return {"effect": "none", "effects": [], "explanation": report.explanation(nominal, [], findings, best, outs) + tail,
                "confidence": round(calibrated(conf, "none") * scale, 3), "score": round(conf, 4), "failed": lost}
    main = accepted[0]
    # rivals: other effects, except those the choice judged to be the same physics (a pre-sliding loop)
    rivals = [h for h in ok if h.augmentation.effect != main.augmentation.effect and h.label not in main.same_physics]
    g_main = _gain(nominal, main)
    g_rival = max([_gain(nominal, h) for h in rivals] + [0.0])
    sep = (g_main - g_rival) / g_main if g_main > 0 else 0.0
    score = float(np.clip(0.5 + 0.5 * sep, 0.0, 1.0))
    conf = calibrated(score)
    if any(h.stage != "full" and _gain(nominal, h) > 0 for h in rivals):
        conf = min(conf, SCREENED_CAP)  # a rival that explains something was only screened
    return {"effect": main.augmentation.effect, "effects": [a.augmentation.effect for a in accepted],
            "explanation": report.explanation(nominal, accepted, findings, rivals[0] if rivals else None, outs) + tail,
            "confidence": round(conf * scale, 3), "score": round(score, 4), "failed": lost}
