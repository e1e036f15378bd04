"""Figures written atomically: rendered in memory, then :func:`phs.io.write_atomic`."""

from __future__ import annotations

import io
import os

from phs.errors import InputDataError
from phs.io import write_atomic


def save_figure(fig, path, dpi: int = 100) -> None:
    """Save a matplotlib figure to ``path`` in the format of its suffix (PNG without one), atomically.

    The figure is rendered into memory first: a failure while rendering leaves no file behind and an
    existing ``path`` untouched, and the file itself appears complete or not at all.

    Raises
    ------
    InputDataError
        When the suffix is not a format matplotlib writes, or the file cannot be written.

    Examples
    --------
    >>> import os, tempfile
    >>> from matplotlib.figure import Figure
    >>> fig = Figure()
    >>> _ = fig.subplots().plot([0, 1], [0, 1])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_figure(fig, os.path.join(d, "line.png"))
    ...     open(os.path.join(d, "line.png"), "rb").read(4), os.listdir(d)
    (b'\\x89PNG', ['line.png'])
    """
    path = os.fspath(path)
    fmt = os.path.splitext(path)[1][1:].lower() or "png"
    if fmt not in fig.canvas.get_supported_filetypes():
        raise InputDataError(f"cannot write figure {path!r}: unknown image format {fmt!r} "
                             f"(use one of {', '.join(sorted(fig.canvas.get_supported_filetypes()))})")
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    write_atomic(path, buf.getvalue())
