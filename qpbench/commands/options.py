"""Arguments several commands share in form, each with the command's own help text, and the
exit code of the commands that benchmark many backends (:func:`strict_exit`)."""

from __future__ import annotations

import argparse


def add_force_resume(parser: argparse.ArgumentParser, force: str, resume: str) -> None:
    """``--force`` or ``--resume`` (not both): what to do with an output that is already there.

    ``force`` and ``resume`` are the help texts: what the command replaces or
    keeps (:func:`qpbench.atomic.check_output` refuses an existing output
    without either).
    """
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--force", action="store_true", help=force)
    group.add_argument("--resume", action="store_true", help=resume)


def add_set(parser: argparse.ArgumentParser, help: str) -> None:
    """``--set KEY=VALUE`` (repeatable, into ``args.overrides``): scenario values set over the
    file's (:func:`qpbench.sim.scenario.load_scenario`'s ``overrides``); ``help`` is the
    command's text."""
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", dest="overrides", help=help
    )


def add_strict(parser: argparse.ArgumentParser) -> None:
    """``--strict``: exit 1 when the outputs show a run or a solve that did not pass (for CI)."""
    parser.add_argument(
        "--strict",
        action="store_true",
        help="exit 1 when a run's verdict is not ok, a run was not real time or a solve failed, "
        "with one line saying why (for CI); without it the exit code is 0 once the outputs are "
        "written, whatever the verdicts",
    )


def strict_exit(args: argparse.Namespace, *, runs=None, failed_solves: int = 0) -> int:
    """The exit code of a command that benchmarks many backends and wrote its outputs.

    0 whatever the verdicts; with ``--strict``, 1 when :func:`qpbench.report.recommend.shortfalls`
    finds something in ``runs`` (closed-loop or sweep rows, a DataFrame) or ``failed_solves``,
    with one line on stderr saying what. (Bad input never gets here: it is exit 2.)
    """
    import sys

    from ..report.recommend import shortfalls

    if not getattr(args, "strict", False):
        return 0
    found = shortfalls(runs, failed_solves)
    if not found:
        return 0
    print(f"qpbench {args.command}: --strict: {'; '.join(found)}", file=sys.stderr)
    return 1
