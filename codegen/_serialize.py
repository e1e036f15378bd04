"""Generated functions shipped between processes in CasADi's own serialization.

A batch sent to Dask workers (:class:`codegen.batch.BatchSimulator` pickles itself with the
functions of :func:`serialize_functions`) must not make every worker translate the model again:
:func:`deserialize_functions` restores the generated functions and installs them where
:func:`codegen.generate` finds them, so a worker only rebuilds integrators from the deserialized
expressions (or loads them compiled from the disk cache).
"""

from __future__ import annotations

import dataclasses

import casadi as ca

from codegen import functions as _functions
from codegen.functions import GeneratedFunctions
from phs.errors import SimulationError


def serialize_functions(functions: GeneratedFunctions) -> dict:
    """The generated functions of a system in CasADi's serialization (one stream, shared symbols kept).

    Returns a plain dict (strings and lists) that pickles cheaply; :func:`deserialize_functions`
    restores it without any symbolic work.

    Examples
    --------
    >>> from codegen import generate
    >>> from systems.examples import rc_circuit
    >>> blob = serialize_functions(generate(rc_circuit()))
    >>> sorted(blob)[:3], blob["casadi"] == ca.__version__
    (['casadi', 'data', 'fields'], True)
    """
    fields = [f.name for f in dataclasses.fields(GeneratedFunctions) if f.name not in ("system", "sx")]
    ser = ca.StringSerializer()
    for name in fields:
        ser.pack(getattr(functions, name))
    keys = list(functions.sx)
    for key in keys:
        ser.pack(functions.sx[key])
    return {"casadi": ca.__version__, "fields": fields, "sx_keys": keys, "data": ser.encode()}


def deserialize_functions(system, blob: dict, install: bool = True) -> GeneratedFunctions:
    """Rebuild :class:`GeneratedFunctions` of ``system`` from :func:`serialize_functions` output.

    With ``install`` (default) they become what :func:`codegen.generate` returns for ``system``
    (and for systems differing from it only in parameter values), so nothing is re-derived.

    Raises
    ------
    SimulationError
        When the blob was written by another CasADi version (its serialization is not portable
        across versions).

    Examples
    --------
    >>> from codegen import generate
    >>> from systems.examples import rc_circuit
    >>> rc = rc_circuit()
    >>> f = deserialize_functions(rc, serialize_functions(generate(rc)), install=False)
    >>> float(f.hamiltonian([1e-6], [0], [1e3, 1e-6]))
    5e-07
    """
    if blob.get("casadi") != ca.__version__:
        raise SimulationError(f"generated functions of {system.name!r} were serialized by CasADi {blob.get('casadi')} "
                              f"but this process runs CasADi {ca.__version__}; install the same version everywhere")
    des = ca.StringDeserializer(blob["data"])
    funs = {name: des.unpack() for name in blob["fields"]}
    sx = {key: des.unpack() for key in blob["sx_keys"]}
    out = GeneratedFunctions(system=system, sx=sx, **funs)
    if install:
        _functions._CACHE[system] = out
        _functions._BY_HASH[system.model_hash()] = out
    return out
