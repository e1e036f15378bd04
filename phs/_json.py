"""Plain JSON values from results holding numpy scalars and arrays, complex numbers and non-finite floats."""

from __future__ import annotations

import math

import numpy as np


def jsonable(obj):
    """``obj`` with every value JSON can hold as itself: dict keys as strings, tuples and arrays as
    lists, numpy scalars as Python numbers, non-finite floats as ``None`` (JSON has no NaN),
    complex numbers as ``[real, imag]``, and anything else that is not a string or ``None`` as its
    ``str``.

    Examples
    --------
    >>> jsonable({"a": np.array([1.0, np.nan]), 2: (np.int64(3), np.bool_(True), 1 + 2j), "f": object}) \\
    ...     == {"a": [1.0, None], "2": [3, True, [1.0, 2.0]], "f": "<class 'object'>"}
    True
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, (complex, np.complexfloating)):
        return [jsonable(float(obj.real)), jsonable(float(obj.imag))]
    return obj if obj is None or isinstance(obj, str) else str(obj)
