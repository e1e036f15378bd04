"""Tables of results for notebooks: pandas DataFrames (pandas is optional) and small HTML tables.

Examples
--------
>>> text = html_table(["name", "value"], [["<b>", 1.5]], caption="a & b")
>>> text[:60]
'<table><caption>a &amp; b</caption><thead><tr><th>name</th><'
>>> text[60:]
'th>value</th></tr></thead><tbody><tr><td>&lt;b&gt;</td><td>1.5</td></tr></tbody></table>'
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from types import ModuleType


def require_pandas(what: str) -> ModuleType:
    """The pandas module, or an ImportError of one line naming ``pip install pandas``.

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
    SimulationResult.to_pandas() needs pandas, which is not installed: pip install pandas
    """
    try:
        import pandas
    except ImportError:
        raise ImportError(f"{what} needs pandas, which is not installed: pip install pandas") from None
    return pandas


def _cell(v) -> str:
    if isinstance(v, float):
        return html.escape(f"{v:.6g}")
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
