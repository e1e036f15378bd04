"""The ``phs`` command line: the parser and the dispatch to the subcommands.

Each subcommand is defined in its workflow's own module (``phs.workflows.simulate_cli``,
``fit_cli``, ``passivity_cli``, ``control_cli``, ``diagnose.cli``, ``sweep.cli``, ``export_cli``, ``list_cli``): one
``add_subcommand`` function declaring its options and one ``run_<name>`` function doing the work.
Errors the project raises on purpose (:class:`~phs.errors.PHSError`) are printed as one line
``phs: error: <message>`` with exit code 2, and no output file is written; an integrator's failure is
printed in words (what happened, where, what to try: :mod:`codegen._solver_errors`), never as its
return flag alone or the C++ file that reported it; solvers' own warnings stay off the terminal unless
``--verbose`` (:func:`phs.workflows.terminal.solver_chatter`).  SIGINT and SIGTERM stop every subcommand with exit
code 130 and 143 (:mod:`phs.workflows.interrupts`), writing nothing for the work in flight.

Examples
--------
>>> main(["--version"])  # doctest: +ELLIPSIS
phs ...
0
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from phs.errors import PHSError

EXIT_ERROR = 2

# Subcommands in the order of ``phs --help``, each defined in its workflow's own module with
# ``add_subcommand(sub)``, which adds its parser and sets ``run`` (a function of the parsed
# arguments returning the exit code).
_SUBCOMMAND_MODULES: tuple[str, ...] = (
    "phs.workflows.simulate_cli",
    "phs.workflows.fit_cli",
    "phs.workflows.passivity_cli",
    "phs.workflows.control_cli",
    "phs.workflows.diagnose.cli",
    "phs.workflows.sweep.cli",
    "phs.workflows.export_cli",
    "phs.workflows.list_cli",
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``phs`` with one subparser per subcommand.

    Examples
    --------
    >>> args = build_parser().parse_args(["simulate", "systems.examples:rc_circuit", "--t-end", "1",
    ...                                   "--dt", "0.1", "--out", "r.csv"])
    >>> args.t_end, args.input
    (1.0, [])
    """
    import phs

    parser = argparse.ArgumentParser(prog="phs", description="Port-Hamiltonian models from the command line.")
    parser.add_argument("--version", action="version", version=f"phs {phs.__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in _SUBCOMMAND_MODULES:
        importlib.import_module(module).add_subcommand(sub)
    return parser


def _one_line(message: str) -> str:
    from codegen._solver_errors import in_words  # an integrator's raw failure inside a message, in words

    return in_words(message).replace(":\n  - ", ": ").replace("\n  - ", "; ").replace("\n", " ")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``phs`` command line; returns the exit code.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 on a usage error or an error naming bad input, 130 after SIGINT and 143 after
        SIGTERM (:mod:`phs.workflows.interrupts`: nothing is written for the work in flight).

    Examples
    --------
    >>> main(["simulate", "no_colon", "--t-end", "1", "--dt", "0.1", "--out", "r.csv"])
    2
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else EXIT_ERROR)
    from phs.workflows.interrupts import Interrupted, received, watching
    from phs.workflows.terminal import solver_chatter

    args.argv = list(sys.argv[1:] if argv is None else argv)  # the command as given, for the echo of a summary
    with watching(), solver_chatter(getattr(args, "verbose", False)):  # solvers' own warnings only with --verbose
        try:
            return args.run(args)
        except Interrupted as exc:
            return _interrupted(exc.signum)
        except KeyboardInterrupt:
            return _interrupted(2)
        except (PHSError, RuntimeError, OSError) as exc:
            if received() is not None:  # a solver's failure caused by the signal: the signal is the news
                return _interrupted(received())
            if isinstance(exc, RuntimeError) and not isinstance(exc, PHSError):  # an integrator's failure, unnamed: in words
                from codegen._solver_errors import failure_code

                if failure_code(exc) is None:
                    raise
            print(f"phs: error: {_one_line(str(exc))}", file=sys.stderr)
            return EXIT_ERROR


def _interrupted(signum: int) -> int:
    """Say that the command was stopped by ``signum``; its exit code, 128 + signum (130 SIGINT, 143 SIGTERM)."""
    import signal

    print(f"phs: interrupted ({signal.Signals(signum).name}); nothing was written for the work in flight",
          file=sys.stderr)
    return 128 + signum


if __name__ == "__main__":
    sys.exit(main())
