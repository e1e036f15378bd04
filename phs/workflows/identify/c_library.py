"""The fit's functions compiled to C in one shared library, cached on disk and built in the background."""

from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile

import casadi as ca

from phs.errors import SimulationError

_CFLAGS = ("-O1",)  # as fast as -O2 on generated code here, and a third quicker to compile


class _Library:
    """``funs`` compiled to C in one shared library, together with their Jacobians (``jacobian``) and
    forward derivatives in ``forward`` directions (CasADi loads those from the library by name),
    cached on disk like :func:`codegen.compile.compiled` (written under a temporary name, renamed
    into place).  The C source is written at once and the compiler runs as a separate process until
    :meth:`load`, so that the caller's other work overlaps the compilation.  ``cc`` is the C compiler
    (None: there is none, which is an error)."""

    def __init__(self, funs: list, key: str, cc: str | None, jacobian: bool = False, forward: tuple = ()):
        from codegen.compile import cache_dir

        if cc is None:
            raise SimulationError("compilation to C requested but no C compiler (gcc/cc) was found; use compile=False")
        self.names = [f.name() for f in funs]
        # the functions' own serializations key the library too: a changed definition never loads a stale one
        content = hashlib.sha256("".join(f.serialize() for f in funs).encode()).hexdigest()
        tag = f"{key}|{content}|{self.names}|{ca.__version__}|{' '.join(_CFLAGS)}|jac={jacobian}|fwd={tuple(forward)}"
        d = cache_dir()
        self.lib = os.path.join(d, f"{self.names[0]}_{hashlib.sha256(tag.encode()).hexdigest()[:20]}.so")
        self._proc = self._tmp = None
        if os.path.exists(self.lib):
            return
        self._tmp = tempfile.TemporaryDirectory(dir=d)
        cname = f"{self.names[0]}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False})
        for fun in funs:
            cg.add(fun)
            if jacobian:
                cg.add(fun.jacobian())
            for nd in forward:
                cg.add(fun.forward(nd))
        cg.generate(self._tmp.name + os.sep)
        self._out = os.path.join(self._tmp.name, "lib.so")
        self._proc = subprocess.Popen([cc, *_CFLAGS, "-shared", "-fPIC", os.path.join(self._tmp.name, cname), "-o",
                                       self._out, "-lm"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)

    def load(self) -> list:
        """Wait for the compiler (if it runs) and load the functions."""
        if self._proc is not None:
            try:
                _, err = self._proc.communicate()
                if self._proc.returncode != 0:
                    raise SimulationError(f"compiling {self.names[0]} failed: {err.strip()[:500]}")
                os.replace(self._out, self.lib)
            finally:
                self._proc = None
                self._tmp.cleanup()
        return [ca.external(name, self.lib) for name in self.names]

    def discard(self) -> None:
        """Stop a running compiler and remove its files (the build is abandoned)."""
        if self._proc is not None:
            self._proc.kill()
            self._proc.communicate()
            self._proc = None
            self._tmp.cleanup()

