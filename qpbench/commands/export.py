"""``qpbench export PROBLEMS --format npz|parquet --out DIR``: problems in the ecosystem's formats.

- ``npz``: one file per problem, ``DIR/<name>.npz``, written by
  :meth:`qpsolvers.Problem.save` (read back with ``qpsolvers.Problem.load``;
  qpbench's metadata rides along as one extra member that qpsolvers ignores);
- ``parquet``: a problem set, ``DIR/problems.parquet`` + ``DIR/manifest.json``
  (qpbenchmark's columns; read with ``qpbench.formats.read_problem_set`` or a
  ``qpbenchmark.ParquetTestSet`` subclass).

``DIR`` must not exist (or ``--force``); its parent must. Every file is
written to a temporary name and renamed, and the folder appears only once
complete: a failed export leaves nothing behind.
"""

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
    parser.add_argument(
        "path",
        metavar="PROBLEMS",
        help="problem-set folder, .parquet, .npz, .mat, or a folder of .npz/.mat",
    )
    parser.add_argument("--format", required=True, choices=("npz", "parquet"), help="output format")
    parser.add_argument(
        "--out", required=True, metavar="DIR", help="output folder (must not exist unless --force)"
    )
    add(parser, "--force", help="replace an existing output folder")
    add(parser, "--problems", "--every", "--limit")


def _safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_.+" else "_" for c in name)


def export(records: list[ProblemRecord], fmt: str, out: Path, source: str) -> Path:
    """Write ``records`` to ``out`` in ``fmt``; the folder appears complete or not at all."""
    from ..atomic import rename
    from ..formats import save_npz, write_problem_set

    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        if fmt == "npz":
            seen = set()
            for rec in records:
                stem = _safe_name(rec.name)
                if stem in seen:
                    raise_dup(rec.name)
                seen.add(stem)
                save_npz(rec, staging / f"{stem}.npz")
        else:
            write_problem_set(
                staging, records, generator={"name": "qpbench export", "source": source}
            )
        if out.exists():
            old = out.with_name(f".{out.name}.old")
            out.rename(old)
            rename(staging, out)
            shutil.rmtree(old)
        else:
            rename(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return out


def raise_dup(name: str) -> None:
    from ..exceptions import InputError

    raise InputError(f"two problems map to the same file name '{_safe_name(name)}.npz'", key=name)


def run(args: argparse.Namespace) -> int:
    from ..atomic import check_folder
    from ..exceptions import OutputExistsError
    from ..formats import load_problems
    from ..selection import select_records

    out = Path(args.out)
    check_folder(out)
    if out.exists() and not args.force:
        raise OutputExistsError(f"{out}: exists; pass --force to overwrite")
    ps = load_problems(args.path)
    records = select_records(ps.records, args.pattern, args.every, args.limit)
    export(records, args.format, out, str(args.path))
    log.info("wrote %d problems to %s (%s)", len(records), out, args.format)
    return 0
