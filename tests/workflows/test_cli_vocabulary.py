"""One option vocabulary across the subcommands of ``phs``: the same name means the same thing,
with the same type and default, everywhere (the table :data:`phs.workflows.cli_vocabulary.OPTIONS`)."""

from __future__ import annotations

import argparse

import pytest

from phs.workflows.cli import build_parser, main
from phs.workflows.cli_vocabulary import OPTIONS, add_deprecated_alias, add_option, vocabulary_problems


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def test_every_subcommand_speaks_the_canonical_vocabulary():
    parsers = _subparsers(build_parser())
    assert {"simulate", "fit", "passivity", "control", "diagnose", "sweep"} <= set(parsers)
    assert vocabulary_problems(parsers) == []


def test_shared_options_are_in_the_table():
    seen: dict[str, int] = {}
    for parser in _subparsers(build_parser()).values():
        for a in parser._actions:
            if a.help is argparse.SUPPRESS or isinstance(a, argparse._HelpAction):
                continue
            for o in a.option_strings:
                seen[o] = seen.get(o, 0) + 1
    shared = {o for o, n in seen.items() if n > 1}
    assert shared <= set(OPTIONS)
    assert {"--param", "--json", "--x0", "--t-end", "--dt", "--input", "--atol", "--seed"} <= shared


@pytest.mark.parametrize("declare, culprit", [
    (lambda p: p.add_argument("--atol", type=float, default=1e-8, metavar="TOL",
                              help="absolute tolerance of the integrator on scaled states (default: rtol/100)"),
     "bad --atol: type float"),
    (lambda p: p.add_argument("--input", action="append", default=[], metavar="NAME", help="controlled input"),
     "bad --input: help does not start with"),
    (lambda p: p.add_argument("--seed", type=OPTIONS["--seed"].type, default=1, metavar="N",
                              help=OPTIONS["--seed"].help), "bad --seed: default 1"),
    (lambda p: p.add_argument("--x0", metavar="NAME=VALUE", help=OPTIONS["--x0"].help), "bad --x0: action"),
    (lambda p: p.add_argument("--gain", type=float), "--gain is used by good, bad but is not in the canonical table"),
])
def test_the_check_fails_on_an_inconsistent_parser(declare, culprit):
    good, bad = argparse.ArgumentParser(), argparse.ArgumentParser()
    for name in ("--atol", "--input", "--seed", "--x0"):
        add_option(good, name)
    good.add_argument("--gain", type=float)
    declare(bad)
    problems = vocabulary_problems({"good": good, "bad": bad})
    assert any(culprit in p for p in problems), problems


def test_a_detail_may_follow_the_canonical_help_but_not_replace_it():
    p = argparse.ArgumentParser()
    add_option(p, "--report", detail="index.html")
    assert vocabulary_problems({"p": p}) == []
    assert p._option_string_actions["--report"].help == "write a report directory DIR; index.html"


def test_deprecated_alias_works_warns_and_is_not_counted(capsys):
    p, other = argparse.ArgumentParser(prog="demo"), argparse.ArgumentParser()
    p.add_argument("--controlled", action="append", default=[])
    add_deprecated_alias(p, "--input", "--controlled")
    add_option(other, "--input")
    args = p.parse_args(["--input", "a", "--controlled", "b", "--input", "c"])
    assert args.controlled == ["a", "b", "c"]
    assert "--input is deprecated" in capsys.readouterr().err
    assert "--input" not in p.format_help()
    assert vocabulary_problems({"demo": p, "other": other}) == []


def test_control_input_is_a_deprecated_alias_of_controlled(capsys):
    parser = build_parser()
    args = parser.parse_args(["control", "systems.examples:mass_spring_damper", "--target", "position=0.5",
                              "--input", "F"])
    assert args.controlled == ["F"]
    assert "use --controlled" in capsys.readouterr().err


def test_passivity_samples_is_a_deprecated_alias_of_box_samples(capsys):
    args = build_parser().parse_args(["passivity", "systems.examples:rc_circuit", "--samples", "16"])
    assert args.box_samples == 16
    assert "use --box-samples" in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--time", "time"], ["--map", "a=b"]])
def test_control_rejects_csv_options_it_never_read(option, capsys):
    assert main(["control", "systems.examples:mass_spring_damper", "--target", "position=0.5", *option]) == 2
    assert "unrecognized arguments" in capsys.readouterr().err


def test_atol_and_dt_defaults_agree_between_simulate_and_sweep():
    parser = build_parser()
    sim = parser.parse_args(["simulate", "m:f", "--t-end", "1", "--out", "r.csv"])
    swp = parser.parse_args(["sweep", "m:f", "--t-end", "1", "--out", "r.csv"])
    assert (sim.atol, sim.rtol, sim.dt) == (swp.atol, swp.rtol, swp.dt) == (None, 1e-8, None)
