"""Translation of sympy expressions to CasADi SX with shared subexpressions.

Every sympy node is translated once (a memo keyed by the node), so common
subexpressions become shared SX nodes.  Custom sympy functions may define
``_casadi(self, *args)`` returning an SX built from their translated args.
"""

from __future__ import annotations

import casadi as ca
import sympy as sp

from phs._sparse import nonzero_entries
from phs.errors import ModelError

_UNARY = {
    sp.sin: ca.sin, sp.cos: ca.cos, sp.tan: ca.tan, sp.asin: ca.asin, sp.acos: ca.acos, sp.atan: ca.atan,
    sp.sinh: ca.sinh, sp.cosh: ca.cosh, sp.tanh: ca.tanh, sp.asinh: ca.asinh, sp.acosh: ca.acosh,
    sp.atanh: ca.atanh, sp.exp: ca.exp, sp.log: ca.log, sp.Abs: ca.fabs, sp.sign: ca.sign, sp.erf: ca.erf,
    sp.floor: ca.floor, sp.ceiling: ca.ceil,
}


class Translator:
    """Translate sympy expressions given a mapping from symbols to SX.

    Examples
    --------
    >>> x = sp.Symbol("x")
    >>> X = ca.SX.sym("x")
    >>> tr = Translator({x: X})
    >>> str(tr(sp.sin(x) ** 2 + sp.sin(x)))   # sin(x) is computed once
    '@1=sin(x), (sq(@1)+@1)'
    """

    def __init__(self, symbols: dict):
        self.memo: dict = dict(symbols)

    def __call__(self, expr):
        if isinstance(expr, sp.MatrixBase):  # only the nonzero entries, in row-major order
            entries = nonzero_entries(expr)
            if not entries:
                return ca.SX(expr.rows, expr.cols)
            rows, cols, vals = zip(*entries)
            return ca.SX.triplet(list(rows), list(cols), ca.vertcat(*[self(v) for v in vals]), expr.rows, expr.cols)
        return self._rec(sp.sympify(expr))

    def _rec(self, e):
        memo = self.memo
        if e in memo:
            return memo[e]
        if e.is_Number or e.is_NumberSymbol:
            r = ca.SX(float(e))
        elif e.is_Symbol:
            raise ModelError(f"symbol {e} has no value in the generated function (unknown state, input or parameter)")
        elif e.is_Add:
            args = [self._rec(a) for a in e.args]
            r = args[0]
            for a in args[1:]:
                r = r + a
        elif e.is_Mul:
            args = [self._rec(a) for a in e.args]
            r = args[0]
            for a in args[1:]:
                r = r * a
        elif e.is_Pow:
            b = self._rec(e.base)
            ex = e.exp
            if ex == 2:
                r = b * b
            elif ex == sp.Rational(1, 2):
                r = ca.sqrt(b)
            elif ex == -1:
                r = 1 / b
            elif ex.is_Integer:
                r = ca.constpow(b, int(ex)) if int(ex) > 0 else 1 / ca.constpow(b, -int(ex))
            elif ex.is_Number:
                r = ca.constpow(b, float(ex))
            else:
                r = ca.power(b, self._rec(ex))
        elif e.func in _UNARY:
            r = _UNARY[e.func](self._rec(e.args[0]))
        elif isinstance(e, sp.atan2):
            r = ca.atan2(self._rec(e.args[0]), self._rec(e.args[1]))
        elif isinstance(e, sp.erfc):
            r = 1 - ca.erf(self._rec(e.args[0]))
        elif isinstance(e, sp.Max):
            args = [self._rec(a) for a in e.args]
            r = args[0]
            for a in args[1:]:
                r = ca.fmax(r, a)
        elif isinstance(e, sp.Min):
            args = [self._rec(a) for a in e.args]
            r = args[0]
            for a in args[1:]:
                r = ca.fmin(r, a)
        elif isinstance(e, sp.Heaviside):
            a = self._rec(e.args[0])
            r = ca.if_else(a > 0, 1.0, ca.if_else(a < 0, 0.0, 0.5))
        elif isinstance(e, sp.Piecewise):
            r = None
            for val, cond in reversed(e.args):
                v = self._rec(val)
                r = v if (cond == sp.true or r is None) else ca.if_else(self._cond(cond), v, r)
        elif hasattr(e, "_casadi"):
            r = e._casadi(*[self._rec(a) for a in e.args])
        else:
            raise ModelError(f"cannot translate {type(e).__name__} ({e}) to CasADi")
        memo[e] = r
        return r

    def _cond(self, c):
        if c == sp.true:
            return ca.SX(1)
        if isinstance(c, sp.And):
            out = self._cond(c.args[0])
            for a in c.args[1:]:
                out = ca.logic_and(out, self._cond(a))
            return out
        if isinstance(c, sp.Or):
            out = self._cond(c.args[0])
            for a in c.args[1:]:
                out = ca.logic_or(out, self._cond(a))
            return out
        if isinstance(c, sp.Not):
            return ca.logic_not(self._cond(c.args[0]))
        a, b = self._rec(c.lhs), self._rec(c.rhs)
        ops = {sp.StrictLessThan: a < b, sp.LessThan: a <= b, sp.StrictGreaterThan: a > b,
               sp.GreaterThan: a >= b, sp.Equality: a == b, sp.Unequality: a != b}
        for k, v in ops.items():
            if isinstance(c, k):
                return v
        raise ModelError(f"cannot translate condition {c} to CasADi")
