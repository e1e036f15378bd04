"""``phs export``: write a model's generated functions (dynamics, outputs, energy) as C source and header.

Examples
--------
>>> import os, tempfile
>>> from phs.workflows.cli import main
>>> with tempfile.TemporaryDirectory() as d:
...     main(["export", "systems.examples:rc_circuit", "--c", os.path.join(d, "c")])  # doctest: +ELLIPSIS
wrote .../c/rc_model.c and .../c/rc_model.h: rc_rhs, rc_output, rc_hamiltonian
0
"""

from __future__ import annotations

import argparse
import os

from phs.workflows.cli_vocabulary import _add_model_argument


def add_subcommand(sub) -> None:
    """Add the ``export`` subcommand to the ``phs`` parser (``sub`` is its subparsers object).

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> build_parser().parse_args(["export", "systems:rc_circuit", "--c", "build"]).c
    'build'
    """
    p = sub.add_parser("export", help="write a model's generated functions as C source and header",
                       description="Write the generated CasADi functions of MODEL (dynamics {name}_rhs, outputs "
                                   "{name}_output, energy {name}_hamiltonian; arguments x, u, p) as DIR/{name}_model.c "
                                   "and .h (CasADi's calling convention; only <math.h> needed), written atomically.")
    _add_model_argument(p)
    p.add_argument("--c", required=True, metavar="DIR", help="directory of the C source and header (created if missing)")
    p.set_defaults(run=run_export)


def run_export(args: argparse.Namespace) -> int:
    """Run ``phs export``; returns the exit code.  Nothing is written on an error."""
    from codegen.c_export import export_model_c
    from phs.workflows.inputs import parse_assignments
    from phs.workflows.loader import load_model

    params = parse_assignments(args.param, "--param", numeric=True)
    system = load_model(args.model, params)
    c_file, h_file = export_model_c(system, args.c)
    name = os.path.basename(c_file)[: -len("_model.c")]
    print(f"wrote {c_file} and {h_file}: {name}_rhs, {name}_output, {name}_hamiltonian")
    return 0
