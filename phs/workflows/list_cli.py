"""``phs list``: the ready-made systems and the bundled recordings, one line each.

Examples
--------
>>> from phs.workflows.cli import main
>>> main(["list", "--path", "msd_two_tone"])  # doctest: +ELLIPSIS
/.../systems/data/msd_two_tone.csv
0
"""

from __future__ import annotations

import argparse


def add_subcommand(sub) -> None:
    """Add the ``list`` subcommand to the ``phs`` parser (``sub`` is its subparsers object).

    Examples
    --------
    >>> from phs.workflows.cli import build_parser
    >>> build_parser().parse_args(["list"]).path is None
    True
    """
    p = sub.add_parser("list", help="list the ready-made systems and the bundled recordings",
                       description="Print one line per ready-made system (a MODEL for every subcommand: "
                                   "systems:NAME) and per bundled example recording (a DATA file for 'phs fit' and "
                                   "'phs diagnose'); with --path NAME, print the path of that recording only.")
    p.add_argument("--path", metavar="NAME", help="print the path of the bundled recording NAME")
    p.set_defaults(run=run_list)


def run_list(args: argparse.Namespace) -> int:
    """Run ``phs list``; returns the exit code."""
    from phs.workflows.bundled import listing, recording_path

    print(recording_path(args.path) if args.path is not None else listing())
    return 0
