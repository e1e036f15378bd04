"""How a recorded input behaves between its samples, as a CSV file states it.

A header cell may follow the column's name and unit with an annotation in braces:

* ``U [V] {zoh}``: the input was held from each sample to the next (a DAC's command);
* ``U [V] {linear}``: a continuous signal sampled by a sensor (interpolated between the samples);
* ``U [V] {square(1500, 3, offset=1500)}``: the law the samples were taken from, in the vocabulary of
  ``--input`` (:func:`phs.signals.parse_expression`, a whitelist: nothing in it runs); a simulation replays the
  law itself, edges between the samples included.  ``phs simulate --out`` writes it for every input given
  as a law, so a file it writes replays its own run exactly.

Without an annotation (and without ``holds=`` / ``--hold``), an input is read by its samples: held when they
change in isolated jumps between flat stretches (:func:`phs.kinks.held_between_samples`), else continuous.

Examples
--------
>>> split_annotation("U [kV] {zoh}")
('U [kV]', 'zoh')
>>> hold_of("square(1.0, 2)", "u.csv", "U").breakpoints(0.0, 1.0).tolist()
[0.25, 0.5, 0.75]
"""

from __future__ import annotations

import re

import numpy as np

from phs.errors import InputDataError
from phs.signals import Signal, parse_expression

_ANNOTATION = re.compile(r"(.*?\S)?\s*\{([^{}]*)\}\s*")
HOLD_WORDS = {"zoh": "zoh", "held": "zoh", "hold": "zoh", "linear": "linear", "continuous": "linear"}
"""The words a header annotation or ``--hold`` may use for how an input behaves between samples."""

LAW_TOLERANCE = 1e-6
"""A column declared to follow a law must equal the law at every sample to this share of the column's largest
magnitude (a CSV written with 10 significant digits is exact to 1e-10 of it), except at samples within rounding
of one of the law's switching times, where either side's value is accepted."""


def split_annotation(cell: str) -> tuple[str, str | None]:
    """A header cell without its trailing ``{...}`` annotation, and the annotation's text (None without one).

    Examples
    --------
    >>> split_annotation("position [mm]"), split_annotation("U {sine(2.0, 5)}")
    (('position [mm]', None), ('U', 'sine(2.0, 5)'))
    """
    m = _ANNOTATION.fullmatch(cell)
    if not m:
        return cell, None
    return (m.group(1) or "").strip(), m.group(2).strip()


def hold_of(text, source: str, column: str) -> str | Signal:
    """The reading an annotation or option ``text`` states for ``column``: ``"zoh"``, ``"linear"``, a
    :class:`~phs.signals.Signal` law, or ``"auto"`` for ``auto``; a :class:`~phs.signals.Signal` passes through.

    Raises
    ------
    InputDataError
        Naming the source and the column when the text is neither a reading nor a law.

    Examples
    --------
    >>> hold_of("ZOH", "r.csv", "U"), hold_of("linear", "r.csv", "U")
    ('zoh', 'linear')
    >>> try:
    ...     hold_of("open('x')", "r.csv", "U")
    ... except InputDataError as err:
    ...     print(str(err)[:70])
    r.csv: column 'U': {open('x')} is neither zoh, linear nor a signal law
    """
    if isinstance(text, Signal):
        return text
    word = str(text).strip()
    if word.lower() in HOLD_WORDS:
        return HOLD_WORDS[word.lower()]
    if word.lower() == "auto":
        return "auto"
    try:
        return parse_expression(word)
    except InputDataError as exc:
        raise InputDataError(f"{source}: column {column!r}: {{{word}}} is neither zoh, linear nor a signal law ({exc})") from None


def check_law(law: Signal, text: str, t: np.ndarray, values: np.ndarray, source: str, column: str, row) -> None:
    """Refuse a column whose samples do not follow its declared law ``law`` (written ``text``; within
    :data:`LAW_TOLERANCE`); ``row(k)`` names sample ``k``.

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 11)
    >>> check_law(parse_expression("2*t"), "2*t", t, 2 * t, "r.csv", "U", lambda k: f"row {k + 2}")
    >>> check_law(parse_expression("2*t"), "2*t", t, 3 * t, "r.csv", "U", lambda k: f"row {k + 2}")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: r.csv: column 'U' does not follow its declared law {2*t}: 0.3 at row 3 where the law gives 0.2
    """
    law_values = np.broadcast_to(np.asarray(law(t), dtype=float), t.shape)
    tol = LAW_TOLERANCE * max(float(np.max(np.abs(values))), float(np.max(np.abs(law_values))), 1e-300)
    off = np.flatnonzero(np.abs(values - law_values) > tol)
    if len(off):
        step = float(np.min(np.diff(t))) if len(t) > 1 else 1.0
        bps = np.asarray(law.breakpoints(float(t[0]) - step, float(t[-1]) + step), dtype=float)
        near = np.zeros(len(off), dtype=bool)
        if len(bps):  # a sample on a switching time, up to rounding: either side's value
            for k_i, k in enumerate(off):
                if np.min(np.abs(bps - t[k])) <= 1e-6 * step:
                    eps = 1e-6 * step
                    sides = np.asarray(law(np.array([t[k] - eps, t[k] + eps])), dtype=float)
                    near[k_i] = bool(np.any(np.abs(sides - values[k]) <= tol))
        off = off[~near]
    if len(off):
        k = int(off[0])
        raise InputDataError(f"{source}: column {column!r} does not follow its declared law {{{text}}}: "
                             f"{values[k]:.10g} at {row(k)} where the law gives {law_values[k]:.10g}")



def header_annotations(raw_header, names) -> dict:
    """The annotation text of each column that has one: ``raw_header`` the header cells as read, ``names`` the
    column names made of them (:func:`phs.workflows.inputs._names_and_units`), in the same order.

    Examples
    --------
    >>> header_annotations(["t [s]", "U [V] {zoh}", "y"], ["t", "U", "y"])
    {'U': 'zoh'}
    """
    out = {}
    for cell, name in zip(raw_header, names, strict=True):
        text = split_annotation(str(cell))[1]
        if text is not None:
            out[name] = text
    return out
