"""Saving and loading systems as JSON files.

A saved system holds its whole definition (states, inputs, parameters with
values and units, energy terms, the matrices J, R, G, P, S, N, measured
outputs, validity conditions, dissipators, definitions and structure).  Every
expression is stored as sympy's ``srepr`` string, which keeps the symbols'
assumptions (``positive=True``), and is read back through a restricted
namespace of sympy classes only.  Loading goes through the
:class:`~phs.system.PHSystem` constructor, so a loaded model is validated
again.

Examples
--------
>>> import tempfile, os
>>> from systems.examples import rc_circuit
>>> with tempfile.TemporaryDirectory() as d:
...     path = os.path.join(d, "rc.json")
...     save_system(rc_circuit(R=2e3), path)
...     load_system(path).param("R.R").value
2000.0
"""

from __future__ import annotations

import ast
import json
import os
import tempfile
from typing import Any

import sympy as sp
from sympy.parsing.sympy_parser import parse_expr

from phs.errors import InputDataError, PHSError
from phs.params import Condition, EnergyTerm, InputInfo, Measured, Param, StateInfo

FORMAT = "phs.system"
"""Value of the ``format`` field of a saved system."""

FORMAT_VERSION = 1
"""Version of the file layout written by :func:`save_system`."""

_MATRICES = ("J", "R", "G", "P", "S", "N")


# -- writing ------------------------------------------------------------------------------
def system_to_dict(system) -> dict[str, Any]:
    """The JSON-ready dictionary :func:`save_system` writes.

    Examples
    --------
    >>> from systems.examples import rc_circuit
    >>> d = system_to_dict(rc_circuit())
    >>> d["format"], d["version"], [p["name"] for p in d["params"]]
    ('phs.system', 1, ['R.R', 'C.C'])
    """
    s = system
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "name": s.name,
        "description": s.description,
        "states": [
            {"name": x.name, "unit": x.unit, "range": list(x.range), "description": x.description, "kind": x.kind,
             "scale": x.scale, "owner": x.owner, "rest": x.rest}
            for x in s.states
        ],
        "inputs": [
            {"name": u.name, "unit": u.unit, "output": u.output, "output_unit": u.output_unit, "kind": u.kind,
             "description": u.description, "range": None if u.range is None else list(u.range)}
            for u in s.inputs
        ],
        "params": [
            {"name": p.name, "value": p.value, "unit": p.unit, "description": p.description, "range": list(p.range),
             "positive": p.positive}
            for p in s.params
        ],
        "energy": [{"label": e.label, "expr": sp.srepr(e.expr)} for e in s.energy_terms],
        "matrices": {k: sp.srepr(getattr(s, k)) for k in _MATRICES},
        "measured": [
            {"name": m.name, "expr": sp.srepr(sp.sympify(m.expr)), "unit": m.unit, "description": m.description}
            for m in s.measured
        ],
        "conditions": [
            {"label": c.label, "expr": sp.srepr(c.expr), "description": c.description} for c in s.conditions
        ],
        "dissipators": [
            {"label": label, "entries": {f"{i},{j}": sp.srepr(v) for (i, j), v in entries.items()}}
            for label, entries in s.dissipators
        ],
        "definitions": [_definition_to_dict(d) for d in s.definitions],
        "structure": _plain(s.structure),
    }


def _definition_to_dict(d) -> dict[str, str]:
    if isinstance(d, (tuple, list)):
        symbol, expr, label = d[0], d[1], d[2]
    else:  # a phs.component.Definition
        symbol, expr, label = d.symbol, d.expr, d.label
    return {"symbol": sp.srepr(symbol), "expr": sp.srepr(expr), "label": str(label)}


def _plain(obj):
    """JSON-ready copy of a structure value (sympy objects become ``{"srepr": ...}``)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    if isinstance(obj, sp.Basic):
        return {"srepr": sp.srepr(obj)}
    return str(obj)


def _unplain(obj, reader):
    """Inverse of :func:`_plain`."""
    if isinstance(obj, dict):
        if set(obj) == {"srepr"}:
            return reader.expr(obj["srepr"], "structure entry")
        return {k: _unplain(v, reader) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_unplain(v, reader) for v in obj]
    return obj


def save_system(system, path) -> None:
    """Save a system's definition and parameter values to a JSON file, atomically.

    The text is written to a temporary file in the target directory and then
    renamed into place, so either the complete file appears or nothing does.

    Parameters
    ----------
    system : PHSystem
        The system to save.
    path : str or path-like
        Target file (conventionally ``*.json``).

    Raises
    ------
    InputDataError
        If the target directory does not exist or cannot be written.

    Examples
    --------
    >>> import tempfile, os
    >>> from systems.examples import mass_spring_damper
    >>> with tempfile.TemporaryDirectory() as d:
    ...     save_system(mass_spring_damper(), os.path.join(d, "msd.json"))
    ...     os.listdir(d)
    ['msd.json']
    """
    text = json.dumps(system_to_dict(system), indent=1)
    write_atomic(path, text)


def write_atomic(path, data: str | bytes) -> None:
    """Write text or bytes to ``path`` through a temporary file in the same directory.

    Either the complete file appears or nothing does (the temporary file is
    removed on any failure).

    Raises
    ------
    InputDataError
        Naming the file when its directory is missing or the write fails.

    Examples
    --------
    >>> import tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_atomic(os.path.join(d, "a.txt"), "hello")
    ...     open(os.path.join(d, "a.txt")).read()
    'hello'
    """
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        raise InputDataError(f"cannot write {path!r}: directory {d!r} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=os.path.splitext(path)[1], dir=d)
    except OSError as exc:
        raise InputDataError(f"cannot write {path!r}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp makes the file private (0600); give it the mode of the file it replaces, or 0644
        os.chmod(tmp, os.stat(path).st_mode & 0o777 if os.path.exists(path) else 0o644)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise InputDataError(f"cannot write {path!r}: {exc.strerror or exc}") from None
        raise


# -- reading ------------------------------------------------------------------------------
def _sympy_namespace() -> dict[str, Any]:
    """Sympy's public classes and constants, then every other loaded Basic subclass by name."""
    ns: dict[str, Any] = {}
    for name, obj in vars(sp).items():
        if name.startswith("_"):
            continue
        if isinstance(obj, type) and issubclass(obj, (sp.Basic, sp.MatrixBase)):
            ns[name] = obj
    for name in ("pi", "E", "I", "oo", "zoo", "nan", "true", "false", "EulerGamma", "GoldenRatio", "Catalan"):
        ns[name] = getattr(sp, name)
    ns["Function"] = sp.Function
    todo = [sp.Basic]
    seen = set()
    while todo:  # classes not exported at top level (ExprCondPair, ...) and user-defined functions
        cls = todo.pop()
        for sub in cls.__subclasses__():
            if sub not in seen:
                seen.add(sub)
                todo.append(sub)
                if not sub.__name__.startswith("_"):
                    ns.setdefault(sub.__name__, sub)
    return ns


_NAMESPACE: dict[str, Any] = {}


def _namespace(name: str) -> dict[str, Any]:
    """The namespace, rebuilt when ``name`` is unknown (classes defined since the last build)."""
    if name not in _NAMESPACE:
        _NAMESPACE.update(_sympy_namespace())
    return _NAMESPACE


_ALLOWED_NODES = (ast.Expression, ast.Call, ast.Name, ast.Load, ast.Constant, ast.keyword, ast.List, ast.Tuple,
                  ast.UnaryOp, ast.USub, ast.UAdd)


def parse_srepr(text: str, where: str = "expression") -> sp.Basic:
    """Rebuild a sympy object from its ``srepr`` string, allowing sympy classes only.

    Parameters
    ----------
    text : str
        Output of :func:`sympy.srepr`.
    where : str
        What the string is (used in the error message).

    Raises
    ------
    InputDataError
        If the string is not a call tree of sympy classes and literals.

    Examples
    --------
    >>> e = parse_srepr(sp.srepr(sp.Symbol("C.C", positive=True) ** 2))
    >>> e, e.free_symbols.pop().is_positive
    (C.C**2, True)
    """
    if not isinstance(text, str):
        raise InputDataError(f"{where}: expected a srepr string, got {type(text).__name__}")
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise InputDataError(f"{where}: cannot read {text[:60]!r}: {exc.msg}") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED_NODES):
            raise InputDataError(f"{where}: {type(node).__name__} is not allowed in a stored expression")
        if isinstance(node, ast.Name) and node.id not in _namespace(node.id):
            raise InputDataError(f"{where}: unknown name {node.id!r} (only sympy classes are allowed)")
    try:
        return parse_expr(text, local_dict={}, global_dict={"__builtins__": {}, **_NAMESPACE}, transformations=())
    except Exception as exc:  # any failure of sympy's constructors means a corrupt entry
        raise InputDataError(f"{where}: cannot rebuild {text[:60]!r}: {exc}") from None


class _Reader:
    """Reads one saved file and turns structural problems into InputDataError naming the file and field."""

    def __init__(self, path: str):
        self.path = path

    def fail(self, what: str) -> InputDataError:
        return InputDataError(f"cannot load system from {self.path!r}: {what}")

    def get(self, d, key, where, kind=None, default=...):
        if not isinstance(d, dict):
            raise self.fail(f"{where} is not an object")
        if key not in d:
            if default is not ...:
                return default
            raise self.fail(f"missing field {where}.{key}")
        v = d[key]
        if kind is not None and not isinstance(v, kind):
            raise self.fail(f"field {where}.{key} has type {type(v).__name__}")
        return v

    def expr(self, text, where) -> sp.Basic:
        try:
            return parse_srepr(text, where)
        except InputDataError as exc:
            raise self.fail(str(exc)) from None

    def items(self, d, key) -> list:
        return self.get(d, key, "file", list)


def _rng(v):
    return None if v is None else tuple(float(a) for a in v)


def system_from_dict(data: dict, source: str = "<dict>"):
    """Rebuild a PHSystem from the dictionary written by :func:`system_to_dict`.

    Raises
    ------
    InputDataError
        Naming ``source`` and the missing or malformed field, or listing the
        problems the PHSystem constructor found.

    Examples
    --------
    >>> from systems.examples import duffing_oscillator
    >>> s = duffing_oscillator()
    >>> system_from_dict(system_to_dict(s)).H == s.H
    True
    """
    from phs.system import PHSystem

    r = _Reader(source)
    if not isinstance(data, dict):
        raise r.fail("the file does not hold a JSON object")
    fmt, version = data.get("format"), data.get("version")
    if fmt != FORMAT:
        raise r.fail(f"not a saved phs system (format {fmt!r}, expected {FORMAT!r})")
    if version != FORMAT_VERSION:
        raise r.fail(f"unsupported format version {version!r} (this version of phs reads {FORMAT_VERSION})")
    try:
        states = [
            StateInfo(r.get(x, "name", "states[]", str), x.get("unit", "1"), _rng(x.get("range", (-1.0, 1.0))),
                      x.get("description", ""), x.get("kind", "C"), x.get("scale"), x.get("owner", ""), x.get("rest"))
            for x in r.items(data, "states")
        ]
        inputs = [
            InputInfo(r.get(u, "name", "inputs[]", str), u.get("unit", "1"), u.get("output", ""),
                      u.get("output_unit", "1"), u.get("kind", "effort"), u.get("description", ""),
                      _rng(u.get("range")))
            for u in r.items(data, "inputs")
        ]
        params = [
            Param(r.get(p, "name", "params[]", str), r.get(p, "value", "params[]"), p.get("unit", "1"),
                  p.get("description", ""), _rng(p.get("range")), p.get("positive"))
            for p in r.items(data, "params")
        ]
        energy = [
            EnergyTerm(r.get(e, "label", "energy[]", str),
                       r.expr(r.get(e, "expr", "energy[]"), f"energy {e['label']!r}"))
            for e in r.items(data, "energy")
        ]
        mats = r.get(data, "matrices", "file", dict)
        matrices = {}
        for k in _MATRICES:
            M = r.expr(r.get(mats, k, "matrices", str), f"matrix {k}")
            if not isinstance(M, sp.MatrixBase):
                raise r.fail(f"matrix {k} is a {type(M).__name__}, not a matrix")
            matrices[k] = M
        measured = [
            Measured(r.get(m, "name", "measured[]", str),
                     r.expr(r.get(m, "expr", "measured[]"), f"measured {m['name']!r}"),
                     m.get("unit", "1"), m.get("description", ""))
            for m in r.items(data, "measured")
        ]
        conditions = [
            Condition(r.get(c, "label", "conditions[]", str),
                      r.expr(r.get(c, "expr", "conditions[]"), f"condition {c['label']!r}"), c.get("description", ""))
            for c in r.items(data, "conditions")
        ]
        dissipators = []
        for dd in r.items(data, "dissipators"):
            label = r.get(dd, "label", "dissipators[]", str)
            entries = {}
            for key, text in r.get(dd, "entries", "dissipators[]", dict).items():
                try:
                    i, j = (int(a) for a in key.split(","))
                except ValueError:
                    raise r.fail(f"dissipator {label!r}: entry key {key!r} is not 'i,j'") from None
                entries[(i, j)] = r.expr(text, f"dissipator {label!r} entry {key}")
            dissipators.append((label, entries))
        definitions = [
            (r.expr(r.get(d, "symbol", "definitions[]"), "definition symbol"),
             r.expr(r.get(d, "expr", "definitions[]"), f"definition {d.get('label')!r}"),
             r.get(d, "label", "definitions[]", str))
            for d in r.items(data, "definitions")
        ]
        name = r.get(data, "name", "file", str)
        description = r.get(data, "description", "file", str, default="")
        structure = _unplain(r.get(data, "structure", "file", dict, default={}), r)
    except InputDataError:
        raise
    except (TypeError, ValueError, AttributeError) as exc:
        raise r.fail(f"malformed entry: {exc}") from None
    try:
        return PHSystem(name, states, energy, matrices["J"], matrices["R"], matrices["G"], P=matrices["P"],
                        S=matrices["S"], N=matrices["N"], inputs=inputs, params=params, measured=measured,
                        conditions=conditions, dissipators=dissipators, definitions=definitions,
                        description=description, structure=structure)
    except PHSError as exc:
        raise InputDataError(f"cannot load system from {source!r}: the stored model is invalid", [str(exc)]) from None


def load_system(path):
    """Load a system saved with :func:`save_system` (or :meth:`PHSystem.save`).

    Parameters
    ----------
    path : str or path-like
        A JSON file written by :func:`save_system`.

    Returns
    -------
    PHSystem
        The rebuilt (and re-validated) system.

    Raises
    ------
    InputDataError
        Naming the file, when it is missing, not JSON, of another format or
        version, or when a field is missing or malformed.

    Examples
    --------
    >>> import tempfile, os
    >>> from systems.examples import rc_circuit
    >>> with tempfile.TemporaryDirectory() as d:
    ...     rc_circuit().save(os.path.join(d, "rc.json"))
    ...     load_system(os.path.join(d, "rc.json")).state_names
    ['C.Q']
    """
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
    except FileNotFoundError:
        raise InputDataError(f"cannot load system: file {path!r} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputDataError(f"cannot load system from {path!r}: {exc}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputDataError(
            f"cannot load system from {path!r}: not valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
        ) from None
    return system_from_dict(data, source=path)
