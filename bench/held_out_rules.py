"""Benchmark: the diagnosis' decision rules switched off one at a time, on the held-out concealed cases.

Every decision threshold of the diagnosis must pay on concealed cases it was not chosen on
(``docs/reference/diagnosis_constants.md``).  The held-out cases are the concealed effects of
``examples/concealed_effects.py`` at noise seed :data:`phs.workflows.diagnose.calibration.HELD_OUT_SEED`
(validation seed + 100), 3 s recordings, each effect at 0.35, 0.6 and 1 times its tuned strength and the
control ``none`` at 1 (40 cases), diagnosed as ``bench/calibrate_confidence.py`` does
(``electrostatic_actuator()``, ``NOMINAL_FREE``, ``n_jobs=1``).  This script diagnoses them once with the
constants as they are (``baseline``) and once per configuration of :data:`RULES`: one constant set to another
value, by setting the module attribute it is read from (and every module that imports it by name,
:data:`RULES`) in a fresh worker process per case.

    python bench/held_out_rules.py                                  # every rule, every value of RULES
    python bench/held_out_rules.py --rules WORSE_Z,DISCOVER_BELOW   # these rules' values (and the baseline)
    python bench/held_out_rules.py --rules RIVAL_MARGIN=0.5         # one value of one rule
    python bench/held_out_rules.py --rules baseline --dir other     # the baseline alone
    python bench/held_out_rules.py --sizes 0.6,1 --jobs 2 --dir runs/held_out
    python bench/held_out_rules.py --report                         # the table of what the files hold
    python bench/held_out_rules.py --rules WORSE_Z=inf --effects offset,none --sizes 1 --seconds 1   # smoke test

Each configuration's diagnoses go to ``DIR/<configuration>.jsonl`` (default ``DIR``: ``held_out_rules``),
one line per case, written atomically after each case; a case the file already holds is not run again (a
stopped run resumes).  A row records the case, the verdict, its rightness, the reported confidence, the
final model's validation fit per channel, the stages it reached beyond the library rounds (``reached``:
``["discovery"]`` when a correction outside the library was looked for, as the accepted effects' rival
too), the diagnosis' CPU and wall seconds, the 1-min load average as it started, the configuration's values
and the ``phs`` package it ran (``source``).  A rule read only inside such a stage (:data:`REACH`: the
discovery's dictionary, families and selection) is run only on the cases whose baseline row reached it:
on the others the diagnosis never reads it, and every computation is the baseline's.

Per configuration it prints one row of a markdown table: the cases run, the verdicts right (the named
effect is the truth's; ``none`` for the control), the verdicts exact (the named effects are the truth's
alone: a correction or a second effect named beside the truth's is not), the Brier score of the reported confidence (mean squared
difference between confidence and rightness: :func:`phs.workflows.diagnose.calibration.brier`), the mean
validation fit of the final model (NRMSE fit % averaged over position and current and over the cases),
the mean CPU seconds per case, and the verdicts whose effects differ from the baseline's (by
:func:`~phs.workflows.diagnose.calibration.case_name`).  The figures of a configuration are compared with
the baseline's on the cases both hold (``common``).  The last line is one JSON object: ``seed``, ``sizes``,
``seconds``, ``cases`` and per configuration (``configurations``) ``values``, ``cases``, ``right``,
``exact``, ``brier``, ``validation_fit``, ``cpu_seconds``, ``wall_seconds``, ``changed`` (case: baseline verdict →
this one) and the baseline's ``right``, ``exact``, ``brier``, ``validation_fit``, ``cpu_seconds`` on the common cases
(``baseline_on_common``).

The values of :data:`RULES` switch each rule off where the code path allows it (read in the comments
there), and some a second way.  ``result.MIN_VALIDATION_GAIN`` (the scale of a ``none`` verdict's raw
score) and ``report.MIN_VALIDATION_GAIN`` (a line in a figure) are left as they are: they are not the
acceptance rule, and a zero would divide by zero.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import math
import multiprocessing as mp
import os
import resource
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

SIZES = (0.35, 0.6, 1.0)
D = "phs.workflows.diagnose"
RULES: dict = {
    # discovery after accepted effects runs when they explain less than this share: inf, always (a
    # correction on top, so the rival from the nominal model never runs); 0, never (the rival runs instead)
    "DISCOVER_BELOW": ((f"{D}.run",), (math.inf, 0.0)),
    # a rival correction replaces the library effect when its validation residual is this share lower
    # (and BIC lower by MIN_BIC_GAIN): 0, the margin off; 1, a rival never replaces (residual below zero)
    "RIVAL_MARGIN": ((f"{D}.run",), (0.0, 1.0)),
    # refits run to REFIT_FTOL for the best TIGHT_REFITS screened, the rest to RIVAL_FTOL: 3 (refit_top),
    # every refit tight (the rule off); 1, only the best
    "TIGHT_REFITS": ((f"{D}.screening",), (3, 1)),
    # hypotheses within this relative margin of the best (validation and training residual) are equally
    # good and the simplest wins: 0, the best alone (the rule off); 0.1, a wider margin
    "SUFFICIENT_MARGIN": ((f"{D}.ranking", D), (0.0, 0.1)),
    # accepted only with a validation residual this share lower: -inf, no validation test (the rule off);
    # 0, any decrease (the margin off).  Not result.MIN_VALIDATION_GAIN: the none score's scale
    "MIN_VALIDATION_GAIN": ((f"{D}.ranking", D), (-math.inf, 0.0)),
    # accepted only with a training BIC this much lower (also discovery's terms, the rival, the library's
    # place next to a correction, and the floor of a none's confidence): -inf, no BIC test; 0, any decrease
    "MIN_BIC_GAIN": ((f"{D}.ranking", f"{D}.result", D), (-math.inf, 0.0)),
    # a hysteresis loop below this share of the stroke is friction (deferred refit, friction preferred):
    # 0, never (the rule off); 0.2, wider
    "FRICTION_LIKE": ((f"{D}.ranking", f"{D}.screening", D), (0.0, 0.2)),
    # a channel's validation fit is lowered when its RSS rises beyond WORSE_Z noise deviations: inf,
    # never (the rule off); 1, stricter
    "WORSE_Z": ((f"{D}.ranking",), (math.inf, 1.0)),
    # a significant finding points at a family from this share of the residual: 0, every significant one
    # (the threshold off); inf, none (no pointer: no refit of the located family, no disagreement)
    "POINTER_SHARE": ((f"{D}.consistency",), (0.0, math.inf)),
    # the confidence of a verdict that names nothing of the pointed family is scaled by this: 1, not scaled
    "DISAGREE_FACTOR": ((f"{D}.consistency",), (1.0,)),
    # the constants that trade time: the cheaper value first (a held-out figure for the time saved), then
    # a costlier one (what the time buys).  Gauss-Newton evaluations of a screening fit
    "SCREEN_ITER": ((f"{D}.hypotheses",), (3, 8)),
    # starts a screening fit runs from (the cheapest at their start)
    "SCREEN_STARTS": ((f"{D}.hypotheses",), (1, 4)),
    # least relative tolerance of a screening fit's integration
    "SCREEN_RTOL": ((f"{D}.hypotheses",), (1e-5, 1e-8)),
    # the nominal fit's stopping point (relative cost decrease)
    "NOMINAL_FTOL": ((f"{D}.nominal",), (1e-4, 1e-8)),
    # rounds of an input element's joint fit (alternating its search and the model's refit)
    "ELEMENT_ROUNDS": ((f"{D}.hypotheses",), (1, 16)),
    # noise surrogates per channel behind the located findings' thresholds
    "N_SURROGATES": ((f"{D}.locate._common", f"{D}.locate", f"{D}.locate.features"), (50, 200)),
    # the decisions of every case: a located finding's significance (the surrogates' quantile)
    "NULL_QUANTILE": ((f"{D}.locate._common", f"{D}.locate", f"{D}.locate.features"), (0.95, 0.999)),
    # a residual RMS above this many noise levels is structure (beside the whiteness test): inf, the RMS
    # test off (colour alone); 1.2, stricter
    "STRUCTURED": ((f"{D}.mismatch",), (math.inf, 1.2)),
    # a coloured residual counts only from this share of the channel's spread: 0, always; 0.05, coarser
    "RELEVANT": ((f"{D}.run",), (0.0, 0.05)),
    # two nominal starts agree within this share of the cost: a second start's work against a missed one
    "AGREE": ((f"{D}.nominal",), (0.001, 0.1)),
    # the plain least-squares check's values replace the nominal fit's when this share lower: 0, any
    # decrease; inf, never (the check off)
    "CHECK_MARGIN": ((f"{D}.nominal",), (0.0, math.inf)),
    # the nominal fit's global step: points tried
    "GLOBAL_SAMPLES": ((f"{D}.nominal",), (4, 16)),
    # a reported refit's stopping point
    "REFIT_FTOL": ((f"{D}.hypotheses",), (1e-5, 1e-7)),
    # the ranking refits' stopping point
    "RIVAL_FTOL": ((f"{D}.hypotheses",), (1e-3, 1e-6)),
    # an input element's rounds stop below this relative decrease
    "ELEMENT_TOL": ((f"{D}.hypotheses",), (1e-2, 1e-4)),
    # an input element's bounded refinement: evaluations of a joint fit's, of a screening fit's
    "REFINE_ITER": ((f"{D}.element_search", f"{D}.hypotheses"), (4, 16)),
    "SCREEN_REFINE_ITER": ((f"{D}.element_search", f"{D}.hypotheses"), (2, 8)),
    # a later round's first bracket around an element's earlier value (share of a grid step)
    "LOCAL_SHARE": ((f"{D}.element_search",), (0.0625, 0.25)),
    # moves tried beyond a round's end (grid steps)
    "EXTRAPOLATE": ((f"{D}.element_search",), ((1.0,), (1.0, 2.0, 4.0, 8.0, 16.0))),
    # discovery's constants (run only on the cases whose baseline diagnosis reached discovery: REACH)
    "SCREEN_TOP": ((f"{D}.discover.selection",), (1, 5)),
    "MAX_TERMS": ((f"{D}.discover.selection",), (1, 5)),
    "NUDGE": ((f"{D}.discover.selection",), (0.005, 0.08)),
    "THETA_MAX": ((f"{D}.discover.dictionary",), (10.0, 100.0)),
    "WIDTH": ((f"{D}.discover.dictionary",), (0.02, 0.1)),
    "ENGAGE_AT": ((f"{D}.discover.dictionary",), ((0.45,), (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8))),
    "SENSITIVITY": ((f"{D}.discover.dictionary",), ((1e-4, 1e6, 0.1), (1e-4, 1e6, 10.0))),
    "TAU_SPAN": ((f"{D}.discover.dictionary",), ((0.1, 20.0), (0.005, 500.0))),
    "MODE_POINTS": ((f"{D}.discover.families",), (3, 9)),
    "MODE_SPAN": ((f"{D}.discover.families",), (2.0, 8.0)),
    "MODE_ZETA": ((f"{D}.discover.families",), ((0.005, 1.0, 0.2),)),
    "DRIFT_TAU": ((f"{D}.discover.families",), ((0.05, 20.0, 1.0),)),
    "LIMIT_START": ((f"{D}.discover.families",), (0.5, 2.0)),
    "KNEE": ((f"{D}.discover.families", f"{D}.discover.emission"), (0.05,)),
}
"""Per rule: the modules whose attribute of that name is set (where it is defined, and every module that
imports it by name and reads it), and the values tried."""
REACH = {rule: "discovery" for rule in ("SCREEN_TOP", "MAX_TERMS", "NUDGE", "THETA_MAX", "WIDTH", "ENGAGE_AT", "SENSITIVITY",
                                         "TAU_SPAN", "MODE_POINTS", "MODE_SPAN", "MODE_ZETA", "DRIFT_TAU", "LIMIT_START", "KNEE")}
"""Rules read only inside a stage that not every diagnosis reaches: their configurations run only on the
cases whose baseline diagnosis reached it (``reached`` of its row), since on the others every computation,
and so the verdict, is the baseline's."""
LEFT = {("MIN_VALIDATION_GAIN", f"{D}.result"), ("MIN_VALIDATION_GAIN", f"{D}.report")}
"""Modules holding a rule's constant by name that are deliberately not set (see the module docstring)."""


def _shown(v) -> str:
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


def configurations(spec: str | None) -> list[tuple[str, str | None, object]]:
    """``(name, rule, value)`` of the configurations ``spec`` asks for (``RULE`` or ``RULE=VALUE``, comma
    separated; ``baseline``: no other; None: every value of every rule), the baseline first.

    Examples
    --------
    >>> [name for name, _, _ in configurations("WORSE_Z,TIGHT_REFITS=2")]
    ['baseline', 'WORSE_Z=inf', 'WORSE_Z=1', 'TIGHT_REFITS=2']
    >>> configurations("baseline")
    [('baseline', None, None)]
    """
    out = [("baseline", None, None)]
    items = list(RULES) if not spec else [s.strip() for s in spec.split(",") if s.strip()]
    for item in items:
        if item == "baseline":  # the baseline alone (it is always run)
            continue
        rule, _, value = item.partition("=")
        if rule not in RULES:
            raise SystemExit(f"--rules: unknown rule {rule!r}; known: {', '.join(RULES)}")
        default = RULES[rule][1][0]
        values = RULES[rule][1] if not value else (type(default)(float(value)) if isinstance(default, int) else float(value),)
        out += [(f"{rule}={_shown(v)}", rule, v) for v in values]
    return list(dict.fromkeys(out))


def cases(sizes) -> list[tuple[str, float]]:
    """``(effect, size)`` of the held-out cases: every concealed effect at each of ``sizes``, the control at 1.

    Examples
    --------
    >>> c = cases((0.6, 1.0))
    >>> len(c), c[:2], c[-1]
    (27, [('charge_retention', 0.6), ('charge_retention', 1.0)], ('none', 1.0))
    """
    from examples.concealed_effects import EFFECTS

    return [(e, s) for e in EFFECTS for s in (sizes if e != "none" else (1.0,))]


def _cpu() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _set(rule: str | None, value) -> dict:
    """Set ``rule`` to ``value`` in the modules of :data:`RULES` (imported here); check that no other loaded
    module of the diagnosis still holds the old value by name, except those of :data:`LEFT`."""
    import importlib

    import phs.workflows.diagnose  # noqa: F401  (and with it every module that imports the constants)
    import phs.workflows.diagnose.discover  # noqa: F401
    import phs.workflows.diagnose.report  # noqa: F401

    if rule is None:
        return {}
    modules, _ = RULES[rule]
    old = getattr(importlib.import_module(modules[0]), rule)
    for m in modules:
        setattr(importlib.import_module(m), rule, value)
    stale = [n for n, m in list(sys.modules.items()) if n.startswith(D) and m is not None and (rule, n) not in LEFT
             and n not in modules and getattr(m, rule, value) is old]
    if stale:
        raise RuntimeError(f"{rule} is also imported by name in {', '.join(stale)}: add them to RULES")
    return {rule: _shown(value)}


def run_case(config: str, rule: str | None, value, effect: str, size: float, seconds: float, seed: int) -> dict:
    """One held-out case diagnosed with ``rule`` set to ``value`` (in a fresh worker process)."""
    from examples.concealed_effects import NOMINAL_FREE, generate

    values = _set(rule, value)
    import phs
    import phs.workflows.diagnose.discover as discovery
    from phs.workflows.diagnose import diagnose
    from systems.electrostatic_actuator import electrostatic_actuator

    train, _ = generate(effect, seconds=seconds, seed=seed, size=size)
    val, _ = generate(effect, seconds=seconds, seed=seed + 100, validation=True, size=size)
    calls, found = [], discovery.discover  # which stages the diagnosis reached (REACH): counted, not changed

    def counted(*a, **k):
        calls.append(1)
        return found(*a, **k)

    discovery.discover = counted
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    c0, t0 = _cpu(), time.perf_counter()
    d = diagnose(electrostatic_actuator(), train, validation=val, free=list(NOMINAL_FREE), n_jobs=1)
    wall, cpu = time.perf_counter() - t0, _cpu() - c0
    discovery.discover = found
    fit = {k: round(float(v), 3) for k, v in d.final.validation_fit_percent.items()}
    v = d.verdict
    return {"config": config, "values": values, "effect": effect, "size": size, "seed": seed, "verdict": d.effect,
            "effects": list(v.get("effects") or []), "right": d.effect == effect, "confidence": v["confidence"],
            "score": v.get("score"), "validation_fit": fit,
            "nominal_validation_fit": {k: round(float(x), 3) for k, x in d.nominal.validation_fit_percent.items()},
            "explained_share": round(float(v.get("explained_share", 0.0)), 4),
            "disagrees_with_located": v.get("disagrees_with_located", []), "rival_of": v.get("rival_of"),
            "dropped": v.get("dropped", []), "reached": ["discovery"] if calls else [], "cpu_seconds": round(cpu, 2),
            "seconds": round(wall, 2),
            "load_before": None if load is None else round(load, 2), "source": os.path.dirname(os.path.realpath(phs.__file__))}


def _path(directory: str, config: str) -> str:
    return os.path.join(directory, f"{config}.jsonl")


def _load(path: str) -> list[dict]:
    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as f:
        return [json.loads(ln) for ln in f if ln.strip()]


def _key(r: dict) -> tuple:
    return (r["effect"], float(r["size"]))


def run(configs, todo, directory: str, seconds: float, seed: int, jobs: int) -> None:
    """Diagnose every case of ``todo`` under every configuration that does not hold it yet, ``jobs`` at a
    time, each in a fresh process (``spawn``, one case per process), appending to the configuration's file;
    a rule of :data:`REACH` only on the cases whose baseline row reached its stage."""
    os.makedirs(directory, exist_ok=True)
    rows = {name: _load(_path(directory, name)) for name, _, _ in configs}
    tasks = []
    for name, rule, value in configs:  # the baseline first, then each configuration in turn
        done = {_key(r) for r in rows[name]}
        tasks += [(name, rule, value, e, s) for e, s in todo if (e, float(s)) not in done and rule not in REACH]
    if any(rule in REACH for _, rule, _ in configs):  # only where the baseline reached the rule's stage
        _run_tasks(tasks, rows, directory, seconds, seed, jobs)  # the baseline's rows first: they say what was reached
        tasks = []
        base = {_key(r): r for r in rows["baseline"]}
        if any("reached" not in base.get((e, float(s)), {}) for e, s in todo):
            raise SystemExit(f"{_path(directory, 'baseline')}: its rows do not record the stages they reached (a run "
                             "before that field): run the baseline again in another --dir")
        for name, rule, value in configs:
            if rule in REACH:
                done = {_key(r) for r in rows[name]}
                tasks += [(name, rule, value, e, s) for e, s in todo if (e, float(s)) not in done
                          and REACH[rule] in base[(e, float(s))]["reached"]]
    _run_tasks(tasks, rows, directory, seconds, seed, jobs)


def _run_tasks(tasks, rows, directory, seconds, seed, jobs) -> None:
    from phs.io import write_atomic

    if not tasks:
        return
    print(f"{len(tasks)} diagnoses to run ({jobs} at a time)", flush=True)
    ctx = mp.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx, max_tasks_per_child=1) as ex:
        futs = {ex.submit(run_case, n, r, v, e, s, seconds, seed): n for n, r, v, e, s in tasks}
        for k, f in enumerate(cf.as_completed(futs), 1):
            name = futs[f]
            row = f.result()
            rows[name].append(row)
            write_atomic(_path(directory, name), "".join(json.dumps(r) + "\n" for r in rows[name]))
            print(f"[{k}/{len(tasks)}] {name:<28} {row['effect']}@{row['size']:g}: {row['verdict']} "
                  f"({'right' if row['right'] else 'WRONG'}, confidence {row['confidence']}) cpu {row['cpu_seconds']:.1f} s, "
                  f"wall {row['seconds']:.1f} s, load {row['load_before']}", flush=True)


def _exact(r: dict) -> bool:
    """The verdict names the truth's effect and nothing else (no effect for the control)."""
    return list(r["effects"]) == ([] if r["effect"] == "none" else [r["effect"]])


def _named(r: dict) -> str:
    return "+".join(r["effects"]) or "none"


def _figures(rows: list[dict]) -> dict:
    from phs.workflows.diagnose.calibration import brier

    if not rows:
        return {"cases": 0}
    fits = [sum(r["validation_fit"].values()) / len(r["validation_fit"]) for r in rows]
    return {"cases": len(rows), "right": sum(bool(r["right"]) for r in rows), "exact": sum(_exact(r) for r in rows),
            "brier": round(brier([r["confidence"] for r in rows], [r["right"] for r in rows]), 4),
            "validation_fit": round(sum(fits) / len(fits), 3),
            "cpu_seconds": round(sum(r["cpu_seconds"] for r in rows) / len(rows), 2),
            "wall_seconds": round(sum(r["seconds"] for r in rows) / len(rows), 2)}


def summary(configs, todo, directory: str, seconds: float, seed: int) -> dict:
    """The table (printed) and the JSON object of the configurations' files, restricted to the cases ``todo``."""
    from phs.workflows.diagnose.calibration import case_name

    wanted = {(e, float(s)) for e, s in todo}
    base = {_key(r): r for r in _load(_path(directory, "baseline")) if _key(r) in wanted}
    out = {"seed": seed, "sizes": sorted({float(s) for _, s in todo}), "seconds": seconds, "cases": len(todo),
           "configurations": {}}
    print("\n| configuration | cases | right | exact | Brier | validation fit % | CPU s / case | verdicts changed against the baseline |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for name, _, _ in configs:
        rows = [r for r in _load(_path(directory, name)) if _key(r) in wanted]
        fig = _figures(rows)
        fig["values"] = rows[0]["values"] if rows else {}
        common = [r for r in rows if _key(r) in base]
        changed = {case_name(r): f"{_named(base[_key(r)])} → {_named(r)}" for r in common
                   if (r["verdict"], r["effects"]) != (base[_key(r)]["verdict"], base[_key(r)]["effects"])}
        if name != "baseline":
            fig["changed"] = changed
            fig["baseline_on_common"] = {k: v for k, v in _figures([base[_key(r)] for r in common]).items()
                                         if k in ("cases", "right", "exact", "brier", "validation_fit", "cpu_seconds")}
        out["configurations"][name] = fig
        if not rows:
            print(f"| {name} | 0 | | | | | | |")
            continue
        b = fig.get("baseline_on_common")
        vs = (f" (baseline on these cases: {b['right']}/{b['cases']}, {b['exact']}, {b['brier']:.3f}, {b['validation_fit']:.2f}, "
              f"{b['cpu_seconds']:.1f})") if b and b["cases"] != len(base) else ""
        said = "—" if name == "baseline" else (", ".join(f"{c}: {w}" for c, w in sorted(changed.items())) or "none")
        print(f"| {name} | {fig['cases']} | {fig['right']}/{fig['cases']} | {fig['exact']}/{fig['cases']} | {fig['brier']:.3f} | "
              f"{fig['validation_fit']:.2f} | "
              f"{fig['cpu_seconds']:.1f} | {said}{vs} |")
    return out


def main(argv=None) -> dict:
    from phs.workflows.diagnose.calibration import HELD_OUT_SEED

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rules", default=None,
                    help="comma-separated RULE or RULE=VALUE, or baseline alone (default: every value of every rule)")
    ap.add_argument("--sizes", default=",".join(f"{s:g}" for s in SIZES), help="strengths of the effects (default 0.35,0.6,1)")
    ap.add_argument("--effects", default=None, help="comma-separated concealed effects (default: every one, and none)")
    ap.add_argument("--seconds", type=float, default=3.0, help="recording length [s] (default 3)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes, one diagnosis each with n_jobs=1 (default 2)")
    ap.add_argument("--dir", default="held_out_rules", help="directory of the JSON-lines files, one per configuration")
    ap.add_argument("--report", action="store_true", help="print the table of what the files hold; run nothing")
    args = ap.parse_args(argv)
    sizes = tuple(float(s) for s in args.sizes.split(","))
    configs = configurations(args.rules)
    todo = cases(sizes)
    if args.effects:
        todo = [(e, s) for e, s in todo if e in args.effects.split(",")]
    if not args.report:
        run(configs, todo, args.dir, args.seconds, HELD_OUT_SEED, args.jobs)
    out = summary(configs, todo, args.dir, args.seconds, HELD_OUT_SEED)
    print(json.dumps(out, ensure_ascii=False))
    return out


if __name__ == "__main__":
    main()
