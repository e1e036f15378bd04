"""Lookup by name in a list of named results (tests of a certificate, certificates of a controller)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

T = TypeVar("T")


def find_named(items: Iterable[T], name: str, kind: str) -> T:
    """The item whose ``name`` is ``name``, or a ``KeyError`` listing the names there are.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> find_named([SimpleNamespace(name="a"), SimpleNamespace(name="b")], "b", "test").name
    'b'
    >>> find_named([SimpleNamespace(name="a")], "c", "test")
    Traceback (most recent call last):
    ...
    KeyError: "no test 'c'; tests: a"
    """
    items = list(items)
    for item in items:
        if item.name == name:
            return item
    raise KeyError(f"no {kind} {name!r}; {kind}s: {', '.join(item.name for item in items)}")
