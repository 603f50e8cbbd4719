"""Arguments several commands share in form, each with the command's own help text."""

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
