"""Bounded symbolic work for the structural checks, and evaluation that never reads NaN as a pass.

Every symbolic decision of the checks (``expand``/``simplify`` of ``J + J^T``, the principal minors of
a dissipation block, the expansion of H) is first priced: :func:`expanded_terms` bounds the number of
terms ``sp.expand`` would produce (a power ``(a + b + 1)**120`` has 7381 of them) without expanding,
and an expression over :data:`MAX_TERMS` terms or :data:`MAX_OPS` operations is not given to sympy's
``expand``/``factor``/``simplify``: the check falls back to sampling and says so.  The price is
computed from the expression tree alone, so no timeout or thread is needed.

Numeric samples that come out NaN or infinite in floating point (``inf - inf``) are evaluated again
with mpmath (arbitrary exponent range, :data:`MP_DIGITS` digits); what is still not finite there is
reported, never skipped.

Examples
--------
>>> import sympy as sp
>>> a, b = sp.symbols("a b", positive=True)
>>> expanded_terms((a + b + 1) ** 120)
7381
>>> affordable((a + b + 1) ** 120 - (a + b + 2) ** 120)
False
>>> affordable(a * b + 1 / a)
True
"""

from __future__ import annotations

from math import comb

import numpy as np
import sympy as sp

#: most terms an expression may expand to before symbolic decisions on it are refused
MAX_TERMS = 400
#: most operations (``sp.count_ops``) of an expression given to ``simplify``
MAX_OPS = 300
#: digits of the mpmath evaluation of samples that overflow in floating point
MP_DIGITS = 30

_CAP = 10**9


def expanded_terms(expr) -> int:
    """Upper bound (capped at 10**9) on the number of terms of ``sp.expand(expr)``, from the tree alone.

    Examples
    --------
    >>> x, y = sp.symbols("x y")
    >>> expanded_terms((x + y) * (x - y)), expanded_terms((x + y) ** 3)
    (4, 4)
    """
    return _prices(expr)[0]


def _prices(expr) -> tuple[int, int]:
    """(price of ``expr``, largest price of an argument of a function or condition inside it)."""
    cache: dict = {}
    inner = 0

    def rec(e) -> int:
        nonlocal inner
        if e in cache:
            return cache[e]
        if e.is_Atom:
            n = 1
        elif e.is_Add:
            n = sum(rec(a) for a in e.args)
        elif e.is_Mul:
            n = 1
            for a in e.args:
                n = min(_CAP, n * rec(a))
        elif e.is_Pow and e.exp.is_Integer and e.exp > 1:
            k, m = rec(e.base), int(e.exp)
            n = 1 if k == 1 else (_CAP if m > 10**4 else min(_CAP, comb(k + m - 1, m)))
        else:  # a function, a negative or fractional power, a condition: one term, its arguments priced apart
            n = 1
            for a in e.args:
                if isinstance(a, sp.Basic):
                    price = rec(a)  # (rec may raise ``inner`` itself: read it after the call)
                    inner = max(inner, price)
        cache[e] = min(n, _CAP)
        return cache[e]

    return rec(sp.sympify(expr, strict=True)), inner


def _worst_inner(expr) -> int:
    """Largest expansion price of ``expr`` or of any argument of a function inside it."""
    return max(_prices(expr))


def affordable(expr, max_terms: int = MAX_TERMS, max_ops: int = MAX_OPS) -> bool:
    """Whether sympy's ``expand``/``factor``/``simplify`` may be run on ``expr`` (or on every entry of a matrix).

    Examples
    --------
    >>> x = sp.Symbol("x")
    >>> affordable(sp.Matrix([[x, (x + 1) ** 2]])), affordable(sp.sin((x + 2) ** 500))
    (True, False)
    """
    if isinstance(expr, sp.MatrixBase):
        return all(affordable(v, max_terms, max_ops) for v in expr if v != 0)
    expr = sp.sympify(expr, strict=True)
    if _worst_inner(expr) > max_terms:
        return False
    return sp.count_ops(expr) <= max_ops


def is_zero(expr) -> bool | None:
    """True/False when ``expr`` is decided (not) identically zero within the budget, None when over it.

    Examples
    --------
    >>> x = sp.Symbol("x")
    >>> is_zero((x + 1) ** 2 - x**2 - 2 * x - 1), is_zero(x), is_zero((x + 1) ** 900 - (x + 1) ** 900 + x)
    (True, False, False)
    >>> print(is_zero((x + 1) ** 900 - (x + 2) ** 900))
    None
    """
    expr = sp.sympify(expr, strict=True)
    if expr == 0:
        return True
    if not affordable(expr):
        return None
    return sp.expand(expr) == 0 or sp.simplify(expr) == 0


def mp_values(exprs, args, values) -> list:
    """``exprs`` at ``args = values`` with mpmath (:data:`MP_DIGITS` digits): mpf values, NaN when undefined.

    Examples
    --------
    >>> a = sp.Symbol("a")
    >>> v = mp_values([(a + 1) ** 120 - (a + 2) ** 120], [a], [1000.0])[0]
    >>> float(v) == float("-inf"), v < 0
    (True, True)
    """
    import mpmath

    out = []
    with mpmath.workdps(MP_DIGITS):
        f = sp.lambdify(list(args), list(exprs), modules="mpmath")
        try:
            res = f(*[mpmath.mpf(float(v)) for v in values])
        except (ArithmeticError, ValueError, TypeError, OverflowError):
            return [mpmath.mpf("nan")] * len(exprs)
        for v in res:
            out.append(v if isinstance(v, mpmath.mpf) else mpmath.mpf("nan"))
    return out


def scaled_block(values) -> tuple[np.ndarray, float]:
    """Entries (mpmath or floats) divided by their largest magnitude, as floats, and that magnitude's log10.

    The signs of the eigenvalues of a symmetric block survive the division, so a block whose entries
    overflow in floating point is still decided.

    Examples
    --------
    >>> import mpmath
    >>> m, e = scaled_block([mpmath.mpf("-1e400"), mpmath.mpf("2e399")])
    >>> m.tolist(), round(e)
    ([-1.0, 0.2], 400)
    """
    import mpmath

    vals = [mpmath.mpf(v) for v in values]
    big = max((abs(v) for v in vals), default=mpmath.mpf(0))
    if big == 0 or not mpmath.isfinite(big):
        return np.array([float(v) for v in vals]), 0.0
    return np.array([float(v / big) for v in vals]), float(mpmath.log10(big))
