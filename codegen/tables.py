"""Tables of results for notebooks: pandas DataFrames (pandas is optional) and small HTML tables.

Both helpers live in the core (:mod:`phs._results`, shared by every result object) and are named here
for the results of :mod:`codegen` and :mod:`phs.workflows`.

Examples
--------
>>> text = html_table(["name", "value"], [["<b>", 1.5]], caption="a & b")
>>> text[:60]
'<table><caption>a &amp; b</caption><thead><tr><th>name</th><'
>>> text[60:]
'th>value</th></tr></thead><tbody><tr><td>&lt;b&gt;</td><td>1.5</td></tr></tbody></table>'
"""

from __future__ import annotations

from phs._results import html_table, require_pandas

__all__ = ["html_table", "require_pandas"]
