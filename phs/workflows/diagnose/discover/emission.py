"""A discovered correction as a component the user keeps: the Python source of a small candidate class.

:func:`source` writes a module holding one :class:`components.candidates.Candidate` subclass whose
``augment`` attaches the fitted terms (coefficients and scales as parameter defaults, with units) with
the library's public building blocks (:func:`components.candidates.add_energy`,
:func:`components.candidates.add_damping`), and ``FITTED``: the nominal parameters as refitted with it.
``cls().augment(system.with_params(FITTED), where, None).system`` is the model it extends (the diagnosed
model, with any accepted library effect attached) with the correction, and simulates as the fitted one did.
"""

from __future__ import annotations

import re

from phs.io import write_atomic
from phs.workflows.diagnose.discover.dictionary import EFFECT, C, Discovered, _slug, shape
from phs.workflows.diagnose.discover.families import CLOCK_SMOOTH, KINDS, KNEE, LIMIT_FAST, state_infos

_FUNCTIONS = ("cosh", "exp", "log", "sqrt")
_WHAT = {"energy": "an added energy", "damping": "an added dissipation R >= 0",
         "memory": "a dissipation R >= 0 with its own heat state (fed by the power it dissipates)",
         "input": "a state-dependent input gain (a modulated transformer)", "sensor": "a correction of a measured output",
         "mode": "a second mass joined by a spring and a damper (two new states)",
         "drift": "a parameter scaled by a slow clock state of its own",
         "limit": "a limit on the flow through an input (a nonlinear resistance in series with it)"}


def _class_name(system_name: str) -> str:
    return "Discovered" + "".join(w.capitalize() for w in re.split(r"[^0-9A-Za-z]+", system_name) if w)


def _param(p, indent: str) -> str:
    rng = f", ({p.range[0]!r}, {p.range[1]!r})" if p.range is not None else ""
    return f"{indent}Param({p.name!r}, {p.value!r}, {p.unit!r}, {p.description!r}{rng}, positive={bool(p.positive)}),"


def source(discovery, description: str = "", share: float | None = None) -> str:
    """Python source of a candidate class reproducing ``discovery``'s fitted correction.

    Parameters
    ----------
    discovery : Discovery
        A discovery that found a correction.
    description : str
        Its description in words (the class docstring).
    share : float, optional
        The share of the residual it explains (stated in the docstring).

    Returns
    -------
    str
    """
    h = discovery.scored
    base = discovery.base.system
    terms = list(discovery.terms)
    cand = Discovered(terms, discovery.values)
    thetas = cand.params()
    scales = {}
    for t in terms:
        for p in t.scales(base):
            scales.setdefault(p.name, p)
    name = _class_name(base.name)
    fitted = {k: float(v) for k, v in h.values.items() if k in base.param_names}
    body = []
    index = {p.name: k for k, p in enumerate(thetas)}
    for k, t in enumerate(terms):
        expr = shape(t).subs({C: t.c}) if t.shape.startswith("engage") else shape(t)
        own = [f"theta[{index[n]}]" for n in t.parameters]
        new = f"[{', '.join(own)}]" + (" + scale" if k == 0 else "")
        th = f"theta[{index[t.parameter]}].symbol"
        sym = {key: repr(f"{EFFECT}.{_slug(t.state)}_{key}") for key in ("scale", "energy", "effort", "damping", "heat", "level")}
        sym["via"] = repr(f"{EFFECT}.{_slug(t.via)}_scale")
        body.append(f"        # {t.label}: {_WHAT[t.kind]}")
        if t.kind in KINDS:
            body.extend(_added(t, base, own, th, new, k))
            continue
        if t.via:
            body.append(f"        x = state({t.via!r}) / S[{sym['via']}]")
        if t.kind == "energy":
            body.append(f"        z = state({t.state!r}) / S[{sym['scale']}]")
            body.append(f"        term = {th} * S[{sym['energy']}] * ({expr})")
            body.append(f"        s = add_energy(s, {f'{EFFECT}@{t.label}'!r}, term, {new}, self.effect)")
        elif t.kind == "damping":
            body.append(f"        e = s.grad_H[s.state_names.index({t.state!r})] / S[{sym['effort']}]")
            body.append(f"        term = {th} * S[{sym['damping']}] * ({expr})")
            body.append(f"        s = add_damping(s, {t.state!r}, term, {new}, {f'{EFFECT}.{k}'!r})")
        elif t.kind == "input":
            body.append(f"        s = scale_input(s, {t.state!r}, 1 + {th} * ({expr}), {new}, self.effect)")
        elif t.kind == "sensor":
            body.append(f"        s = correct_measured(s, {t.state!r}, {th} * S[{sym['level']}] * ({expr}), {new}, self.effect)")
        else:
            E_h = t.heat_scale
            body.append(f"        heat = StateInfo({t.heat_state!r}, 'J', ({-1e3 * E_h!r}, {1e3 * E_h!r}), "
                        f"{f'heat dissipated on {t.state} not yet relaxed'!r}, 'C', {E_h!r}, self.effect)")
            body.append(f"        s = add_heated_dissipation(s, {t.state!r}, {th} * S[{sym['damping']}], heat, {own[1]}, {own[2]}, "
                        f"S[{sym['heat']}], {new}, self.effect, {f'{EFFECT}@{t.label}'!r})")
    text = "\n".join(body)
    used = [f for f in _FUNCTIONS if re.search(rf"\b{f}\(", text)]
    main = {t.parameter for t in terms}
    neutral = {p.name: (0.0 if not p.positive else p.range[0]) for p in thetas if p.name in main}
    log = [n for t in terms for n in t.log_parameters]
    x0 = {x: 0.0 for t in terms for x in t.new_states}
    memory = [t for t in terms if t.new_states]
    kinds = {t.kind for t in terms} | {"input" for t in terms if t.shape == "drift_gain"}
    blocks = [b for b, kind in (("add_clock", "drift"), ("add_heated_dissipation", "memory"), ("add_mode", "mode"),
                                ("correct_measured", "sensor"), ("limit_input_current", "limit"), ("scale_input", "input"))
              if kind in kinds]
    lines = [
        f'"""{name}: a correction of {base.name!r} discovered by diagnosis.',
        "",
        *_wrap(description or "A passive correction found by sparse regression over the model's own states."),
        "",
        "Terms (coefficients in units of the state's scale along the fit):",
        "",
        *[f"* ``{t.label}`` ({t.kind}): " + ", ".join(f"{n} = {discovery.values[n]:.6g}" for n in t.parameters) for t in terms],
        "",
        *([f"It explains {100 * share:.0f} % of what the model it extends misses above the noise floor.", ""] if share is not None else []),
        "``FITTED`` holds the parameters of the model it extends (the diagnosed model with any accepted library effect)",
        "as refitted with it; that model with the correction is",
        f"``{name}().augment(system.with_params(FITTED), {terms[0].state!r}, None).system``.",
        '"""',
        "",
        "from __future__ import annotations",
        "",
        *([f"from sympy import {', '.join(used)}", ""] if used else []),
        "from components.candidates import Augmentation, Candidate, add_damping, add_energy",
        *(["from components.candidates.maps import " + ", ".join(blocks)] if blocks else []),
        "from phs import Param" + (", StateInfo" if memory else ""),
        "",
        f"FITTED = {fitted!r}",
        '"""The diagnosed model\'s parameters as refitted together with the correction."""',
        "",
        "",
        f"class {name}(Candidate):",
        f'    """{_first_sentence(description)}"""',
        "",
        f"    effect = {EFFECT!r}",
        f"    summary = {_first_sentence(description)!r}",
        '    kind = "structure"',
        "",
        "    def attach_points(self, system):",
        f"        return [{terms[0].state!r}]",
        "",
        "    def augment(self, system, where, scales=None):",
        "        self._check_where(system, where)",
        "        scale = [",
        *[_param(p, "            ") for p in scales.values()],
        "        ]",
        "        theta = [",
        *[_param(p, "            ") for p in thetas],
        "        ]",
        "        S = {p.name: p.symbol for p in scale}",
        "",
        "        def state(name):",
        "            return system.states[system.state_names.index(name)].symbol",
        "",
        "        s = system",
        text,
        f"        return Augmentation(self.effect, where, {' + '.join(t.label for t in terms)!r}, s, [p.name for p in theta],",
        f"                            {{p.name: p.range for p in theta}}, {log!r}, {x0!r}, neutral={neutral!r})",
        "",
    ]
    return "\n".join(lines)


def _state(info) -> str:
    return (f"StateInfo({info.name!r}, {info.unit!r}, ({float(info.range[0])!r}, {float(info.range[1])!r}), {info.description!r}, "
            f"{info.kind!r}, {float(info.scale)!r}, self.effect)")


def _added(t, base, own: list, th: str, new: str, k: int) -> list[str]:
    """Source lines attaching a term that appends states (:mod:`~phs.workflows.diagnose.discover.families`),
    as :func:`~phs.workflows.diagnose.discover.attach` does."""
    slug, b = _slug(t.state), t.parameter.split(".theta_", 1)[1]
    infos = state_infos(t, base)
    label = f"{EFFECT}@{t.label}"
    if t.kind == "mode":
        return [f"        added = [{_state(infos[0])},", f"                 {_state(infos[1])}]",
                f"        s = add_mode(s, {t.state!r}, {th}, {own[1]}.symbol, {own[2]}.symbol, S[{f'{EFFECT}.{slug}_mass'!r}], *added, {new}, "
                f"self.effect, {label!r})"]
    if t.kind == "limit":
        flow, knee, step = (f"S[{f'{EFFECT}.{slug}_{key}'!r}]" for key in ("flow", "knee", "step"))
        return [f"        limit = {flow} / {th}",
                f"        s = limit_input_current(s, {t.state!r}, limit, {knee}, {LIMIT_FAST * KNEE!r} * {step} * limit / {knee}, "
                f"{_state(infos[0])}, {new}, self.effect)"]
    lines = [f"        clock = {_state(infos[0])}",
             f"        s = add_clock(s, clock, {own[1]}.symbol, S[{f'{EFFECT}.{b}_clock_energy'!r}], {new}, self.effect, {label + ':clock'!r})"]
    if t.shape == "drift_stiffness":
        return lines + [f"        z = state({t.state!r}) / S[{f'{EFFECT}.{slug}_scale'!r}]",
                        f"        s = add_energy(s, {label!r}, {th} * clock.symbol * S[{f'{EFFECT}.{slug}_energy'!r}] * z**2 / 2, [], self.effect)"]
    if t.shape == "drift_damping":
        return lines + [f"        term = {th} * S[{f'{EFFECT}.{slug}_damping'!r}] * sqrt(clock.symbol**2 + {CLOCK_SMOOTH!r})",
                        f"        s = add_damping(s, {t.state!r}, term, [], {f'{EFFECT}.{k}'!r})"]
    return lines + [f"        s = scale_input(s, {t.state!r}, 1 + {th} * clock.symbol, [], self.effect)"]


def _wrap(text: str, width: int = 100) -> list[str]:
    import textwrap

    return textwrap.wrap(text, width) or [""]


def _first_sentence(text: str) -> str:
    head = (text or "A discovered passive correction.").split("; ")[0].split(". ")[0].rstrip(".")
    return (head + ".").replace('"""', "'''")


def write_source(path, text: str) -> None:
    """Write emitted source to ``path`` atomically (after checking that it compiles).

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_source(os.path.join(d, "c.py"), "X = 1")
    ...     open(os.path.join(d, "c.py")).read()
    'X = 1'
    """
    compile(text, str(path), "exec")
    write_atomic(path, text)

