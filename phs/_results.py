"""What every result object shares: a short ``repr``, a small HTML table for Jupyter, figures drawn into
new or given axes and written atomically, and pandas as an optional extra.

A result class derives from :class:`ResultMixin` and defines ``_headline()`` (the few words of its
``repr``) and ``_table()`` (the header and rows of its HTML table); its ``plot`` draws into the axes of
:func:`panels` and ends with :func:`finish`; its ``to_pandas`` starts with :func:`require_pandas`.  Only
numpy is imported here: matplotlib and pandas are imported when a figure or a table is asked for.

Examples
--------
>>> class Count(ResultMixin):
...     def __init__(self, n):
...         self.n = n
...     def _headline(self):
...         return f"{self.n} runs"
...     def _table(self):
...         return ["runs"], [[self.n]]
>>> Count(3), Count(3)._repr_html_()[:36]
(Count(3 runs), '<table><caption>Count(3 runs)</capti')
"""

from __future__ import annotations

import html
import io
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from phs.errors import InputDataError
from phs.io import write_atomic

if TYPE_CHECKING:
    from types import ModuleType

    from matplotlib.figure import Figure

PANDAS_HINT = 'pip install "phs[pandas]"'
"""How to install the optional pandas extra, named by every ``to_pandas()`` without pandas."""
REPR_LIMIT = 300
"""Longest ``repr`` of a result (characters); a longer headline is cut with ``...``."""
VERDICT_COLORS = {"pass": "#2a7", "fail": "#c33", "undecided": "#c90"}


def require_pandas(what: str) -> ModuleType:
    """The pandas module, or an ImportError of one line naming ``pip install "phs[pandas]"``.

    Examples
    --------
    >>> import sys
    >>> saved, sys.modules["pandas"] = sys.modules.get("pandas"), None  # as if pandas were absent
    >>> try:
    ...     require_pandas("SimulationResult.to_pandas()")
    ... except ImportError as exc:
    ...     print(exc)
    ... finally:
    ...     _ = sys.modules.pop("pandas") if saved is None else sys.modules.update(pandas=saved)
    SimulationResult.to_pandas() needs pandas, which is not installed: pip install "phs[pandas]"
    """
    try:
        import pandas
    except ImportError:
        raise ImportError(f"{what} needs pandas, which is not installed: {PANDAS_HINT}") from None
    return pandas


def _cell(v) -> str:
    if isinstance(v, (float, np.floating)):
        return html.escape(f"{float(v):.6g}")
    return html.escape(str(v))


def html_table(header: Sequence[str], rows: Sequence[Sequence], caption: str | None = None) -> str:
    """A small HTML table; every header, cell and the caption are escaped (floats shown with 6 digits).

    Examples
    --------
    >>> html_table(["x"], [[1 / 3]])
    '<table><thead><tr><th>x</th></tr></thead><tbody><tr><td>0.333333</td></tr></tbody></table>'
    """
    head = "".join(f"<th>{_cell(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    cap = f"<caption>{_cell(caption)}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _is_axes(obj) -> bool:
    return hasattr(obj, "plot") and hasattr(obj, "get_figure")


def panels(ax, rows: int, cols: int = 1, *, figsize=None, sharex: bool = False, what: str = "plot"):
    """``(figure, axes)``: a ``rows x cols`` array of axes to draw into, new or given.

    Without ``ax``, a new figure (not registered with pyplot, so it is never shown twice nor kept
    alive) of ``figsize``; with ``ax`` (one Axes or an array of them), its first ``rows * cols`` axes in
    reading order, and the figure they belong to.

    Raises
    ------
    InputDataError
        When ``ax`` holds fewer axes than the figure has panels, or something that is no Axes.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> fig, axes = panels(None, 2)
    >>> axes.shape, len(fig.axes)
    ((2, 1), 2)
    >>> given = Figure().subplots(1, 3)
    >>> panels(given, 2)[1].shape
    (2, 1)
    >>> panels(given[0], 2, what="SimulationResult.plot")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: SimulationResult.plot(ax=...): this figure has 2 panels, ax= gives 1 axes
    """
    n = rows * cols
    if ax is None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize or (8, 2.6 * rows), constrained_layout=True)
        FigureCanvasAgg(fig)
        return fig, fig.subplots(rows, cols, squeeze=False, sharex=sharex)
    given = [ax] if _is_axes(ax) else list(np.ravel(np.asarray(ax, dtype=object)))
    if not all(_is_axes(a) for a in given):
        raise InputDataError(f"{what}(ax=...): expected a matplotlib Axes or an array of them, got {type(ax).__name__}")
    if len(given) < n:
        raise InputDataError(f"{what}(ax=...): this figure has {n} panels, ax= gives {len(given)} axes")
    first = given[0]
    try:
        fig = first.get_figure(root=True)
    except TypeError:  # matplotlib before 3.10
        fig = first.figure
    return fig, np.array(given[:n], dtype=object).reshape(rows, cols)


def new_figure(fig, figsize):
    """``fig``, or a new figure of ``figsize`` with an Agg canvas (not registered with pyplot)."""
    if fig is not None:
        return fig
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, constrained_layout=True)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path, dpi: int = 100) -> None:
    """Save ``fig`` to ``path`` in the format of its suffix (PNG without one), atomically: rendered in
    memory first, so a failure leaves no file behind and an existing ``path`` untouched.

    Raises
    ------
    InputDataError
        When the suffix is not a format matplotlib writes, or the file cannot be written.

    Examples
    --------
    >>> import tempfile
    >>> fig, axes = panels(None, 1)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_figure(fig, os.path.join(d, "f.png"))
    ...     open(os.path.join(d, "f.png"), "rb").read(4)
    b'\\x89PNG'
    """
    path = os.fspath(path)
    fmt = os.path.splitext(path)[1][1:].lower() or "png"
    if fmt not in fig.canvas.get_supported_filetypes():
        raise InputDataError(f"cannot write figure {path!r}: unknown image format {fmt!r} "
                             f"(use one of {', '.join(sorted(fig.canvas.get_supported_filetypes()))})")
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    write_atomic(path, buf.getvalue())


def finish(fig, path, dpi: int = 100) -> Figure:
    """``fig``, first written to ``path`` (:func:`save_figure`) when a path is given."""
    if path is not None:
        save_figure(fig, path, dpi=dpi)
    return fig


def draw_verdicts(ax, rows: Sequence[tuple[str, str, str]], title: str = "") -> None:
    """One coloured row per check on ``ax``: ``(name, verdict, detail)``, verdict ``pass``, ``fail`` or
    ``undecided`` (green, red, amber), the detail cut to one line.

    Examples
    --------
    >>> fig, axes = panels(None, 1)
    >>> draw_verdicts(axes[0, 0], [("skew", "pass", "J + J^T = 0"), ("psd", "fail", "R[0,0] < 0")])
    >>> [t.get_text() for t in axes[0, 0].texts][:2]
    ['skew: pass   J + J^T = 0', 'psd: fail   R[0,0] < 0']
    """
    n = len(rows)
    for k, (name, verdict, detail) in enumerate(rows):
        y = n - 1 - k
        ax.barh(y, 1.0, left=0.0, height=0.8, color=VERDICT_COLORS.get(verdict, "#999"), alpha=0.35)
        line = f"{name}: {verdict}   {' '.join(str(detail).split())}"
        ax.text(0.01, y, line if len(line) <= 110 else line[:107] + "...", va="center", fontsize=8)
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.6, max(n, 1) - 0.4)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)


class ResultMixin:
    """``repr`` and ``_repr_html_`` of a result from its ``_headline()`` and ``_table()``.

    ``repr(result)`` is ``ClassName(headline)`` of at most :data:`REPR_LIMIT` characters, never an array;
    ``_repr_html_`` is the table of ``_table() -> (header, rows)`` with the repr as caption.
    """

    def _headline(self) -> str:  # pragma: no cover - every result defines its own
        return ""

    def _table(self) -> tuple[list, list]:  # pragma: no cover - every result defines its own
        return [], []

    def __repr__(self) -> str:
        text = f"{type(self).__name__}({self._headline()})"
        return text if len(text) <= REPR_LIMIT else text[:REPR_LIMIT - 4] + "...)"

    def _repr_html_(self) -> str:
        header, rows = self._table()
        return html_table(header, rows, caption=repr(self))


def names(items: Sequence[str], limit: int = 6) -> str:
    """``a, b, c`` or ``a, b, ... (n more)``: a list of names short enough for a headline.

    Examples
    --------
    >>> names(["x", "y"]), names([f"s{i}" for i in range(9)], limit=3)
    ('x, y', 's0, s1, s2, ... (6 more)')
    """
    items = list(items)
    head = ", ".join(map(str, items[:limit]))
    return head + (f", ... ({len(items) - limit} more)" if len(items) > limit else "")
