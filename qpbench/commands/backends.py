"""``qpbench backends``: list every registered backend and whether it can run here."""

from __future__ import annotations

import argparse

from .options import add, print_listing

HELP = "list solver backends: name, available, version, algorithm family, reason if unavailable"
EXAMPLE = "qpbench backends    (qpbench backends --available --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--available", action="store_true", help="list only the backends that can run here"
    )
    add(parser, "--json", help="one JSON object per backend, one per line")


def run(args: argparse.Namespace) -> int:
    from dataclasses import asdict

    from ..backends import backend_info

    infos = [i for i in backend_info() if i.available or not args.available]
    rows = [("name", "available", "version", "family", "reason")]
    for i in infos:
        available = "yes" if i.available else "no"
        rows.append((i.name, available, i.version or "-", i.family, i.reason or ""))
    return print_listing(args, [asdict(i) for i in infos], rows, align="llll", free_last=True)
