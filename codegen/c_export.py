"""C export of a model's generated functions: dynamics, outputs and energy as one C source and header
(CasADi's ``CodeGenerator``), written atomically.

The functions keep their names ``{system}_rhs`` (``xdot = f(x, u, p)``), ``{system}_output``
(``y``, ``measured``) and ``{system}_hamiltonian`` (``H``), their inputs ``x``, ``u``, ``p`` in the
order of the model's states, inputs and parameters (listed with units in a comment at the top of
both files, with the parameter values), and CasADi's calling convention with work-size functions
(``{system}_rhs_work``); nothing but ``<math.h>`` is needed to compile them.
"""

from __future__ import annotations

import os
import tempfile

import casadi as ca

from phs.errors import InputDataError
from phs.io import write_all_atomic


def write_c_sources(functions, directory, base: str, head: str) -> list[str]:
    """Generate ``base.c`` and ``base.h`` defining ``functions`` (CasADi), each starting with the
    comment ``head``, and write them into ``directory``, both or neither (:func:`phs.io.write_all_atomic`;
    the directory is created if missing, its parent must exist).  Returns the paths written (``.c`` then ``.h``).

    Raises
    ------
    InputDataError
        When the directory's parent does not exist, or the directory is a file.

    Examples
    --------
    >>> import os, tempfile
    >>> import casadi as ca
    >>> x = ca.SX.sym("x")
    >>> twice = ca.Function("twice", [x], [2 * x], ["x"], ["y"])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     paths = write_c_sources([twice], d, "demo", c_comment(["y = 2 x"]))
    ...     [os.path.basename(p) for p in paths], open(paths[1]).read().splitlines()[:3]
    (['demo.c', 'demo.h'], ['/*', ' * y = 2 x', ' */'])
    """
    directory = os.fspath(directory)
    if os.path.exists(directory) and not os.path.isdir(directory):
        raise InputDataError(f"cannot export into {directory!r}: it exists and is not a directory")
    if not os.path.isdir(directory):
        parent = os.path.dirname(os.path.abspath(directory))
        if not os.path.isdir(parent):
            raise InputDataError(f"cannot export into {directory!r}: directory {parent!r} does not exist")
    files = []
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{base}.c", {"with_header": True, "casadi_real": "double", "casadi_int": "long long int"})
        for f in functions:
            cg.add(f)
        cg.generate(tmp + os.sep)
        for ext in (".c", ".h"):
            with open(os.path.join(tmp, base + ext), encoding="utf-8") as fh:
                files.append((os.path.join(directory, base + ext), head + fh.read()))
    write_all_atomic(dict(files), create=[directory])  # both or neither (the directory removed again on failure)
    return [p for p, _ in files]


def c_comment(lines) -> str:
    """A C block comment of ``lines``.

    Examples
    --------
    >>> print(c_comment(["first", "", "third"]), end="")
    /*
     * first
     *
     * third
     */
    """
    body = "\n".join(" * " + ln if ln else " *" for ln in lines)
    return "/*\n" + body + "\n */\n"


def export_model_c(system, directory, params: dict | None = None) -> list[str]:
    """Write the generated dynamics, outputs and energy of ``system`` as C source and header.

    Parameters
    ----------
    system : PHSystem
    directory : path
        Created if missing (its parent must exist).
    params : dict, optional
        Parameter overrides by name: the values listed in the files' comment (``p`` stays an
        argument of every function).

    Returns
    -------
    list of str
        The paths written: ``{directory}/{system}_model.c`` and ``.h``.

    Raises
    ------
    InputDataError
        When the directory's parent does not exist.

    Examples
    --------
    >>> import tempfile, os
    >>> from systems.examples import mass_spring_damper
    >>> with tempfile.TemporaryDirectory() as d:
    ...     paths = export_model_c(mass_spring_damper(), d)
    ...     [os.path.basename(p) for p in paths], "msd_rhs_work" in open(paths[1]).read()
    (['msd_model.c', 'msd_model.h'], True)
    """
    from codegen.functions import generate

    f = generate(system)
    p = system.param_vector(params)
    s = system
    name = f.rhs.name()[: -len("_rhs")]
    lines = [f"Generated functions of the port-Hamiltonian model {s.name} (model hash {s.model_hash()}), by phs.",
             "",
             f"{name}_rhs(x, u, p) -> xdot;  {name}_output(x, u, p) -> y, measured;  {name}_hamiltonian(x, u, p) -> H [J]",
             "  x:  " + ", ".join(f"{st.name} [{st.unit}]" for st in s.states),
             "  u:  " + (", ".join(f"{i.name} [{i.unit}]" for i in s.inputs) or "(none)"),
             "  y:  " + (", ".join(f"{i.output} [{i.output_unit}]" for i in s.inputs) or "(none)"),
             "  measured:  " + (", ".join(f"{m.name} [{m.unit}]" for m in s.measured) or "(none)"),
             "  p:  " + ", ".join(f"{prm.name} = {v:.17g} [{prm.unit}]" for prm, v in zip(s.params, p))]
    return write_c_sources([f.rhs, f.output, f.hamiltonian], directory, f"{name}_model", c_comment(lines))
