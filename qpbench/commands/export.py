"""``qpbench export PROBLEMS --format npz|parquet --out DIR``: problems in the ecosystem's formats
(``npz``: one ``qpsolvers.Problem`` file each; ``parquet``: a problem set)."""

from __future__ import annotations

import argparse
import logging
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from .options import add

if TYPE_CHECKING:
    from ..formats import ProblemRecord

HELP = "write problems as qpsolvers .npz files or a Parquet problem set (subset with --problems/--every/--limit)"
EXAMPLE = "qpbench export problems/wall --format npz --problems 'wall_paper_001*' --limit 10 --out wall-npz"

log = logging.getLogger("qpbench")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "path")
    parser.add_argument("--format", required=True, choices=("npz", "parquet"), help="output format")
    add(parser, "--out", help="output folder (must not exist unless --force)")
    add(parser, "--force", help="replace an existing output folder")
    add(parser, "--problems", "--every", "--limit")


def _safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.+" else "_" for c in name)


def export(records: list[ProblemRecord], fmt: str, out: Path, source: str) -> Path:
    """Write ``records`` to ``out`` in ``fmt``; the folder appears complete or not at all."""
    from ..atomic import promote
    from ..exceptions import InputError
    from ..formats import save_npz, write_problem_set

    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        (staging / out.name).mkdir()
        if fmt == "parquet":
            generator = {"name": "qpbench export", "source": source}
            write_problem_set(staging / out.name, records, generator=generator)
        for rec in records if fmt == "npz" else ():
            file = staging / out.name / f"{_safe_name(rec.name)}.npz"
            if file.exists():
                raise InputError(
                    f"two problems map to the same file name '{file.name}'", key=rec.name
                )
            save_npz(rec, file)
        promote(staging, out.parent, [out.name])
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out


def run(args: argparse.Namespace) -> int:
    from ..atomic import check_output
    from ..formats import load_problems
    from ..selection import select_records

    out = Path(args.out)
    check_output(out, force=args.force, kind="dir")
    ps = load_problems(args.path)
    records = select_records(ps.records, args.pattern, args.every, args.limit)
    export(records, args.format, out, str(args.path))
    log.info("wrote %d problems to %s (%s)", len(records), out, args.format)
    return 0
