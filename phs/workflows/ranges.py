"""Inputs outside their declared range and states leaving theirs: said once per run, or refused.

Every state declares a physical range (:class:`phs.params.StateInfo`, ``range``) and an input may
(:class:`phs.params.InputInfo`, ``range``: a 0-6 kV supply, a ±5 N load cell).  A simulation does not stop
when a signal leaves its range, since the equations stay defined; but a value far outside says the
input was given in the wrong unit (30 000 where the model reads kV), or that the model is used where
its parameters were never meant to hold.  :func:`range_report` measures each signal against its range in
the form ``phs control`` reports its closed-loop inputs (``min``, ``max``, ``range``, ``exceeded``), and
:func:`check_ranges` says it: one :class:`RangeWarning` per run naming every signal outside, or, with
``strict=True`` (``--strict-ranges`` on the command line), an error naming the first.

In Python, ``warnings.simplefilter("error", RangeWarning)`` turns the warnings into exceptions too.

Examples
--------
>>> import numpy as np
>>> from codegen import simulate
>>> from systems.examples import mass_spring_damper
>>> res = simulate(mass_spring_damper(), np.linspace(0.0, 2.0, 201), u={"F": 1.0})  # k.l declared for ±0.1 m
>>> check_ranges(res, strict=True)
Traceback (most recent call last):
...
phs.errors.DomainError: state 'k.l' of 'msd' reaches 0.432311 m, outside its declared range -0.1 to 0.1 m (first at t = 0.48 s)
>>> from systems.msd_hasel import msd_hasel
>>> range_messages({"inputs": input_report(msd_hasel(), [0.0, 1.0], {"V": 30000.0})}, "msd_hasel")
["input 'V' of 'msd_hasel' reaches 30000 V, outside its declared range 0 to 6000 V"]
"""

from __future__ import annotations

import warnings

import numpy as np

from phs.errors import DomainError, InputDataError


class RangeWarning(UserWarning):
    """An input outside its declared range, or a state leaving its range, in a run (:func:`check_ranges`).

    Examples
    --------
    >>> issubclass(RangeWarning, UserWarning)
    True
    """


def _outside(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Where ``values`` lie outside ``[lo, hi]`` beyond rounding (1e-9 relative, as ``phs control``)."""
    return (values < lo - 1e-9 * abs(lo)) | (values > hi + 1e-9 * abs(hi))


def _entry(t: np.ndarray, values: np.ndarray, r, unit: str) -> dict:
    v = np.asarray(values, dtype=float)
    finite = v[np.isfinite(v)]
    out = _outside(v, r[0], r[1])
    first = int(np.argmax(out)) if out.any() else None
    return {"min": float(finite.min()) if finite.size else float("nan"),
            "max": float(finite.max()) if finite.size else float("nan"), "range": [float(r[0]), float(r[1])],
            "exceeded": bool(out.any()), "first_time": None if first is None else float(t[first]), "unit": unit}


def input_report(system, t, inputs: dict) -> dict:
    """``{input: {"min", "max", "range", "exceeded", "first_time", "unit"}}`` of the inputs with a declared
    range, from their values ``inputs`` (``{name: array on t}``, or a :mod:`phs.signals` signal or callable
    evaluated on ``t``; a number is constant).  Inputs without a declared range are left out.

    Examples
    --------
    >>> import numpy as np
    >>> from systems.msd_hasel import msd_hasel
    >>> input_report(msd_hasel(), np.linspace(0, 1, 3), {"V": 7000.0})["V"]["exceeded"]
    True
    """
    t = np.asarray(t, dtype=float)
    out = {}
    for info in system.inputs:
        if info.range is None or info.name not in inputs:
            continue
        u = inputs[info.name]
        values = u(t) if callable(u) else u
        values = np.broadcast_to(np.asarray(values, dtype=float), t.shape)
        out[info.name] = _entry(t, values, info.range, info.unit)
    return out


def range_report(res) -> dict:
    """Each input with a declared range and each state of a simulation result ``res`` against its range:
    ``{"inputs": {name: entry}, "states": {name: entry}}``, an entry as in :func:`input_report`.

    Examples
    --------
    >>> import numpy as np
    >>> from codegen import simulate
    >>> from systems.examples import mass_spring_damper
    >>> rep = range_report(simulate(mass_spring_damper(), np.linspace(0, 1, 11), u={"F": 0.1}))
    >>> sorted(rep["states"]), rep["states"]["k.l"]["exceeded"]
    (['k.l', 'm.p'], False)
    """
    s = res.system
    t = np.asarray(res.t, dtype=float)
    inputs = input_report(s, t, {name: np.asarray(res[name], dtype=float) for name in s.input_names})
    states = {st.name: _entry(t, np.asarray(res[st.name], dtype=float), st.range, st.unit) for st in s.states}
    return {"inputs": inputs, "states": states}


def _words(kind: str, name: str, system_name: str, e: dict) -> str:
    lo, hi = e["range"]
    unit = "" if e["unit"] in ("", "1") else f" {e['unit']}"
    low = e["min"] < lo - 1e-9 * abs(lo)
    value = e["min"] if low and not (e["max"] > hi + 1e-9 * abs(hi) and e["max"] - hi > lo - e["min"]) else e["max"]
    when = "" if kind == "input" and not e["first_time"] else f" (first at t = {e['first_time']:.6g} s)"
    return f"{kind} {name!r} of {system_name!r} reaches {value:.6g}{unit}, outside its declared range {lo:g} to {hi:g}{unit}{when}"


def range_messages(report: dict, system_name: str) -> list[str]:
    """One sentence per signal outside its range in ``report`` (:func:`range_report` or ``{"inputs":
    input_report(...)}``), inputs first.

    Examples
    --------
    >>> rep = {"inputs": {"V": {"min": 0.0, "max": 3e4, "range": [0.0, 5e3], "exceeded": True, "first_time": 0.0,
    ...                         "unit": "V"}}}
    >>> range_messages(rep, "actuator")
    ["input 'V' of 'actuator' reaches 30000 V, outside its declared range 0 to 5000 V"]
    """
    out = []
    for kind, key in (("input", "inputs"), ("state", "states")):
        for name, e in report.get(key, {}).items():
            if e["exceeded"]:
                out.append(_words(kind, name, system_name, e))
    return out


def check_ranges(res, *, strict: bool = False, report: dict | None = None) -> list[str]:
    """Say which inputs of the run ``res`` were outside their declared ranges and which states left theirs.

    Parameters
    ----------
    res : SimulationResult
        A run (:func:`codegen.simulate`).
    strict : bool
        Raise instead of warning.
    report : dict, optional
        A :func:`range_report` of ``res`` already computed.

    Returns
    -------
    list of str
        One sentence per signal outside its range (empty when none); they are also given as one
        :class:`RangeWarning` for the whole run.

    Raises
    ------
    InputDataError
        With ``strict``, for an input outside its declared range (the first one named).
    DomainError
        With ``strict``, for a state that left its declared range (the first one named, with the time).

    Examples
    --------
    >>> import numpy as np, warnings
    >>> from codegen import simulate
    >>> from systems.msd_hasel import msd_hasel
    >>> res = simulate(msd_hasel(), np.linspace(0.0, 0.01, 11), u={"V": 1000.0}, x0={"x": 2.9e-5})
    >>> check_ranges(res)
    []
    """
    rep = range_report(res) if report is None else report
    name = res.system.name
    found = range_messages(rep, name)
    if found and strict:
        first_input = range_messages({"inputs": rep.get("inputs", {})}, name)
        if first_input:
            raise InputDataError(first_input[0])
        raise DomainError(found[0])
    if found:
        warnings.warn("; ".join(found), RangeWarning, stacklevel=2)
    return found
