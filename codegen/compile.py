"""Compilation of generated CasADi functions to C, cached on disk by a hash of the model.

The cache directory is ``$PHS_CACHE_DIR`` or ``~/.cache/phs``.  A library is
written to a temporary name and renamed into place, so concurrent processes
never load a half-written file.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile

import casadi as ca

from phs.errors import SimulationError


def cache_dir() -> str:
    """The directory holding compiled libraries (created on demand).

    Examples
    --------
    >>> isinstance(cache_dir(), str)
    True
    """
    d = os.environ.get("PHS_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "phs")
    os.makedirs(d, exist_ok=True)
    return d


def compiled(fun: ca.Function, key: str, flags: tuple[str, ...] = ("-O2",)) -> ca.Function:
    """Return ``fun`` compiled to a shared library (with its Jacobian), loaded as a CasADi external.

    Parameters
    ----------
    fun : casadi.Function
        An SX/MX function; its Jacobian is generated too so that solvers can use it.
    key : str
        Identifies the function's content (e.g. a model hash and a template key);
        the library name is derived from it and the CasADi version.
    flags : tuple of str
        Compiler optimisation flags.

    Raises
    ------
    SimulationError
        If no C compiler is available or compilation fails.

    Examples
    --------
    >>> x = ca.SX.sym("x")
    >>> f = compiled(ca.Function("sq_doc", [x], [x * x]), "doc-example")
    >>> float(f(3.0))
    9.0
    """
    cc = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
    if cc is None:
        raise SimulationError("compilation to C requested but no C compiler (gcc/cc) was found; use compile=False")
    h = hashlib.sha256(f"{key}|{fun.name()}|{ca.__version__}|{' '.join(flags)}".encode()).hexdigest()[:20]
    d = cache_dir()
    lib = os.path.join(d, f"{fun.name()}_{h}.so")
    if not os.path.exists(lib):
        with tempfile.TemporaryDirectory(dir=d) as tmp:
            cname = f"{fun.name()}.c"
            cg = ca.CodeGenerator(cname, {"with_header": False})
            cg.add(fun)
            cg.add(fun.jacobian())
            cg.generate(tmp + os.sep)
            out = os.path.join(tmp, "lib.so")
            proc = subprocess.run([cc, *flags, "-shared", "-fPIC", os.path.join(tmp, cname), "-o", out, "-lm"],
                                  capture_output=True, text=True)
            if proc.returncode != 0:
                raise SimulationError(f"compiling {fun.name()} failed: {proc.stderr.strip()[:500]}")
            os.replace(out, lib)
    return ca.external(fun.name(), lib)
