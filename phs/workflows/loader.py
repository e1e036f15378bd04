"""Load a model named on the command line: ``module:function``, ``path/file.py:function``, or a
model saved as JSON (``FILE.json``, written by :meth:`PHSystem.save`).

The function is called without arguments and must return a
:class:`~phs.system.PHSystem`; ``--param NAME=VALUE`` overrides are then
applied with :meth:`PHSystem.with_params`.  Every failure (bad spec, missing
module, file or function, an exception inside the function, a wrong return
type) becomes one :class:`~phs.errors.InputDataError` naming the culprit; no
traceback is printed.  A JSON model is read by the safe reader of :mod:`phs.io` only: its
expressions are data, never run.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from types import ModuleType

from phs.errors import InputDataError, PHSError
from phs.system import PHSystem


def _describe(exc: BaseException) -> str:
    text = str(exc).replace("\n", " ").strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _import_file(path: str, spec: str) -> ModuleType:
    if not os.path.isfile(path):
        where = "does not exist" if not os.path.exists(path) else "is not a file"
        raise InputDataError(f"MODEL {spec!r}: file {path!r} {where}")
    abspath = os.path.abspath(path)
    name = "_phs_model_" + hashlib.sha1(abspath.encode()).hexdigest()[:12]
    mspec = importlib.util.spec_from_file_location(name, abspath)
    if mspec is None or mspec.loader is None:
        raise InputDataError(f"MODEL {spec!r}: cannot import {path!r} as a Python file")
    module = importlib.util.module_from_spec(mspec)
    sys.modules[name] = module  # dataclasses and pickling look the module up by name
    try:
        mspec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[name]
        raise InputDataError(f"MODEL {spec!r}: importing file {path!r} failed with {_describe(exc)}") from None
    return module


def _import_module(modname: str, spec: str) -> ModuleType:
    added = os.getcwd() not in sys.path
    if added:  # like `python -m`, let modules in the working directory be found
        sys.path.insert(0, os.getcwd())
    try:
        return importlib.import_module(modname)
    except ModuleNotFoundError as exc:
        if exc.name and (modname == exc.name or modname.startswith(exc.name + ".")):
            raise InputDataError(f"MODEL {spec!r}: module {exc.name!r} not found") from None
        raise InputDataError(f"MODEL {spec!r}: importing module {modname!r} failed with {_describe(exc)}") from None
    except Exception as exc:
        raise InputDataError(f"MODEL {spec!r}: importing module {modname!r} failed with {_describe(exc)}") from None
    finally:
        if added and os.getcwd() in sys.path:
            sys.path.remove(os.getcwd())


def _load_json(spec: str) -> PHSystem:
    """A model saved with :meth:`PHSystem.save`, read as data (never run); errors name the file."""
    if not os.path.isfile(spec):
        where = "does not exist" if not os.path.exists(spec) else "is not a file"
        raise InputDataError(f"MODEL {spec!r}: file {where}")
    try:
        return PHSystem.load(spec)
    except (PHSError, OSError, ValueError) as exc:
        raise InputDataError(f"MODEL {spec!r}: not a readable saved model: {_describe(exc)}") from None


def load_model(spec: str, params: dict | None = None) -> PHSystem:
    """Build the system named by ``spec`` and apply parameter overrides.

    Parameters
    ----------
    spec : str
        ``module:function`` (``systems.examples:rc_circuit``) or
        ``path/to/file.py:function``; the function is called without
        arguments.  Dotted attributes (``module:Class.factory``) are allowed.
        Or a path ending in ``.json``: a model saved with :meth:`PHSystem.save`.
    params : dict of str -> float, optional
        Parameter overrides by name.

    Returns
    -------
    PHSystem

    Raises
    ------
    InputDataError
        When the spec has no colon, the module or file cannot be found or
        imported, the function is missing, raises, or does not return a
        PHSystem; when a ``.json`` model cannot be read.
    ParameterError
        When an override names an unknown parameter or is not a finite number.

    Examples
    --------
    >>> load_model("systems.examples:rc_circuit", {"R.R": 2e3}).param("R.R").value
    2000.0
    >>> load_model("systems.examples")
    Traceback (most recent call last):
    ...
    phs.errors.InputDataError: MODEL 'systems.examples' must be 'module:function', 'path/file.py:function' or FILE.json
    >>> import os, tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     load_model("systems.examples:rc_circuit", {"R.R": 2e3}).save(os.path.join(d, "rc.json"))
    ...     load_model(os.path.join(d, "rc.json")).param("R.R").value
    2000.0
    """
    if isinstance(spec, str) and spec.lower().endswith(".json"):
        system = _load_json(spec)
        return system.with_params(params) if params else system
    if not isinstance(spec, str) or ":" not in spec:
        raise InputDataError(f"MODEL {spec!r} must be 'module:function', 'path/file.py:function' or FILE.json")
    where, _, attr = spec.rpartition(":")
    if not where or not attr:
        raise InputDataError(f"MODEL {spec!r} must be 'module:function', 'path/file.py:function' or FILE.json")
    is_file = where.endswith(".py") or "/" in where or os.sep in where
    module = _import_file(where, spec) if is_file else _import_module(where, spec)
    what = f"file {where!r}" if is_file else f"module {where!r}"
    obj = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            known = sorted(n for n, v in vars(module).items() if callable(v) and not n.startswith("_"))
            hint = f"; available: {', '.join(known)}" if known and obj is module else ""
            raise InputDataError(f"MODEL {spec!r}: {what} has no function {attr!r}{hint}")
        obj = getattr(obj, part)
    if isinstance(obj, PHSystem):
        system = obj
    else:
        if not callable(obj):
            raise InputDataError(f"MODEL {spec!r}: {attr!r} in {what} is a {type(obj).__name__}, not a function")
        try:
            system = obj()
        except Exception as exc:
            raise InputDataError(f"MODEL {spec!r}: function {attr!r} raised {_describe(exc)}") from None
    if not isinstance(system, PHSystem):
        raise InputDataError(
            f"MODEL {spec!r}: function {attr!r} returned a {type(system).__name__}, not a PHSystem"
        )
    return system.with_params(params) if params else system
