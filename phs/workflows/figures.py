"""Figures: axis labels with units, and files written atomically (rendered in memory, then :func:`phs.io.write_atomic`)."""

from __future__ import annotations

from codegen.figures import save_figure  # noqa: F401  (re-exported: the figures of the workflows are saved with it)


def axis_label(name: str, unit: str = "") -> str:
    """``name [unit]`` (``[-]`` for a dimensionless ``"1"``), or ``name`` alone when the unit is unknown.

    Examples
    --------
    >>> axis_label("R.R", "Ohm"), axis_label("gain", "1"), axis_label("score")
    ('R.R [Ohm]', 'gain [-]', 'score')
    """
    return f"{name} [{'-' if unit == '1' else unit}]" if unit else name
