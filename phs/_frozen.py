"""Read-only values held by a frozen model (:class:`phs.PHSystem`).

A model is a value: everything it holds and everything it hands out (matrices, the terms of its
power balance, its dissipation forms, its structure) is immutable, so no cached result (derived
matrices, checks, generated functions keyed by the model's hash) can speak of another model than
the one simulated.  Matrices become sympy ``ImmutableDenseMatrix``; mappings :class:`FrozenDict`;
lists tuples.
"""

from __future__ import annotations

import sympy as sp

FROZEN = "a PHSystem is frozen: build a new one with with_params(), with_measured(), renamed() or interconnect()"


class FrozenDict(dict):
    """A dict that refuses every change (a model's mapping); it pickles, copies and compares as a dict.

    Examples
    --------
    >>> d = FrozenDict({"a": 1})
    >>> d["a"], d == {"a": 1}
    (1, True)
    >>> d["a"] = 2
    Traceback (most recent call last):
    ...
    TypeError: a PHSystem is frozen: build a new one with with_params(), with_measured(), renamed() or interconnect()
    """

    __slots__ = ()

    def _refuse(self, *args, **kwargs):
        raise TypeError(FROZEN)

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = __ior__ = _refuse

    def __reduce__(self):
        return (type(self), (dict(self),))

    def __copy__(self) -> FrozenDict:
        return self

    def __deepcopy__(self, memo) -> FrozenDict:
        return self


def frozen_matrix(M) -> sp.ImmutableDenseMatrix:
    """``M`` as a sympy ``ImmutableDenseMatrix`` (no copy when it already is one).

    Examples
    --------
    >>> M = frozen_matrix(sp.Matrix([[1, 0], [0, 2]]))
    >>> type(M).__name__, M[1, 1]
    ('ImmutableDenseMatrix', 2)
    """
    if isinstance(M, sp.ImmutableDenseMatrix):
        return M
    if isinstance(M, sp.MutableDenseMatrix):
        return M.as_immutable()  # a copy: later changes of ``M`` do not reach the frozen one
    return sp.ImmutableDenseMatrix(M)


def frozen(value):
    """A read-only copy of a structure value: dicts become :class:`FrozenDict`, lists and tuples tuples,
    sets frozensets, matrices immutable matrices (recursively); anything else is kept.

    Examples
    --------
    >>> frozen({"components": ["R", "C"], "nested": {"k": [1, 2]}})
    {'components': ('R', 'C'), 'nested': {'k': (1, 2)}}
    """
    if isinstance(value, dict):
        return FrozenDict({k: frozen(v) for k, v in value.items()})
    if isinstance(value, list) or type(value) is tuple:
        return tuple(frozen(v) for v in value)
    if isinstance(value, (set, frozenset)):
        return frozenset(frozen(v) for v in value)
    if isinstance(value, sp.MatrixBase):
        return frozen_matrix(value)
    return value
