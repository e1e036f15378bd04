"""How a :class:`phs.PHSystem` reads what it is given: expressions (never strings), matrices (of the
declared shape, frozen), and the validity conditions implied by the functions in its expressions."""

from __future__ import annotations

import sympy as sp

from phs._frozen import frozen_matrix
from phs.params import Condition


def _holds_string(M) -> bool:
    """Whether a matrix given as (nested) lists holds a string entry: sympy would parse it with ``eval``."""
    return isinstance(M, str) or isinstance(M, (list, tuple)) and any(_holds_string(v) for v in M)


def _strict(value, what: str, problems: list[str]) -> sp.Expr:
    """``value`` as a sympy expression, a number or a sympy object; a string is a problem (sympy would parse it
    with ``eval``; expressions read from files go through :mod:`phs.safe_parse`)."""
    try:
        return sp.sympify(value, strict=True)
    except sp.SympifyError:
        problems.append(f"{what} is a {type(value).__name__}, not a sympy expression or a number: {value!r}")
        return sp.Integer(0)


def _as_matrix(M, rows: int, cols: int, what: str, problems: list[str]) -> sp.ImmutableDenseMatrix:
    """``M`` as an immutable ``rows x cols`` matrix; zeros (and a problem) when it is not one."""
    return frozen_matrix(_matrix(M, rows, cols, what, problems))


def _matrix(M, rows: int, cols: int, what: str, problems: list[str]) -> sp.MatrixBase:
    if M is None:
        return sp.zeros(rows, cols)
    if _holds_string(M):
        problems.append(f"{what} holds a string entry: give sympy expressions or numbers")
        return sp.zeros(rows, cols)
    try:
        M = M if isinstance(M, sp.MatrixBase) else sp.Matrix(M)
    except (TypeError, ValueError) as exc:
        problems.append(f"{what} is not a matrix: {exc}")
        return sp.zeros(rows, cols)
    if cols == 0 and M.shape == (rows, 1) and rows == 0:
        return sp.zeros(rows, cols)
    if M.shape != (rows, cols):
        if rows * cols == 0 and len(M) == 0:
            return sp.zeros(rows, cols)
        problems.append(f"{what} has shape {M.shape}, expected ({rows}, {cols})")
        return sp.zeros(rows, cols)
    return M


def _domain_conditions(exprs, label: str) -> list[Condition]:
    """Validity conditions implied by asin/acos/sqrt/log arguments inside ``exprs``."""
    out: dict[sp.Expr, Condition] = {}
    for ex in exprs:
        for node in sp.preorder_traversal(ex):
            if isinstance(node, (sp.asin, sp.acos)):
                a = node.args[0]
                fn = node.func.__name__
                out.setdefault(1 - a, Condition(f"{fn} argument <= 1 in {label}", 1 - a, f"{a} <= 1"))
                out.setdefault(1 + a, Condition(f"{fn} argument >= -1 in {label}", 1 + a, f"{a} >= -1"))
            elif isinstance(node, sp.log):
                a = node.args[0]
                out.setdefault(a, Condition(f"log argument > 0 in {label}", a, f"{a} > 0"))
            elif node.is_Pow and node.exp.is_Rational and not node.exp.is_Integer and node.exp.q == 2:
                a = node.base
                if not a.is_nonnegative:
                    out.setdefault(a, Condition(f"square-root argument >= 0 in {label}", a, f"{a} >= 0"))
    return list(out.values())


def _replaced(expr, rule: dict):
    """``expr`` (an expression, a matrix or nested sequences of them) with symbols replaced by ``rule``."""
    if isinstance(expr, (list, tuple)):
        return type(expr)(_replaced(e, rule) for e in expr)
    return expr.xreplace(rule) if isinstance(expr, sp.Basic) or isinstance(expr, sp.MatrixBase) else expr
