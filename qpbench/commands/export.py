"""``qpbench export PROBLEMS --format npz|parquet --out DIR``: problems in the ecosystem's formats
(``npz``: one ``qpsolvers.Problem`` file each; ``parquet``: a problem set)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from .options import add, log

HELP = "write problems as qpsolvers .npz files or a Parquet problem set (subset with --problems/--every/--limit)"
EXAMPLE = "qpbench export problems/wall --format npz --problems 'wall_paper_001*' --limit 10 --out wall-npz"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--format", required=True, choices=("npz", "parquet"), help="output format")
    add(parser, "--out", help="output folder (must not exist unless --force)")
    add(parser, "--force", help="replace an existing output folder")
    add(parser, "path", "--problems", "--every", "--limit")


def run(args: argparse.Namespace) -> int:
    from ..atomic import check_output, promote
    from ..exceptions import InputError
    from ..formats import load_problems, save_npz, write_problem_set
    from ..selection import select_set

    out = Path(args.out)
    check_output(out, force=args.force, kind="dir")
    records = select_set(load_problems(args.path), args.pattern, args.every, args.limit).records
    # written beside ``out`` and renamed into place: the folder appears complete or not at all
    with tempfile.TemporaryDirectory(
        prefix=f".{out.name}.", dir=out.parent, ignore_cleanup_errors=True
    ) as staging:
        folder = Path(staging) / out.name
        folder.mkdir()
        if args.format == "parquet":
            generator = {"name": "qpbench export", "source": str(args.path)}
            write_problem_set(folder, records, generator=generator)
        for rec in records if args.format == "npz" else ():
            safe = "".join(c if c.isalnum() or c in "-_.+" else "_" for c in rec.name)
            file = folder / f"{safe}.npz"
            if file.exists():
                raise InputError(
                    f"two problems map to the same file name '{file.name}'", key=rec.name
                )
            save_npz(rec, file)
        promote(Path(staging), out.parent, [out.name])
    log.info("wrote %d problems to %s (%s)", len(records), out, args.format)
    return 0
