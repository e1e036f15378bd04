"""The stored grammar of :mod:`phs.safe_parse`: the ``srepr`` text a saved model holds.

A tree of whitelisted sympy constructors (``Mul(Integer(2), Symbol('x', real=True))``), walked
with the limits and messages of :mod:`phs.safe_parse`; the project's own functions that appear in
saved models (kinematic-chain inertia forms) are added with :func:`register_function`.
"""

from __future__ import annotations

import ast
import math
import re

import sympy as sp

from phs.errors import InputDataError
from phs.safe_parse import (
    _STORED_NODES,
    MAX_ARGS,
    MAX_BITS,
    MAX_DEPTH,
    Refusal,
    _at,
    _check_name,
    _first_line,
    _prescan,
    _quote,
    _run,
    check_value,
    parse_tree,
    power,
)

# -- the stored grammar (srepr) ----------------------------------------------------------------------------
_FUNCTIONS: dict[str, type] = {
    cls.__name__: cls for cls in (
        sp.Add, sp.Mul, sp.sin, sp.cos, sp.tan, sp.cot, sp.sec, sp.csc, sp.asin, sp.acos, sp.atan, sp.acot,
        sp.atan2, sp.sinh, sp.cosh, sp.tanh, sp.coth, sp.asinh, sp.acosh, sp.atanh, sp.exp, sp.log, sp.Abs,
        sp.sign, sp.Heaviside, sp.Max, sp.Min, sp.erf, sp.erfc, sp.floor, sp.ceiling, sp.re, sp.im,
        sp.Piecewise, sp.functions.elementary.piecewise.ExprCondPair, sp.StrictGreaterThan, sp.StrictLessThan,
        sp.GreaterThan, sp.LessThan, sp.Equality, sp.Unequality, sp.And, sp.Or, sp.Not,
    )
}
_CONSTANTS = {"pi": sp.pi, "E": sp.E, "I": sp.I, "true": sp.true, "false": sp.false}
_MATRICES = {"MutableDenseMatrix": sp.MutableDenseMatrix, "ImmutableDenseMatrix": sp.ImmutableDenseMatrix}
_ASSUMPTIONS = frozenset({
    "real", "positive", "negative", "nonnegative", "nonpositive", "nonzero", "zero", "integer", "rational",
    "finite", "complex", "commutative", "extended_real", "extended_positive", "extended_negative",
    "extended_nonnegative", "extended_nonpositive", "extended_nonzero", "imaginary", "even", "odd", "prime",
    "hermitian", "irrational", "algebraic", "transcendental",
})
_SYMBOL_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*\Z")
_FLOAT_TEXT = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\Z")
_REGISTERED: dict[str, type] = {}
_MAX_LATTICE = 16  # arguments of Min and Max in one stored expression


def register_function(cls: type) -> type:
    """Allow a sympy function class defined by the project in saved models (a class decorator).

    Only code registers; a saved file can only name what is registered (and
    sympy's own elementary functions).  Its arguments are built by the
    stored grammar, like every other node.

    Examples
    --------
    >>> from components.kinematics import InverseQuadraticForm  # registered where it is defined
    >>> parse_srepr("InverseQuadraticForm(Integer(2), Symbol('p', real=True))")
    InverseQuadraticForm(2, p)
    """
    if not (isinstance(cls, type) and issubclass(cls, sp.Function)) or "__" in cls.__name__:
        raise TypeError(f"{cls!r} is not a sympy function class")
    _REGISTERED[cls.__name__] = cls
    return cls


def parse_srepr(text, where: str = "expression", *, error: type[Exception] = InputDataError,
                max_length: int = 1_000_000) -> sp.Basic | sp.MatrixBase:
    """Rebuild a sympy object from its ``srepr`` text through the whitelist of stored constructors.

    Accepted: ``Integer(n)``, ``Rational(p, q)``, ``Float('digits', precision=n)``,
    ``Symbol('dotted.name', real=True, ...)``, the constants ``pi E I true false``,
    ``MutableDenseMatrix``/``ImmutableDenseMatrix`` of such entries, and calls of
    ``Add``, ``Mul``, ``Pow``, the elementary functions, ``Piecewise``, relations,
    ``And``/``Or``/``Not`` and functions registered with :func:`register_function`
    on such arguments.

    Parameters
    ----------
    text : str
        Output of :func:`sympy.srepr`.
    where : str
        What the text is (a JSON field), said first in errors.
    error : exception class
        The error raised.
    max_length : int
        Longest text accepted.

    Raises
    ------
    error
        If the text is anything else, or a number is out of bounds.

    Examples
    --------
    >>> e = parse_srepr(sp.srepr(sp.Symbol("C.C", positive=True) ** 2))
    >>> e, e.free_symbols.pop().is_positive
    (C.C**2, True)
    >>> try:
    ...     parse_srepr("sin('1')", "energy[0].expr")
    ... except InputDataError as err:
    ...     print(err)
    energy[0].expr: sin() takes expressions, not Constant "'1'"
    """
    tree = parse_tree(text, where, error=error, max_length=max_length)
    body = text.strip()
    return _run(text, where, error, lambda: (_prescan(tree, body, _STORED_NODES), _Stored(body).visit(tree, 0))[1])


class _Stored:
    """The walk of the stored grammar over one text."""

    def __init__(self, text: str):
        self.text, self.lattice = text, 0
        self.known = {"Integer", "Rational", "Float", "Symbol", "Pow"} | set(_FUNCTIONS) | set(_MATRICES) | set(_REGISTERED)

    def seg(self, node) -> str:
        return _quote(ast.get_source_segment(self.text, node) or "?", 30)

    def integer(self, node) -> int:
        """A (possibly negated) integer literal."""
        neg = isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub)
        lit = node.operand if neg else node
        if not (isinstance(lit, ast.Constant) and type(lit.value) is int):
            raise Refusal(f"expected an integer literal, not {type(lit).__name__} {self.seg(lit)}", node)
        if lit.value.bit_length() > MAX_BITS:
            raise Refusal(f"an integer has more than {MAX_BITS} bits", node)
        return -lit.value if neg else lit.value

    def string(self, node, pattern: re.Pattern, what: str) -> str:
        if not (isinstance(node, ast.Constant) and isinstance(node.value, str) and pattern.match(node.value)):
            raise Refusal(f"expected {what}, not {type(node).__name__} {self.seg(node)}", node)
        return node.value

    def visit(self, node, depth: int):
        if depth > MAX_DEPTH:
            raise Refusal(f"nested deeper than {MAX_DEPTH} levels", node)
        if isinstance(node, ast.Name):
            _check_name(node.id, node)
            if node.id in _CONSTANTS:
                return _CONSTANTS[node.id]
            raise Refusal(f"unknown name {node.id!r}" + (" (call it)" if node.id in self.known else ""), node)
        if not isinstance(node, ast.Call):  # a minus sign outside Integer(-n), Float('-x')
            raise Refusal(f"{type(node).__name__}: operators are not allowed (a stored expression is a tree of calls)", node)
        if not isinstance(node.func, ast.Name):
            raise Refusal(f"only named constructors can be called, not {self.seg(node.func)}", node)
        name = node.func.id
        _check_name(name, node.func)
        if name not in self.known:
            raise Refusal(f"unknown name {name!r} (not a constructor a saved model uses)", node)
        if len(node.args) > MAX_ARGS:
            raise Refusal(f"{name}() has more than {MAX_ARGS} arguments", node)
        kwargs = {kw.arg: kw.value for kw in node.keywords}
        if name not in ("Symbol", "Float") and kwargs:
            raise Refusal(f"{name}() takes no keyword arguments", node)
        return _at(node, lambda: self.construct(name, node.args, kwargs, depth))

    def construct(self, name: str, args: list, kwargs: dict, depth: int):
        if name == "Integer" and len(args) == 1:
            return sp.Integer(self.integer(args[0]))
        if name == "Rational" and len(args) == 2:
            p, q = self.integer(args[0]), self.integer(args[1])
            if q == 0:
                raise Refusal("Rational() with a zero denominator")
            return check_value(sp.Rational(p, q))
        if name == "Float" and len(args) == 1:
            return self.float(args[0], kwargs)
        if name == "Symbol" and len(args) == 1:
            return self.symbol(args[0], kwargs)
        if name in _MATRICES:
            return self.matrix(_MATRICES[name], args, depth)
        if name in ("Integer", "Rational", "Float", "Symbol"):
            raise Refusal(f"{name}() takes {'two arguments' if name == 'Rational' else 'one argument'}")
        built = []
        for a in args:
            if isinstance(a, ast.Constant):
                raise Refusal(f"{name}() takes expressions, not {type(a).__name__} {self.seg(a)}", a)
            built.append(self.visit(a, depth + 1))
        if name == "Pow":
            if len(built) != 2:
                raise Refusal("Pow() takes two arguments")
            return power(*built)
        cls = _FUNCTIONS.get(name) or _REGISTERED[name]
        if cls in (sp.Min, sp.Max):  # sympy compares their arguments pairwise: bound the work per text
            self.lattice += sum(len(a.args) if isinstance(a, cls) else 1 for a in built)
            if self.lattice > _MAX_LATTICE:
                raise Refusal(f"Min and Max take at most {_MAX_LATTICE} arguments in all in one expression")
        try:
            value = cls(*built)
        except Refusal:
            raise
        except Exception as exc:  # noqa: BLE001 - a sympy constructor refusing its (already safe) arguments
            raise Refusal(f"{name}(): {_first_line(exc)}") from None
        return check_value(value)

    def float(self, arg, kwargs: dict):
        digits = self.string(arg, _FLOAT_TEXT, "the decimal digits of a float")
        if set(kwargs) - {"precision"}:
            raise Refusal(f"Float() takes no keyword {sorted(set(kwargs) - {'precision'})[0]!r}")
        precision = self.integer(kwargs["precision"]) if "precision" in kwargs else 53
        if not 1 <= precision <= 1000:
            raise Refusal(f"Float() precision {precision} is outside 1..1000")
        if not math.isfinite(float(digits)):
            raise Refusal(f"the number {digits!r} is not a finite double-precision float")
        return check_value(sp.Float(digits, precision=precision))

    def symbol(self, arg, kwargs: dict):
        name = self.string(arg, _SYMBOL_NAME, "a dotted symbol name")
        if "__" in name:
            raise Refusal(f"symbol name {name!r} is not allowed (names with '__' are reserved)")
        assumptions = {}
        for key, value in kwargs.items():
            if key not in _ASSUMPTIONS or not (isinstance(value, ast.Constant) and isinstance(value.value, bool)):
                raise Refusal(f"Symbol() takes assumptions such as real=True, not {key}={self.seg(value)}", value)
            assumptions[key] = value.value
        try:
            return sp.Symbol(name, **assumptions)
        except Exception as exc:  # noqa: BLE001 - inconsistent assumptions
            raise Refusal(f"Symbol({name!r}): {_first_line(exc)}") from None

    def matrix(self, cls, args: list, depth: int):
        if len(args) == 3:  # (rows, cols, flat entries): written for empty matrices
            rows, cols = self.integer(args[0]), self.integer(args[1])
            entries = self.rows(args[2], depth, flat=True)
            if not (0 <= rows <= MAX_ARGS and 0 <= cols <= MAX_ARGS and rows * cols == len(entries)):
                raise Refusal(f"a {rows}x{cols} matrix cannot hold {len(entries)} entries")
            return cls(rows, cols, entries)
        if len(args) != 1:
            raise Refusal("a matrix takes a list of rows")
        rows = self.rows(args[0], depth, flat=False)
        if len({len(r) for r in rows}) > 1:
            raise Refusal("the rows of a matrix differ in length")
        return cls(rows)

    def rows(self, node, depth: int, flat: bool) -> list:
        if not isinstance(node, ast.List) or len(node.elts) > MAX_ARGS:
            raise Refusal(f"expected a list of {'entries' if flat else 'rows'}, not {type(node).__name__} {self.seg(node)}",
                           node)
        if flat:
            return [self.visit(e, depth + 1) for e in node.elts]
        out = []
        for row in node.elts:
            if not isinstance(row, ast.List) or len(row.elts) > MAX_ARGS:
                raise Refusal(f"expected a row (a list of entries), not {type(row).__name__} {self.seg(row)}", row)
            out.append([self.visit(e, depth + 2) for e in row.elts])
        return out
