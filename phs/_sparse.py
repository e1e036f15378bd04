"""Passes over the nonzero entries of sympy matrices, in row-major order.

The matrices of a model (``J``, ``R``, ``G``, ...) are ``n x n`` with ``O(n)`` nonzero entries for
element-wise models such as a discretised rod.  sympy stores them sparsely (dict of keys), but
indexing every entry (``M[i, j]``, ``list(M)``, ``sp.srepr(M)``) is a dense ``O(n^2)`` pass of
Python calls.  These helpers visit only the stored entries, in the order a dense row-major loop
would meet them, so every result built from them is the one the dense loop gives.
"""

from __future__ import annotations

import sympy as sp

_ZERO_SREPR = sp.srepr(sp.Integer(0))


def nonzero_entries(M: sp.MatrixBase) -> list[tuple[int, int, sp.Expr]]:
    """``(i, j, M[i, j])`` for the entries of ``M`` that are not zero, in row-major order.

    Examples
    --------
    >>> nonzero_entries(sp.Matrix([[0, 2], [sp.Symbol("a"), 0]]))
    [(0, 1, 2), (1, 0, a)]
    """
    return [(i, j, v) for (i, j), v in sorted(M.todok().items()) if v != 0]


def srepr_matrix(M: sp.MatrixBase) -> str:
    """``sympy.srepr(M)``, with the zero entries written without visiting them one by one.

    Examples
    --------
    >>> M = sp.Matrix([[0, sp.Symbol("a")], [1, 0]])
    >>> srepr_matrix(M) == sp.srepr(M)
    True
    """
    if (M.rows == 0) ^ (M.cols == 0) or M.rows == 0:
        return sp.srepr(M)
    rows = [[_ZERO_SREPR] * M.cols for _ in range(M.rows)]
    for (i, j), v in M.todok().items():
        rows[i][j] = sp.srepr(v)
    return f"{type(M).__name__}([" + ", ".join("[" + ", ".join(r) + "]" for r in rows) + "])"
