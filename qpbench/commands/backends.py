"""``qpbench backends``: list every registered backend and whether it can run here."""

from __future__ import annotations

import argparse

from .options import add, aligned

HELP = "list solver backends: name, available, version, algorithm family, reason if unavailable"
EXAMPLE = "qpbench backends    (qpbench backends --available --json)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--available", action="store_true", help="list only the backends that can run here"
    )
    add(parser, "--json", help="one JSON object per backend, one per line")


def run(args: argparse.Namespace) -> int:
    from ..backends import backend_info

    infos = [i for i in backend_info() if i.available or not args.available]
    if args.json:
        import dataclasses
        import json

        for i in infos:
            print(json.dumps(dataclasses.asdict(i)))
        return 0
    rows = [("name", "available", "version", "family", "reason")]
    for i in infos:
        rows.append(
            (i.name, "yes" if i.available else "no", i.version or "-", i.family, i.reason or "")
        )
    print(aligned(rows, left=4, free_last=True))
    return 0
