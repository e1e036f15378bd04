"""Reading expressions and units from text without running it.

Every string that comes from a file or a command line (an input expression,
a unit, an expression of a saved model) is read here and nowhere else.  The
text is parsed with :func:`ast.parse` and the syntax tree is walked against a
whitelist; the value is built node by node by the project's own code, never
by ``eval``, ``sympify`` or ``parse_expr`` (which run Python).  Two grammars
share the walk, the limits and the error messages:

* **infix** (:func:`evaluate` with an :class:`Arithmetic`): numbers, names,
  ``+ - * / **``, unary minus and calls of whitelisted functions, as in
  ``5000*sin(2*pi*t)`` or ``N*m/rad``;
* **stored** (:func:`phs.stored_expressions.parse_srepr`): the ``srepr`` text a saved model holds,
  a tree of whitelisted sympy constructors, as in
  ``Mul(Integer(2), Symbol('x', real=True))``.

Nothing else is accepted: no string constants (except a symbol's name and a
float's digits in the stored grammar), no attributes, subscripts, lambdas,
comprehensions, f-strings or keywords (except those a whitelisted call
declares).  Sizes are bounded: text length, nesting depth, exponent
magnitude, integer size, and numbers must be finite, so ``9**9**9`` or
``1e400`` are refused at once instead of hanging or overflowing.  Every
refusal is one line naming where the text came from and what is wrong.

Examples
--------
>>> t = sp.Symbol("t", real=True)
>>> evaluate("5000*sin(2*pi*t)", "--input", Arithmetic({"t": t, "pi": sp.pi}, {"sin": sp.sin}))
5000*sin(2*pi*t)
>>> try:
...     evaluate("__import__('os')", "--input", Arithmetic({"t": t}))
... except InputDataError as err:
...     print(err)
--input: name '__import__' is not allowed (names with '__' are reserved)
>>> try:
...     evaluate('sin("1")', "--input", Arithmetic({}, {"sin": sp.sin}))
... except InputDataError as err:
...     print(err)
--input: Constant '"1"': string constants are not allowed
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

import sympy as sp

from phs.errors import InputDataError

MAX_DEPTH = 100
"""Deepest nesting of the syntax tree (the saved models use about 20 levels)."""

MAX_EXPONENT = 1000
"""Largest magnitude of a numeric exponent."""

MAX_BITS = 4096
"""Largest size in bits of an exact integer (numerator or denominator of a rational)."""

_Value = TypeVar("_Value")

MAX_ARGS = 10_000
"""Most arguments of one call (or rows of a matrix, or entries of one row)."""

_MAX_FLOAT = sp.Float(1.7976931348623157e308)
_OPERATORS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**", ast.Mod: "%"}
_SYNTAX = {  # what each refused kind of syntax is, in words
    ast.Attribute: "attribute access", ast.Subscript: "subscripts", ast.Lambda: "lambdas",
    ast.ListComp: "comprehensions", ast.SetComp: "comprehensions", ast.DictComp: "comprehensions",
    ast.GeneratorExp: "comprehensions", ast.JoinedStr: "f-strings", ast.FormattedValue: "f-strings",
    ast.Compare: "comparisons", ast.BoolOp: "boolean operators", ast.IfExp: "conditional expressions",
    ast.NamedExpr: "assignments", ast.Starred: "unpacking", ast.List: "lists", ast.Tuple: "tuples",
    ast.Dict: "dictionaries", ast.Set: "sets", ast.Await: "await", ast.Yield: "yield", ast.YieldFrom: "yield",
    ast.BinOp: "operators",
}


class Refusal(Exception):
    """Raised by the methods of an :class:`Arithmetic` to refuse a value: what is wrong (and the node).

    The walk turns it into one line of the caller's error type, naming where
    the text came from and the piece of text refused.
    """

    def __init__(self, what: str, node: ast.AST | None = None):
        super().__init__(what)
        self.what, self.node = what, node


def _quote(text: str, limit: int = 60) -> str:
    """``repr`` of ``text``, shortened when long."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + f"... ({len(text)} characters)"


def _first_line(exc: BaseException, limit: int = 300) -> str:
    lines = str(exc).strip().splitlines()
    line = lines[0] if lines else type(exc).__name__
    return line if len(line) <= limit else line[: limit - 3] + "..."


def parse_tree(text, where: str, *, error: type[Exception] = InputDataError, max_length: int = 1000) -> ast.expr:
    """Syntax tree of one Python expression, refusing text that is too long or not an expression.

    Parameters
    ----------
    text : str
        The expression.
    where : str
        Where the text comes from (an option, a file field), said first in errors.
    error : exception class
        The error raised (``InputDataError``, ``UnitError``, ...).
    max_length : int
        Longest text accepted, in characters.

    Examples
    --------
    >>> try:
    ...     parse_tree("1 +", "--input")
    ... except InputDataError as err:
    ...     print(err)
    --input: cannot read '1 +': invalid syntax
    """
    if not isinstance(text, str):
        raise error(f"{where}: expected text, got {type(text).__name__}")
    if len(text) > max_length:
        raise error(f"{where}: {_quote(text)} is longer than {max_length} characters")
    try:
        return ast.parse(text.strip(), mode="eval").body
    except SyntaxError as exc:
        raise error(f"{where}: cannot read {_quote(text)}: {exc.msg}") from None
    except (ValueError, RecursionError, MemoryError) as exc:  # null bytes, nesting too deep for the parser
        raise error(f"{where}: cannot read {_quote(text)}: {_first_line(exc) or 'nested too deeply'}") from None


def _refuse_syntax(node: ast.AST, text: str) -> None:
    """Raise the refusal of a node no grammar accepts."""
    kind = type(node).__name__
    seg = ast.get_source_segment(text, node) or ""
    if isinstance(node, ast.Attribute):
        raise Refusal(f"{kind} '.{node.attr}': attribute access is not allowed", node)
    if isinstance(node, ast.Constant):
        what = {str: "string constants", bytes: "bytes constants", complex: "complex numbers",
                bool: "True and False"}.get(type(node.value), f"the constant {seg}")
        raise Refusal(f"{kind} {_quote(seg, 30)}: {what} are not allowed", node)
    what = "operators" if isinstance(node, ast.operator) else "unary operators" if isinstance(node, ast.unaryop) else None
    raise Refusal(f"{kind}: {what or _SYNTAX.get(type(node), 'expressions of this kind')} are not allowed", node)


_INFIX_NODES = (ast.Constant, ast.Name, ast.Load, ast.UnaryOp, ast.USub, ast.UAdd, ast.BinOp, ast.Call, ast.keyword,
                *_OPERATORS)
_STORED_NODES = (ast.Constant, ast.Name, ast.Load, ast.UnaryOp, ast.USub, ast.Call, ast.keyword, ast.List)


def _prescan(tree: ast.AST, text: str, allowed: tuple) -> None:
    """Refuse the whole text at a reserved name, then at a node kind outside ``allowed``, before building anything."""
    nodes = list(ast.walk(tree))
    for node in nodes:
        if isinstance(node, ast.Name):
            _check_name(node.id, node)
    for node in nodes:
        if not isinstance(node, allowed):
            _refuse_syntax(node, text)


def _check_name(name: str, node: ast.AST) -> None:
    if "__" in name:
        raise Refusal(f"name {name!r} is not allowed (names with '__' are reserved)", node)


def _run(text: str, where: str, error: type[Exception], walk: Callable[[], Any]):
    """Run ``walk`` and turn a refusal or a failing constructor into one line of ``error``."""
    try:
        return walk()
    except Refusal as exc:
        seg = ast.get_source_segment(text.strip(), exc.node) if exc.node is not None else None
        what = _first_line(exc)
        at = f" in {_quote(seg)}" if seg and seg != text.strip() and seg not in what else ""
        raise error(f"{where}: {what}{at}") from None
    except RecursionError:
        raise error(f"{where}: nested too deeply") from None


# -- numbers and powers ------------------------------------------------------------------------------------
def check_value(value: _Value, exact: bool = True) -> _Value:
    """Refuse a built value that is infinite, undefined or too large; return it otherwise.

    Rationals are limited to :data:`MAX_BITS` bits; floats, and every number
    when ``exact`` is False, must be finite double-precision numbers.

    Examples
    --------
    >>> check_value(sp.Integer(2) ** 10)
    1024
    """
    if value in (sp.zoo, sp.nan, sp.oo, -sp.oo):
        raise Refusal("the result is not finite (a division by zero or a logarithm of zero?)")
    if isinstance(value, sp.Rational):
        if max(abs(value.p).bit_length(), value.q.bit_length()) > MAX_BITS:
            raise Refusal(f"a number has more than {MAX_BITS} bits")
        if not exact and abs(value) > _MAX_FLOAT:
            raise Refusal("a number is too large for a double-precision float")
    elif isinstance(value, sp.Float) and not (value.is_finite and abs(value) <= _MAX_FLOAT):
        raise Refusal("a number is not a finite double-precision float")
    return value


def power(base, exponent, exact: bool = True) -> sp.Expr:
    """``base**exponent`` with the exponent and the size of the result bounded before computing it.

    Examples
    --------
    >>> power(sp.Integer(9), sp.Integer(99)) == 9**99
    True
    >>> try:
    ...     power(sp.Integer(9), sp.Integer(9) ** 9)
    ... except Refusal as refusal:
    ...     print(refusal)
    exponent 387420489 is larger than 1000 in magnitude
    """
    if isinstance(exponent, sp.Number):
        if abs(exponent) > MAX_EXPONENT:
            raise Refusal(f"exponent {exponent} is larger than {MAX_EXPONENT} in magnitude")
        if isinstance(base, sp.Rational) and isinstance(exponent, sp.Integer):
            bits = max(abs(base.p).bit_length(), base.q.bit_length()) * abs(int(exponent))
            if bits > MAX_BITS:
                raise Refusal(f"{base}**{exponent} has more than {MAX_BITS} bits")
    return check_value(sp.Pow(base, exponent), exact)


def _number(value, node: ast.AST, text: str, exact: bool):
    """A sympy number from a numeric literal (bounded)."""
    seg = ast.get_source_segment(text, node) or repr(value)
    if isinstance(value, int):
        if value.bit_length() > (MAX_BITS if exact else 1024):
            raise Refusal(f"the number {_quote(seg, 30)} is too large", node)
        return sp.Integer(value)
    if not math.isfinite(value):
        raise Refusal(f"the number {_quote(seg, 30)} is not a finite double-precision float", node)
    return sp.Rational(repr(value)) if exact else sp.Float(value)


# -- the infix grammar -------------------------------------------------------------------------------------
class Arithmetic:
    """How :func:`evaluate` builds a value from the nodes of an infix expression.

    This base builds sympy expressions: ``names`` maps the allowed names to
    values, ``functions`` the allowed function names to callables taking
    positional sympy arguments.  ``exact`` reads decimals as rationals
    (``2.5`` -> ``5/2``, for units) instead of floats.  Subclasses may accept
    other values (signals) or keywords by overriding the methods.
    """

    operators = frozenset({"+", "-", "*", "/", "**"})

    def __init__(self, names: Mapping[str, Any], functions: Mapping[str, Callable] | None = None, *,
                 exact: bool = False, hint: str = ""):
        self.names, self.functions, self.exact, self.hint = dict(names), dict(functions or {}), exact, hint

    def number(self, value, node, text) -> sp.Number:
        """A numeric literal (bounded; exact rationals or floats)."""
        return _number(value, node, text, self.exact)

    def name(self, name: str) -> Any:
        """The value of a name, or a refusal naming it."""
        if name in self.names:
            return self.names[name]
        if name in self.functions:
            raise Refusal(f"{name!r} is a function: call it, as in {name}(...)")
        raise Refusal(f"unknown name {name!r}{self.hint}")

    def keywords(self, name: str) -> frozenset:
        """Keyword arguments the call of ``name`` accepts (none)."""
        return frozenset()

    def call(self, name: str, args: list, kwargs: dict) -> Any:
        """A whitelisted function applied to built arguments; infinite results are refused."""
        try:
            value = self.functions[name](*args, **kwargs)
        except Refusal:
            raise
        except Exception as exc:  # noqa: BLE001 - a constructor refusing its (already safe) arguments
            raise Refusal(f"{name}(): {_first_line(exc)}") from None
        if value in (sp.zoo, sp.nan, sp.oo, -sp.oo):
            shown = ", ".join(map(str, args))
            raise Refusal(f"{name}({shown if len(shown) <= 40 else '...'}) is not finite")
        return check_value(value, self.exact)

    def binary(self, op: str, a, b) -> Any:
        """``a op b`` for an operator in :attr:`operators`, bounded (powers) and checked (division by zero)."""
        if op == "**":
            return power(a, b, self.exact)
        if op in ("/", "%") and getattr(b, "is_zero", False):
            raise Refusal("division by zero")
        value = {"+": lambda: sp.Add(a, b), "-": lambda: sp.Add(a, -b), "*": lambda: sp.Mul(a, b),
                 "/": lambda: sp.Mul(a, sp.Pow(b, -1)), "%": lambda: sp.Mod(a, b)}[op]()
        return check_value(value, self.exact)

    def negate(self, a) -> Any:
        """``-a``."""
        return -a


def evaluate(text, where: str, arithmetic: Arithmetic, *, error: type[Exception] = InputDataError,
             max_length: int = 1000) -> Any:
    """Value of an infix expression, built node by node by ``arithmetic``.

    Raises
    ------
    error
        One line naming ``where`` and what is wrong: unreadable text, syntax
        outside the grammar, an unknown name or function, a keyword the call
        does not take, a number or exponent out of bounds, a division by zero.

    Examples
    --------
    >>> evaluate("2**10 / 4", "--x", Arithmetic({}))
    256
    >>> try:
    ...     evaluate("9**9**9", "--x", Arithmetic({}))
    ... except InputDataError as err:
    ...     print(err)
    --x: exponent 387420489 is larger than 1000 in magnitude
    """
    tree = parse_tree(text, where, error=error, max_length=max_length)
    body = text.strip()

    def visit(node, depth):
        if depth > MAX_DEPTH:
            raise Refusal(f"nested deeper than {MAX_DEPTH} levels", node)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return arithmetic.number(node.value, node, body)
        if isinstance(node, ast.Name):
            _check_name(node.id, node)
            return _at(node, lambda: arithmetic.name(node.id))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            a = visit(node.operand, depth + 1)
            return _at(node, lambda: arithmetic.negate(a)) if isinstance(node.op, ast.USub) else a
        if isinstance(node, ast.BinOp):
            op = _OPERATORS.get(type(node.op))
            if op not in arithmetic.operators:
                raise Refusal(f"the operator {op or type(node.op).__name__} is not allowed", node)
            a, b = visit(node.left, depth + 1), visit(node.right, depth + 1)
            return _at(node, lambda: arithmetic.binary(op, a, b))
        if isinstance(node, ast.Call):
            return _call(node, depth)
        _refuse_syntax(node, body)

    def _call(node, depth):
        if not isinstance(node.func, ast.Name):
            raise Refusal(f"only named functions can be called, not {_quote(ast.get_source_segment(body, node.func) or '?', 30)}",
                           node)
        name = node.func.id
        _check_name(name, node.func)
        if name not in arithmetic.functions:
            raise Refusal(f"unknown function {name!r}{arithmetic.hint}", node)
        if len(node.args) + len(node.keywords) > MAX_ARGS:
            raise Refusal(f"{name}() has more than {MAX_ARGS} arguments", node)
        allowed = arithmetic.keywords(name)
        kwargs = {}
        for kw in node.keywords:
            if kw.arg is None or kw.arg not in allowed:
                what = "**" if kw.arg is None else repr(kw.arg)
                raise Refusal(f"{name}() takes no keyword argument {what}"
                               + (f" (it takes {', '.join(sorted(allowed))})" if allowed else ""), node)
            v = kw.value
            kwargs[kw.arg] = v.value if isinstance(v, ast.Constant) and isinstance(v.value, bool) else visit(v, depth + 1)
        args = [visit(a, depth + 1) for a in node.args]
        return _at(node, lambda: arithmetic.call(name, args, kwargs))

    return _run(text, where, error, lambda: (_prescan(tree, body, _INFIX_NODES), visit(tree, 0))[1])


def _at(node: ast.AST, build: Callable[[], Any]):
    """``build()``, attaching ``node`` to a refusal that names no node."""
    try:
        return build()
    except Refusal as exc:
        if exc.node is None:
            exc.node = node
        raise
