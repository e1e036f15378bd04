"""Saving and loading systems as JSON files.

A saved system holds its whole definition (states, inputs, parameters with
values and units, energy terms, the matrices J, R, G, P, S, N, measured
outputs, validity conditions, dissipators, definitions and structure).  Every
expression is stored as sympy's ``srepr`` string, which keeps the symbols'
assumptions (``positive=True``), and is read back by the stored grammar of
:mod:`phs.safe_parse` (a whitelist of sympy constructors with bounded numbers:
nothing in the file is run); units are read by :func:`phs.units.parse_unit`.
Loading builds the class it is given (:meth:`PHSystem.load` passes
:class:`~phs.system.PHSystem`, so this module never imports it), and the
constructor validates the loaded model again.

Examples
--------
>>> import tempfile, os
>>> from phs import PHSystem
>>> from systems.examples import rc_circuit
>>> with tempfile.TemporaryDirectory() as d:
...     path = os.path.join(d, "rc.json")
...     save_system(rc_circuit(R=2e3), path)
...     load_system(path, PHSystem).param("R.R").value
2000.0
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from typing import Any, TypeVar

import sympy as sp

from phs._sparse import srepr_matrix
from phs.errors import InputDataError, PHSError, UnitError
from phs.params import Condition, EnergyTerm, InputInfo, Measured, StateInfo, stored_param
from phs.stored_expressions import parse_srepr
from phs.units import parse_unit

FORMAT = "phs.system"
"""Value of the ``format`` field of a saved system."""

FORMAT_VERSION = 1
"""Version of the file layout written by :func:`save_system`."""

_MATRICES = ("J", "R", "G", "P", "S", "N")

_Built = TypeVar("_Built")


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
        "matrices": {k: srepr_matrix(getattr(s, k)) for k in _MATRICES},
        "measured": [
            {"name": m.name, "expr": sp.srepr(m.expr), "unit": m.unit, "description": m.description,
             **({"command": True} if m.command else {})}
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


def _unplain(obj, reader, where: str, depth: int = 0):
    """Inverse of :func:`_plain` (``where`` is the JSON path of ``obj``)."""
    if depth > 50:
        raise reader.fail(f"{where}: nested deeper than 50 levels")
    if isinstance(obj, dict):
        if set(obj) == {"srepr"}:
            return reader.expr(obj["srepr"], where)
        return {k: _unplain(v, reader, f"{where}.{k}", depth + 1) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_unplain(v, reader, f"{where}[{i}]", depth + 1) for i, v in enumerate(obj)]
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


def write_all_atomic(files, commit=None, create=()) -> None:
    """Write several files all or nothing: each to a temporary file beside it, then every rename.

    ``files`` maps paths to their text or bytes, or to a function ``write(path)`` that writes the
    file at the path it is given (the temporary one).  When any temporary file cannot be written, every
    one written so far is removed and no destination changes.  ``commit`` (a context manager
    factory, optional) wraps the renames, e.g. to hold back interrupts while they run.  ``create``
    names directories (a report's) made first, with their missing parents; those made here are
    removed again, when still empty, if the writing fails.

    Raises
    ------
    InputDataError
        Naming the first file that cannot be written (nothing is written then).

    Examples
    --------
    >>> import tempfile, os
    >>> with tempfile.TemporaryDirectory() as d:
    ...     write_all_atomic({os.path.join(d, "a.txt"): "A", os.path.join(d, "b.txt"): b"B"})
    ...     sorted(os.listdir(d))
    ['a.txt', 'b.txt']
    >>> with tempfile.TemporaryDirectory() as d:
    ...     try:
    ...         write_all_atomic({os.path.join(d, "a.txt"): "A", os.path.join(d, "no", "b.txt"): "B"})
    ...     except InputDataError as exc:
    ...         print(os.listdir(d), str(exc).startswith("cannot write"))
    [] True
    >>> with tempfile.TemporaryDirectory() as d:
    ...     rep = os.path.join(d, "rep")
    ...     try:
    ...         write_all_atomic({os.path.join(rep, "a.txt"): "A", os.path.join(d, "no", "b.txt"): "B"}, create=[rep])
    ...     except InputDataError:
    ...         print(os.listdir(d))
    []
    """
    import contextlib

    staged = []
    made: list[str] = []  # directories made here, outermost first
    try:
        for directory in create:
            missing = []
            d = os.path.abspath(os.fspath(directory))
            while not os.path.isdir(d) and d != os.path.dirname(d):
                missing.append(d)
                d = os.path.dirname(d)
            for d in reversed(missing):
                try:
                    os.mkdir(d)
                except OSError as exc:
                    raise InputDataError(f"cannot create directory {os.fspath(directory)!r}: {exc.strerror or exc}") from None
                made.append(d)
        for path, data in files.items():
            path = os.fspath(path)
            d = os.path.dirname(os.path.abspath(path))
            if not os.path.isdir(d):
                raise InputDataError(f"cannot write {path!r}: directory {d!r} does not exist")
            if os.path.isdir(path):  # its rename would fail after others were made
                raise InputDataError(f"cannot write {path!r}: it is a directory")
            try:
                fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=os.path.splitext(path)[1], dir=d)
            except OSError as exc:
                raise InputDataError(f"cannot write {path!r}: {exc.strerror}") from None
            staged.append((tmp, path))
            try:
                with os.fdopen(fd, "wb") as fh:
                    if not callable(data):
                        fh.write(data.encode("utf-8") if isinstance(data, str) else data)
                        fh.flush()
                        os.fsync(fh.fileno())
                if callable(data):
                    data(tmp)
                os.chmod(tmp, os.stat(path).st_mode & 0o777 if os.path.exists(path) else 0o644)
            except OSError as exc:
                raise InputDataError(f"cannot write {path!r}: {exc.strerror or exc}") from None
        with commit() if commit is not None else contextlib.nullcontext():
            while staged:
                tmp, path = staged[0]
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise InputDataError(f"cannot write {path!r}: {exc.strerror or exc}") from None
                staged.pop(0)
        made.clear()  # every file is in place: the directories stay
    finally:
        for tmp, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        for d in reversed(made):
            with contextlib.suppress(OSError):
                os.rmdir(d)  # only when empty: a file renamed into it keeps it


# -- reading ------------------------------------------------------------------------------
class _Reader:
    """Reads one saved file; every problem becomes one InputDataError naming the file and the JSON field."""

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
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if kind is not None and (not isinstance(v, kinds) or isinstance(v, bool) and bool not in kinds):
            raise self.fail(f"field {where}.{key} has type {type(v).__name__}")
        return v

    def expr(self, text, where) -> sp.Basic:
        """A stored expression, read by the stored grammar of :mod:`phs.safe_parse`."""
        if not isinstance(text, str):
            raise self.fail(f"{where}: expected a srepr string, got {type(text).__name__}")
        try:
            return parse_srepr(text, where)
        except InputDataError as exc:
            raise self.fail(str(exc)) from None

    def unit(self, d, key, where) -> str:
        """A unit string, read by :func:`phs.units.parse_unit` (a product of powers of known unit names)."""
        text = self.get(d, key, where, str, default="1")
        try:
            parse_unit(text, f"{where}.{key}")
        except UnitError as exc:
            raise self.fail(str(exc)) from None
        return text

    def number(self, d, key, where, default=...) -> float | None:
        """A JSON number (or null) as a float."""
        return self.as_float(self.get(d, key, where, (*_NUMBER, type(None)), default), f"{where}.{key}")

    def as_float(self, v, where: str) -> float | None:
        if v is not None and (isinstance(v, bool) or not isinstance(v, _NUMBER)):
            raise self.fail(f"field {where} is not a number")
        try:
            return None if v is None else float(v)
        except OverflowError:
            raise self.fail(f"field {where} is too large") from None

    def range(self, d, key, where, default):
        v = self.get(d, key, where, (list, type(None)), default)
        if v is None:
            return None
        if len(v) != 2:
            raise self.fail(f"field {where}.{key} is not a pair of numbers")
        return tuple(self.as_float(a, f"{where}.{key}[{i}]") for i, a in enumerate(v))

    def items(self, d, key) -> list:
        return self.get(d, key, "file", list)


_NUMBER = (int, float)


def system_arguments(data: dict, source: str = "<dict>") -> dict[str, Any]:
    """The PHSystem constructor's arguments held in a dictionary written by :func:`system_to_dict`.

    Every expression is read by :func:`phs.stored_expressions.parse_srepr` and every unit
    by :func:`phs.units.parse_unit` (which knows the unit names): nothing in the
    dictionary is run.

    Raises
    ------
    InputDataError
        Naming ``source`` and the missing or malformed field (``params[2].unit``,
        ``energy[0].expr``, ``matrices.J``, ...).

    Examples
    --------
    >>> from systems.examples import duffing_oscillator
    >>> args = system_arguments(system_to_dict(duffing_oscillator()))
    >>> args["name"], len(args["states"]), args["J"].shape
    ('duffing', 2, (2, 2))
    """
    r = _Reader(source)
    if not isinstance(data, dict):
        raise r.fail("the file does not hold a JSON object")
    fmt, version = data.get("format"), data.get("version")
    if fmt != FORMAT:
        raise r.fail(f"not a saved phs system (format {fmt!r}, expected {FORMAT!r})")
    if version != FORMAT_VERSION:
        raise r.fail(f"unsupported format version {version!r} (this version of phs reads {FORMAT_VERSION})")
    try:
        states = []
        for i, x in enumerate(r.items(data, "states")):
            w = f"states[{i}]"
            states.append(StateInfo(r.get(x, "name", w, str), r.unit(x, "unit", w), r.range(x, "range", w, (-1.0, 1.0)),
                                    r.get(x, "description", w, str, ""), r.get(x, "kind", w, str, "C"),
                                    r.number(x, "scale", w, None), r.get(x, "owner", w, str, ""),
                                    r.number(x, "rest", w, None)))
        inputs = []
        for i, u in enumerate(r.items(data, "inputs")):
            w = f"inputs[{i}]"
            inputs.append(InputInfo(r.get(u, "name", w, str), r.unit(u, "unit", w), r.get(u, "output", w, str, ""),
                                    r.unit(u, "output_unit", w), r.get(u, "kind", w, str, "effort"),
                                    r.get(u, "description", w, str, ""), r.range(u, "range", w, None)))
        params = []
        for i, p in enumerate(r.items(data, "params")):
            w = f"params[{i}]"
            params.append(stored_param(r.get(p, "name", w, str), r.number(p, "value", w), r.unit(p, "unit", w),
                                r.get(p, "description", w, str, ""), r.range(p, "range", w, None),
                                r.get(p, "positive", w, (bool, type(None)), None)))
        energy = []
        for i, e in enumerate(r.items(data, "energy")):
            label = r.get(e, "label", f"energy[{i}]", str)
            energy.append(EnergyTerm(label, r.expr(r.get(e, "expr", f"energy[{i}]"), f"energy[{i}].expr (energy {label!r})")))
        mats = r.get(data, "matrices", "file", dict)
        matrices = {}
        for k in _MATRICES:
            M = r.expr(r.get(mats, k, "matrices", str), f"matrices.{k} (matrix {k})")
            if not isinstance(M, sp.MatrixBase):
                raise r.fail(f"matrices.{k} (matrix {k}) is a {type(M).__name__}, not a matrix")
            matrices[k] = M
        measured = []
        for i, m in enumerate(r.items(data, "measured")):
            w = f"measured[{i}]"
            name = r.get(m, "name", w, str)
            measured.append(Measured(name, r.expr(r.get(m, "expr", w), f"{w}.expr (measured {name!r})"), r.unit(m, "unit", w),
                                     r.get(m, "description", w, str, ""), r.get(m, "command", w, bool, False)))
        conditions = []
        for i, c in enumerate(r.items(data, "conditions")):
            w = f"conditions[{i}]"
            label = r.get(c, "label", w, str)
            conditions.append(Condition(label, r.expr(r.get(c, "expr", w), f"{w}.expr (condition {label!r})"),
                                        r.get(c, "description", w, str, "")))
        dissipators = []
        for i, dd in enumerate(r.items(data, "dissipators")):
            w = f"dissipators[{i}]"
            label = r.get(dd, "label", w, str)
            entries = {}
            for key, text in r.get(dd, "entries", w, dict).items():
                try:
                    a, b = (int(v) for v in key.split(","))
                except ValueError:
                    raise r.fail(f"{w}.entries: dissipator {label!r}: entry key {key[:20]!r} is not 'i,j'") from None
                entries[(a, b)] = r.expr(text, f"{w}.entries[{key!r}] (dissipator {label!r})")
            dissipators.append((label, entries))
        definitions = []
        for i, d in enumerate(r.items(data, "definitions")):
            w = f"definitions[{i}]"
            symbol = r.expr(r.get(d, "symbol", w), f"{w}.symbol")
            if not isinstance(symbol, sp.Symbol):
                raise r.fail(f"{w}.symbol is a {type(symbol).__name__}, not a symbol")
            label = r.get(d, "label", w, str)
            definitions.append((symbol, r.expr(r.get(d, "expr", w), f"{w}.expr (definition {label!r})"), label))
        name = r.get(data, "name", "file", str)
        description = r.get(data, "description", "file", str, default="")
        structure = _unplain(r.get(data, "structure", "file", dict, default={}), r, "structure")
    except InputDataError:
        raise
    except (TypeError, ValueError, AttributeError) as exc:  # the constructors of StateInfo, Param, ... refusing a value
        raise r.fail(f"malformed entry: {str(exc).splitlines()[0]}") from None
    return dict(name=name, states=states, H=energy, J=matrices["J"], R=matrices["R"], G=matrices["G"], P=matrices["P"],
                S=matrices["S"], N=matrices["N"], inputs=inputs, params=params, measured=measured,
                conditions=conditions, dissipators=dissipators, definitions=definitions, description=description,
                structure=structure)


def system_from_dict(data: dict, build: Callable[..., _Built], source: str = "<dict>") -> _Built:
    """Rebuild a system from the dictionary written by :func:`system_to_dict`.

    Parameters
    ----------
    data : dict
        The dictionary.
    build : callable
        The class to build (``PHSystem``), called with :func:`system_arguments`.
    source : str
        Where the dictionary comes from, said in errors.

    Raises
    ------
    InputDataError
        Naming ``source`` and the missing or malformed field, or listing the
        problems the PHSystem constructor found.

    Examples
    --------
    >>> from phs import PHSystem
    >>> from systems.examples import duffing_oscillator
    >>> s = duffing_oscillator()
    >>> system_from_dict(system_to_dict(s), PHSystem).H == s.H
    True
    """
    args = system_arguments(data, source)
    try:
        return build(**args)
    except PHSError as exc:
        raise InputDataError(f"cannot load system from {source!r}: the stored model is invalid", [str(exc)]) from None


def load_system(path, build: Callable[..., _Built]) -> _Built:
    """Load a system saved with :func:`save_system` (:meth:`PHSystem.load` and :func:`phs.load` call this).

    Parameters
    ----------
    path : str or path-like
        A JSON file written by :func:`save_system`.
    build : callable
        The class to build (``PHSystem``).

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
    >>> from phs import PHSystem
    >>> from systems.examples import rc_circuit
    >>> with tempfile.TemporaryDirectory() as d:
    ...     rc_circuit().save(os.path.join(d, "rc.json"))
    ...     load_system(os.path.join(d, "rc.json"), PHSystem).state_names
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
    except (ValueError, RecursionError) as exc:  # an integer of too many digits, arrays nested too deeply
        raise InputDataError(f"cannot load system from {path!r}: not readable JSON ({str(exc)[:100]})") from None
    return system_from_dict(data, build, source=path)
