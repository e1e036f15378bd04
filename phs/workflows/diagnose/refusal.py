"""When the nominal model cannot describe a recording at all, the diagnosis names no effect.

Every effect of the library is a correction attached to the nominal model: its fit starts from the
nominal fit with the effect at zero, and its verdict says what the model left out.  That reading
presumes that the refitted nominal model already follows the recording: that its simulated output has
the recording's shape and, within the reach of its parameters, its scale.  A channel recorded in mm and
read as m, a sign flipped by a sensor's mounting, an input and an output swapped by a wrong ``--map``
break that presumption; the residual is then the recording itself, and whichever candidate best
imitates some of it (often a constant ``offset``) would be named with a confident verdict.

:func:`cannot_describe` is the rule; :func:`refusal` applies it to every fitted channel of the nominal
fit, on the training part and on the validation part, and returns the verdict
:data:`REFUSED` with the figures and what to check, or None when the diagnosis may go on.
"""

from __future__ import annotations

import math

import numpy as np

REFUSED = "model_cannot_describe"
"""The verdict of a diagnosis stopped after the nominal fit: not a physical effect."""

SHAPE_FLOOR = 0.5
"""Least correlation between a channel's simulated and recorded values.  ``ρ²`` is the share of the
recorded variance that the simulated output explains after the best gain *and* offset (the R² of the
affine regression of the recording on the simulation): below ``ρ = 0.5`` not even a quarter, whatever
scale or sensor zero is assumed; a negative ``ρ`` is a response of the opposite sign.
Chosen by that argument and checked on the refusal tests (a unit misread, a flipped sign, a swapped mapping)."""

SCALE_FACTOR = 10.0
"""Largest ratio (either way) between a channel's recorded and simulated standard deviations.  The fit
has already moved the free parameters to match the amplitude as well as their ranges allow; what is
left beyond a decade is what no parameter could reach.  A unit prefix (k, m) is a factor 10³, a
centimetre 10², a bar 10⁵ Pa: after the fit absorbs up to two decades, one is left.
Chosen by that argument, not on a measurement."""

LAG_SAMPLES = 10
"""Most samples by which a channel's response may lead or lag the simulation's and still count as its shape
(:func:`channel_figures`, ``lagged_correlation``): a delay the nominal model lacks (a drive's, a sensor's) is
missing physics the library names, not a wrong unit, sign or mapping; on a channel made of spikes (a
capacitor's current at held voltage steps) a few samples of it take the zero-lag correlation far down (a 2 ms
delay at 2 kHz: 0.40 at lag 0, its spikes four samples apart).  Ten samples is a delay of 10 ms at 1 kHz;
a sign flipped or a mapping swapped is not undone by it unless the recording repeats within 20 samples.
A response spread over a few samples (spikes at the steps of a command that is smooth elsewhere, each late by
the delay) matches neither at one lag: its course over ±LAG_SAMPLES (a moving mean of 2 LAG_SAMPLES + 1
samples, ``smoothed_correlation``) is compared too (the 2 ms delay at 2 kHz on the electrostatic actuator's
current: 0.40 at lag 0, 0.38 at lag 4, 0.72 smoothed).
Chosen on that lab case (``bench/diagnose.py --lab``, seed 1)."""

STILL = 1e-6
"""A simulated channel whose standard deviation is below this share of its own RMS value stays at rest
(at the integrator's tolerance, 1e-7 to 1e-8, not above): a closed chamber that holds its pressure.  Its
response says nothing about units or signs; what the recording does beyond a level is the missing
physics itself (a leak), and the diagnosis goes on.  Chosen by the integrator's tolerance, not on a measurement."""


def channel_figures(recorded, simulated) -> dict:
    """Figures of one channel of a fitted model on one window: ``correlation`` of the simulated with the
    recorded values (NaN when either is constant), ``spread_ratio`` (standard deviation recorded /
    simulated; ``inf`` when the simulation is constant, NaN when the recording is: a flat channel holds
    nothing to describe) and ``still`` (the simulation stays at rest, :data:`STILL`).

    Examples
    --------
    >>> t = np.linspace(0, 1, 201)
    >>> f = channel_figures(1000 * np.sin(2 * np.pi * t), np.sin(2 * np.pi * t))
    >>> round(f["correlation"], 3), round(f["spread_ratio"]), f["still"]
    (1.0, 1000, False)
    """
    y, s = np.asarray(recorded, float), np.asarray(simulated, float)
    sy, ss = float(np.std(y)), float(np.std(s))
    rms = float(np.sqrt(np.mean(s**2)))
    still = ss <= STILL * rms or rms == 0.0
    corr = float(np.corrcoef(y, s)[0, 1]) if sy > 0 and ss > 0 and not still else math.nan
    ratio = math.nan if sy == 0 else (sy / ss if ss > 0 and not still else math.inf)
    lagged, lag, smoothed = corr, 0, corr
    if not math.isnan(corr) and len(y) > 4 * LAG_SAMPLES:
        box = np.ones(2 * LAG_SAMPLES + 1) / (2 * LAG_SAMPLES + 1)  # the course over ±LAG_SAMPLES
        ys, ss_ = np.convolve(y, box, mode="valid"), np.convolve(s, box, mode="valid")
        if np.std(ys) > 0 and np.std(ss_) > 0:
            smoothed = float(np.corrcoef(ys, ss_)[0, 1])
        for k in range(1, LAG_SAMPLES + 1):  # the recording later than the simulation (k > 0) or earlier
            for a, b, kk in ((y[k:], s[:-k], k), (y[:-k], s[k:], -k)):
                if np.std(a) > 0 and np.std(b) > 0:
                    c = float(np.corrcoef(a, b)[0, 1])
                    if c > lagged:
                        lagged, lag = c, kk
    return {"correlation": corr, "spread_ratio": ratio, "still": bool(still), "lagged_correlation": lagged, "lag": lag,
            "smoothed_correlation": smoothed}


def cannot_describe(figures: dict) -> list[str]:
    """Why a nominal model's fitted channel cannot describe the recording (empty: it can).

    ``"shape"``: the correlation of simulated and recorded values is below :data:`SHAPE_FLOOR` (negative:
    opposite sign).  ``"scale"``: their standard deviations differ by more than :data:`SCALE_FACTOR`.  A
    simulation at rest (``still``) is never refused: the recording's motion is then what is missing.

    Why these figures and not the NRMSE fit.  The fit mixes three things: shape, scale and level.  The
    level is a sensor's zero, which the library names (``offset``), and a model at rest scores a fit of
    0 % against any recording while being right about everything it describes (the leak-free chambers of
    ``docs/studies/diagnosis.md`` (the pneumatic actuator) score 0 % and are diagnosed ``leakage``).  Shape and scale are left:
    after the fit no single effect of the library can turn a response around or multiply it by a decade,
    while a wrong unit, sign or mapping does exactly that.  The thresholds sit far from every diagnosis
    the project has: the nominal fits of the real recordings (Silverbox windows, Bouc-Wen, cascaded tanks,
    seal friction, EMPS) have correlations 0.93-1.00 and spread ratios 0.96-1.11 on training and
    validation; the fourteen 3 s concealed cases of ``examples/concealed_effects.py`` correlations
    0.98-1.00 and ratios 0.95-1.10; the six closed-loop cases of ``examples/concealed_loops.py``
    correlations 0.78-1.00 (a friction absorbed by the damping, on validation) and ratios 0.87-1.34.
    Against them, a mass-spring-damper read in mm as m
    has ratio 125 (1251 with the stiffness alone free), with its sign flipped a validation correlation of
    -0.88, with input and output swapped a training correlation of 0.21
    (``tests/workflows/test_diagnose_refuses.py``).

    Examples
    --------
    >>> t = np.linspace(0, 1, 201); y = np.sin(2 * np.pi * 3 * t) + 0.3 * np.sin(2 * np.pi * 7 * t)
    >>> cannot_describe(channel_figures(y + 5.0, 0.8 * y))      # a level and 20 % of amplitude missing
    []
    >>> cannot_describe(channel_figures(1000 * y, y))           # read in mm as m
    ['scale']
    >>> cannot_describe(channel_figures(-y, 0.5 * y))           # sign flipped
    ['shape']
    >>> cannot_describe(channel_figures(y, np.full_like(y, 2.0)))   # a model at rest
    []
    >>> cannot_describe(channel_figures(np.zeros_like(y), y))      # a flat recording: nothing to describe
    []
    >>> spikes = np.zeros(400); spikes[::50] = 1.0                  # a current made of spikes, 4 samples late
    >>> f = channel_figures(np.roll(spikes, 4), spikes)
    >>> round(f["correlation"], 2), round(f["lagged_correlation"], 2), f["lag"], cannot_describe(f)
    (-0.02, 1.0, 4, [])
    """
    if figures["still"]:
        return []
    out = []
    rho = figures["correlation"]
    # a response the right way round that only comes a few samples late or early has the recording's shape
    # (LAG_SAMPLES); a negative one has the opposite sign whatever its lag
    shifted = max(figures.get("lagged_correlation", rho), figures.get("smoothed_correlation", rho))
    if not math.isnan(rho) and rho < SHAPE_FLOOR and (rho <= -SHAPE_FLOOR or not shifted >= SHAPE_FLOOR):
        out.append("shape")
    r = figures["spread_ratio"]
    if r > SCALE_FACTOR or r < 1.0 / SCALE_FACTOR:
        out.append("scale")
    return out


def _unit(system, name: str) -> str:
    for group in (system.measured, system.inputs):
        for m in group:
            if m.name == name:
                return str(m.unit)
    return "?"


def _checks(system, rec, ch: str, reasons: list, figs: dict) -> list[str]:
    """What to check for channel ``ch``, in words, most likely first."""
    col = rec.columns.get(ch, ch)
    unit = _unit(system, ch)
    inputs = ", ".join(f"{rec.columns.get(n, n)} [{_unit(system, n)}]" for n in system.input_names) or "none"
    out = []
    if "shape" in reasons and figs["correlation"] <= -SHAPE_FLOOR:
        out.append(f"the sign of column {col!r} and of the model's input map (recorded and simulated move in opposite directions)")
    if "scale" in reasons:
        out.append(f"the unit of column {col!r} against the model's {unit!r} and those of the input columns ({inputs}) "
                   "(--scale COLUMN=FROM:TO; a unit prefix is a factor 10^3)")
        out.append("how the input columns are read between samples (held or straight lines: --hold COLUMN=zoh|linear; "
                   "a step read where the source ramped drives spikes through a derivative)")
    if "shape" in reasons:
        out.append(f"the --map mapping (is {col!r} the model's {ch!r}, are the inputs {inputs} the right columns?)")
        out.append("the time column (--time) and its unit (s)")
    out.append("the model's structure, sign and scale parameters")
    return out


def refusal(nominal, data) -> dict | None:
    """The verdict :data:`REFUSED` when some fitted channel of the nominal fit ``nominal`` (a
    :class:`~phs.workflows.diagnose.hypotheses.Scored`) cannot describe the recording by
    :func:`cannot_describe`, on the training part or the validation part of ``data``; None otherwise.

    The verdict carries ``cannot_describe``: per refused channel its training and validation fit %,
    correlation and spread ratio, the reasons and the checks; its ``explanation`` says it in words.

    Examples
    --------
    >>> from codegen import simulate
    >>> from systems.examples import rc_circuit
    >>> from phs.workflows.recording import Recording
    >>> from phs.workflows.diagnose.hypotheses import Data
    >>> from phs.workflows.diagnose.nominal import fit_nominal
    >>> t = np.linspace(0, 0.02, 401); u = np.where((t % 0.01) > 0.005, 1.0, 0.0)
    >>> y = simulate(rc_circuit(), t, u={"U": u})["v_C"]
    >>> rec = Recording.from_arrays(t, {"U": u, "v_C": -y})          # the probe's leads swapped
    >>> h, data = fit_nominal(rc_circuit(), Data(rec, rec, np.ones(401, bool), None, ["v_C"], ["R.R"], {}, [], None))
    >>> v = refusal(h, data)
    >>> v["effect"], v["cannot_describe"][0]["channel"], v["cannot_describe"][0]["reasons"]
    ('model_cannot_describe', 'v_C', ['shape'])
    """
    rec, val, mask = data.recording, data.validation, data.val_mask
    sims = nominal.simulated.get("validation") or {}
    refused = []
    for ch in data.outputs:
        y = np.asarray(rec[ch], float)
        train = channel_figures(y, y - np.asarray(nominal.residuals[ch], float))
        valid = (channel_figures(np.asarray(val[ch], float)[mask], np.asarray(sims[ch], float)[mask])
                 if ch in sims and np.count_nonzero(mask) > 2 else None)
        on_train = cannot_describe(train)
        on_valid = cannot_describe(valid) if valid is not None else []
        reasons = on_train + [r for r in on_valid if r not in on_train]
        worst = train if on_train else valid
        if not reasons:
            continue
        refused.append({
            "channel": ch, "column": rec.columns.get(ch, ch), "unit": _unit(nominal.system, ch), "reasons": reasons,
            "fit_percent": nominal.fit_percent[ch], "validation_fit_percent": nominal.validation_fit_percent[ch],
            "correlation": train["correlation"], "spread_ratio": train["spread_ratio"],
            "validation_correlation": valid["correlation"] if valid else None,
            "validation_spread_ratio": valid["spread_ratio"] if valid else None,
            "window": "training" if worst is train else "validation",
            "checks": _checks(nominal.system, rec, ch, reasons, worst)})
    if not refused:
        return None
    return {"effect": REFUSED, "effects": [], "explanation": explanation(refused), "confidence": 1.0, "score": 1.0,
            "failed": [], "explained_share": 0.0, "residual_above_noise": True, "cannot_describe": refused}


def _channel_sentence(c: dict) -> str:
    w = "" if c["window"] == "training" else "validation "
    rho = c["correlation"] if c["window"] == "training" else c["validation_correlation"]
    ratio = c["spread_ratio"] if c["window"] == "training" else c["validation_spread_ratio"]
    return (f"{c['channel']}: nominal fit {c['fit_percent']:.1f} % (training) / {c['validation_fit_percent']:.1f} % (validation), "
            f"{w}recorded spread {ratio:.3g} times the simulated, {w}correlation {rho:+.2f}")


def explanation(refused: list) -> str:
    """The refusal in words: the figures of each refused channel and what to check."""
    parts = []
    for c in refused:
        parts.append(_channel_sentence(c) + "; check " + "; ".join(c["checks"]) + ".")
    return ("The nominal model cannot describe the recording at all, so no missing effect is named: "
            + " ".join(parts) + " A model that misses one effect still follows the recording's shape and scale "
            f"(correlation >= {SHAPE_FLOOR}, spreads within a factor {SCALE_FACTOR:g}); this points at units, mappings or the model.")


def headline(verdict: dict, source: str = "the recording") -> str:
    """One line for the command line: the refused channels with their figures and the first check.

    Examples
    --------
    >>> c = {"channel": "x", "column": "x", "unit": "m", "reasons": ["scale"], "fit_percent": -3.2,
    ...      "validation_fit_percent": -7.0, "correlation": 0.93, "spread_ratio": 125.0, "validation_correlation": 0.7,
    ...      "validation_spread_ratio": 120.0, "window": "training", "checks": ["the unit of column 'x'"]}
    >>> line = headline({"cannot_describe": [c]}, "run.csv")
    >>> line.startswith("the nominal model cannot describe run.csv, no effect named: x: nominal fit -3.2 %")
    True
    >>> "recorded spread 125 times the simulated, correlation +0.93; check the unit of column 'x'" in line
    True
    """
    return (f"the nominal model cannot describe {source}, no effect named: "
            + " | ".join(f"{_channel_sentence(c)}; check {c['checks'][0]}" for c in verdict["cannot_describe"]))


def summary(d) -> str:
    """The text summary of a refused :class:`~phs.workflows.diagnose.result.Diagnosis`: the verdict, the
    explanation and the nominal fit of every channel."""
    lines = [f"Diagnosis of {d.system.name!r} ({d.seconds:.1f} s): verdict {REFUSED} (no effect named)",
             "  " + d.verdict["explanation"], "  nominal fit % (training / validation):"]
    lines += [f"    {ch}: {d.nominal.fit_percent[ch]:.2f} / {d.nominal.validation_fit_percent[ch]:.2f}" for ch in d.outputs]
    return "\n".join(lines)
