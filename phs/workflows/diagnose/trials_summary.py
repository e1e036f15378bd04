"""What many trials' diagnoses say together: :class:`Trials` (which effects recur, their parameters' spread),
and :func:`trial_record`, the JSON-ready record of one trial's diagnosis that it is built from."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field

import numpy as np

from phs._results import ResultMixin, finish, panels, require_pandas


def trial_record(name: str, d) -> dict:
    """One trial's :class:`~phs.workflows.diagnose.Diagnosis` as a JSON-ready dict: ``trial``, ``status``
    (``ok`` or ``refused``), ``verdict``, ``effects`` (each named effect with its fitted parameters, as in the
    final model), ``nominal`` (the refitted nominal parameters), ``seconds``, ``summary`` (the text of
    ``phs diagnose``) and ``diagnosis`` (its whole JSON, :meth:`Diagnosis.to_dict`).

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
    >>> r = trial_record("a", d)
    >>> r["effects"][0]["effect"], round(r["effects"][0]["parameters"]["offset.v_C"], 4), sorted(r["nominal"])
    ('offset', 0.05, ['R.R'])
    """
    from phs.workflows.diagnose.report import to_json

    names = list(d.verdict.get("effects") or [])
    effects = []
    for a in d.accepted:
        aug = a.augmentation
        if aug.effect not in names:
            continue
        params = {k: float(d.final.values.get(k, a.values.get(k))) for k in aug.free}
        params.update({k: float(d.final.element_values.get(k, v)) for k, v in a.element_values.items()})
        effects.append({"effect": aug.effect, "attached_to": aug.attached_to, "parameters": params})
    effects += [{"effect": n, "attached_to": None, "parameters": {}} for n in names
                if n not in [e["effect"] for e in effects]]
    free = list(d.nominal.values) if d.nominal is not None else []
    doc = json.loads(to_json(d))
    return {"trial": name, "status": "refused" if d.refused else "ok", "verdict": doc["verdict"], "effects": effects,
            "nominal": {k: doc["final"]["parameters"].get(k) for k in free}, "seconds": float(d.seconds),
            "summary": d.summary(), "diagnosis": doc}


def _stats(pairs: list) -> dict:
    """Count, mean, sample std (n - 1), min and max of ``(trial, value)`` pairs (None values left out)."""
    pairs = [(t, float(x)) for t, x in pairs if x is not None]
    v = np.asarray([x for _, x in pairs], dtype=float)
    if not len(v):
        return {"n": 0, "mean": None, "std": None, "min": None, "max": None, "values": [], "trials": []}
    return {"n": int(len(v)), "mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
            "min": float(v.min()), "max": float(v.max()), "values": v.tolist(), "trials": [t for t, _ in pairs]}


@dataclass(repr=False)
class Trials(ResultMixin):
    """The diagnoses of many trials of one model (:func:`~phs.workflows.diagnose.trials.diagnose_trials`):
    :meth:`recurring` says which effects recur and the spread of their parameters, :meth:`summary` prints it,
    :meth:`to_json`, :meth:`to_csv` and :meth:`plot` write it.  ``records`` holds each trial's
    :func:`trial_record` (with its stored ``identity``), in the order of the trials.

    Examples
    --------
    >>> rec = {"trial": "a", "status": "ok", "verdict": {"effect": "offset", "confidence": 0.9},
    ...        "effects": [{"effect": "offset", "parameters": {"offset.y": 0.05}}], "nominal": {"k": 2.0}}
    >>> t = Trials("m", [rec, {**rec, "trial": "b", "nominal": {"k": 2.2}}])
    >>> t  # doctest: +ELLIPSIS
    Trials('m': 2 trials; offset in 2/2)
    >>> round(t.nominal_spread()["k"]["std"], 4)
    0.1414
    """

    system: str
    records: list
    shared: dict | None = None
    ran: int = 0
    units: dict = field(default_factory=dict)

    @property
    def diagnosed(self) -> list:
        """The trials that reached a verdict (neither failed nor refused)."""
        return [r for r in self.records if r.get("status") == "ok"]

    def recurring(self) -> list[dict]:
        """One entry per verdict found in some trial, most frequent first: ``effect``, ``count``, ``of`` (the
        trials that reached a verdict), ``share``, ``trials`` (their names), ``parameters`` (name -> ``n``,
        ``mean``, ``std`` (n - 1), ``min``, ``max``, ``values`` and the ``trials`` they come from).  ``none``: no effect missing."""
        ok = self.diagnosed
        found: dict = {}
        for r in ok:
            named = r.get("effects") or [{"effect": r["verdict"]["effect"], "parameters": {}}]
            for e in named:
                entry = found.setdefault(e["effect"], {"trials": [], "parameters": {}})
                if r["trial"] not in entry["trials"]:
                    entry["trials"].append(r["trial"])
                for k, v in e.get("parameters", {}).items():
                    entry["parameters"].setdefault(k, []).append((r["trial"], v))
        out = [{"effect": name, "count": len(e["trials"]), "of": len(ok), "share": len(e["trials"]) / len(ok),
                "trials": e["trials"], "parameters": {k: _stats(v) for k, v in e["parameters"].items()}}
               for name, e in found.items()]
        return sorted(out, key=lambda e: (-e["count"], e["effect"] == "none", e["effect"]))

    def nominal_spread(self) -> dict:
        """The refitted nominal parameters across the trials that reached a verdict (as in :meth:`recurring`)."""
        names = list(dict.fromkeys(k for r in self.diagnosed for k in r.get("nominal", {})))
        return {k: _stats([(r["trial"], r.get("nominal", {}).get(k)) for r in self.diagnosed]) for k in names}

    def to_dict(self) -> dict:
        """The trials (their verdicts, effects, nominal parameters), :meth:`recurring`, :meth:`nominal_spread`,
        the joint fit of the shared parameters and the failed and refused trials: the summary JSON."""
        return {"system": self.system, "trials": [{k: r.get(k) for k in ("trial", "status", "verdict", "effects", "nominal",
                                                                          "seconds", "error")} for r in self.records],
                "recurring": self.recurring(), "nominal": self.nominal_spread(), "shared": self.shared,
                "failed": [r["trial"] for r in self.records if r.get("status") == "failed"],
                "refused": [r["trial"] for r in self.records if r.get("status") == "refused"]}

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text (non-finite numbers as null)."""
        from phs.workflows.diagnose.report import _json_default

        return json.dumps(_finite(self.to_dict()), indent=2, default=_json_default)

    def to_csv(self) -> str:
        """One row per effect and parameter (``effect,trials,of,share,parameter,n,mean,std,min,max``; an effect
        without parameters has one row with the parameter empty), then the nominal parameters (effect ``nominal``)."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["effect", "trials", "of", "share", "parameter", "n", "mean", "std", "min", "max"])
        for e in self.recurring():
            head = [e["effect"], e["count"], e["of"], f"{e['share']:.4g}"]
            for k, s in e["parameters"].items() or [("", None)]:
                w.writerow(head + ([k] + [_g(s[c]) for c in ("n", "mean", "std", "min", "max")] if s else ["", "", "", "", "", ""]))
        n = len(self.diagnosed)
        for k, s in self.nominal_spread().items():
            w.writerow(["nominal", n, n, "1"] + [k] + [_g(s[c]) for c in ("n", "mean", "std", "min", "max")])
        return buf.getvalue()

    def to_pandas(self):  # noqa: ANN201 - pandas is optional
        """:meth:`to_csv`'s table as a DataFrame: one row per effect and parameter, then the nominal parameters.

        Examples
        --------
        >>> rec = {"trial": "a", "status": "ok", "verdict": {"effect": "offset"},
        ...        "effects": [{"effect": "offset", "parameters": {"offset.y": 0.05}}], "nominal": {}}
        >>> df = Trials("m", [rec, {**rec, "trial": "b"}]).to_pandas()  # doctest: +SKIP
        >>> df[["effect", "trials", "parameter", "mean"]].values.tolist()  # doctest: +SKIP
        [['offset', 2, 'offset.y', 0.05]]
        """
        require_pandas("Trials.to_pandas()")
        import pandas as pd

        return pd.read_csv(io.StringIO(self.to_csv()))

    def summary(self) -> str:
        """The table ``phs diagnose`` prints for several recordings."""
        rec = self.recurring()
        failed = [r for r in self.records if r.get("status") == "failed"]
        refused = [r for r in self.records if r.get("status") == "refused"]
        lines = [f"Diagnoses of {self.system!r} over {len(self.records)} trials ({self.ran} run now, "
                 f"{len(self.records) - self.ran} resumed): {self._headline().split('; ', 1)[-1]}"]
        if self.shared:
            lines.append("Shared by every trial (fitted jointly first): "
                         + ", ".join(f"{k} = {v:.6g}" for k, v in self.shared["shared"].items()))
        rows = [("effect", "trials", "parameter", "mean", "std", "min", "max")]
        for e in rec:
            first = [e["effect"], f"{e['count']}/{e['of']}"]
            for k, s in e["parameters"].items() or [("", None)]:
                rows.append(tuple(first + ([k, _g(s["mean"]), _spread(s), _g(s["min"]), _g(s["max"])] if s else [""] * 5)))
                first = ["", ""]
        first = ["(nominal)", f"{len(self.diagnosed)}/{len(self.diagnosed)}"]
        for k, s in self.nominal_spread().items():
            rows.append(tuple(first + [k, _g(s["mean"]), _spread(s), _g(s["min"]), _g(s["max"])]))
            first = ["", ""]
        widths = [max(len(str(r[c])) for r in rows) for c in range(len(rows[0]))]
        lines += ["  ".join(str(v).ljust(wd) for v, wd in zip(r, widths, strict=True)).rstrip() for r in rows]
        lines.append("Per trial: " + "; ".join(f"{r['trial']} {_said(r)}" for r in self.records))
        if refused:
            lines.append(f"The nominal model cannot describe {', '.join(r['trial'] for r in refused)}: see each trial's summary.")
        if failed:
            lines.append("Failed: " + "; ".join(f"{r['trial']}: {r.get('error')}" for r in failed))
        return "\n".join(lines)

    def plot(self, path=None, *, ax=None):  # noqa: ANN201 - matplotlib is imported on demand
        """How often each verdict came (left) and each effect parameter by trial relative to its mean across
        the trials (right).

        Examples
        --------
        >>> rec = {"trial": "a", "status": "ok", "verdict": {"effect": "offset"},
        ...        "effects": [{"effect": "offset", "parameters": {"offset.y": 0.05}}], "nominal": {}}
        >>> [a.get_xlabel() for a in Trials("m", [rec, {**rec, "trial": "b"}]).plot().axes]
        ['trials', 'trial']
        """
        fig, grid = panels(ax, 1, 2, figsize=(11, 4), what="Trials.plot")
        left, right = grid[0, 0], grid[0, 1]
        rec = self.recurring()
        left.barh([e["effect"] for e in rec][::-1], [e["count"] for e in rec][::-1], color="tab:blue")
        left.set_xlim(0, max(1, len(self.diagnosed)))
        left.set_xlabel("trials")
        left.set_title(f"verdicts over {len(self.diagnosed)} trials")
        names = [r["trial"] for r in self.diagnosed]
        for e in rec:
            for k, s in e["parameters"].items():
                if s["mean"]:
                    x = [names.index(t) for t in s["trials"]]
                    right.plot(x, np.asarray(s["values"]) / s["mean"], "o-", label=k)
        right.axhline(1.0, color="0.6", lw=0.8)
        right.set_xticks(range(len(names)), names, rotation=30, fontsize=8)
        right.set_xlabel("trial")
        right.set_ylabel("value / mean over the trials")
        if right.get_legend_handles_labels()[0]:
            right.legend(fontsize=7)
        fig.suptitle(f"{self.system}: effects across trials")
        return finish(fig, path, dpi=90)

    def _headline(self) -> str:
        rec = [e for e in self.recurring() if e["effect"] != "none"]
        said = ", ".join(f"{e['effect']} in {e['count']}/{e['of']}" for e in rec) or "no effect missing in any trial"
        return f"{self.system!r}: {len(self.records)} trials; {said}"

    def _table(self) -> tuple[list, list]:
        return ["effect", "trials", "parameters"], [[e["effect"], f"{e['count']}/{e['of']}", ", ".join(e["parameters"])]
                                                    for e in self.recurring()]


def _g(v) -> str:
    return "" if v is None else (f"{v:.6g}" if isinstance(v, float) else str(v))


def _spread(s) -> str:
    if s["n"] < 2:
        return "-"
    rel = f" ({100 * s['std'] / abs(s['mean']):.1f} %)" if s["mean"] else ""
    return f"{s['std']:.3g}{rel}"


def _said(r) -> str:
    if r.get("status") == "failed":
        return "failed"
    v = r["verdict"]
    return f"{v['effect']}" + (f" (confidence {v['confidence']:.2f})" if isinstance(v.get("confidence"), (int, float)) else "")


def _finite(o):
    if isinstance(o, dict):
        return {str(k): _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, float) and not np.isfinite(o):
        return None
    return o
