"""``qpbench scaling``: solve time against arm and obstacle size (:mod:`qpbench.scaling`)."""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from .options import add, add_force_resume, check_tables, log, pick, strict_exit

HELP = (
    "scaling study: generated planar arms of 4-64 links and point clouds of 1-1,000 points, "
    "and spatial arms facing balls; solve time against QP size"
)
EXAMPLE = (
    "qpbench scaling --backends daqp,qpoases,piqp,osqp,clarabel --out scaling/ ; "
    "qpbench report scaling/ --out scaling-report/"
)

#: What a --force removes from --out (nothing else in the folder is touched).
OWNED = ("scaling.csv", "scaling.md", "scaling.png", "bench", "sets", "scenarios")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..scaling.runner import ScalingConfig

    d = ScalingConfig(backends=[], sizes=[])
    add(parser, "--backends", required=True)
    add(
        parser,
        "--out",
        help="folder of scaling.csv, bench/, scenarios/ and the report (and sets/ with --keep-sets)",
    )
    parser.add_argument(
        "--sizes",
        default="default",
        metavar="LIST",
        help="'default' (13 sizes: n4-p1-m1,m10,m100,m1000, n4..n64-p2-m16, and spatial: "
        "panda-m4, iiwa14-m4, chain14-m4, chain28-m4) or comma-separated names: nN-pP-mM (a "
        "planar arm of N links, P key points per link, a cloud of M points), panda-mM, iiwa14-mM "
        "or chainN-mM (a generated spatial chain of N joints, modified DH rows) facing M balls",
    )

    def option(flag, text, spec="", **kw):
        # default and type: ScalingConfig's field of the same name; the help text says it
        value = getattr(d, flag[2:].replace("-", "_"))
        kw = {"default": value, "type": type(value), **kw}
        parser.add_argument(flag, help=f"{text} (default {value:{spec}})", **kw)

    option("--driver", "backend solving the closed loop whose ticks are dumped")
    option("--duration", "simulated seconds per size")
    option("--every", "keep every K-th tick")
    option("--repeat", "timed solves per tick, minimum kept")
    option("--seed", "seed of the arms, clouds and backend order")
    option("--profile", "settings profile")
    option(
        "--dense-limit",
        "skip dense-only backends when n x rows exceeds this",
        ",",
        metavar="ENTRIES",
    )
    option(
        "--slow-limit",
        "skip a backend on the larger sizes of an axis once its median solve exceeds S seconds",
        metavar="S",
    )
    parser.add_argument(
        "--no-report", action="store_true", help="do not write scaling.md and scaling.png"
    )
    parser.add_argument(
        "--keep-sets",
        action="store_true",
        help="keep each size's problem set in sets/ (tens of MB for the large sizes; by default "
        "a size's set is removed once its rows are written: the same --seed makes it again)",
    )
    add_force_resume(
        parser,
        force="delete this command's outputs in --out and start again",
        resume="keep the sizes done in --out and run the rest",
    )


def run(args: argparse.Namespace) -> int:
    from ..jit import warmup_logged
    from ..scaling.runner import SUMMARY_NAME, ScalingConfig, failure_line, run_scaling
    from ..scaling.sizes import parse_sizes
    from ..selection import select_backend, select_backends

    config = ScalingConfig(  # every input checked before anything is written
        backends=select_backends(args.backends, floor=False),
        sizes=parse_sizes(args.sizes),
        driver=select_backend(args.driver, "--driver"),
        **pick(args, "duration every repeat seed profile dense_limit slow_limit keep_sets"),
    )
    out = Path(args.out)
    check_tables(out, [SUMMARY_NAME], args)
    for name in OWNED if args.force else ():
        target = out / name
        if target.is_dir():
            shutil.rmtree(target)
        else:
            target.unlink(missing_ok=True)
    # no compile inside a timed solve or build: the driver's loop and the benched backends
    warmup_logged(log, [config.driver, *config.backends])
    progress = not args.quiet and sys.stderr.isatty()
    failed_solves = run_scaling(config, out, resume=args.resume, progress=progress)
    if not args.no_report:
        from ..scaling.report import write_scaling_report

        write_scaling_report(out, out, force=True)
    code = strict_exit(args, failed_solves=failed_solves)
    if failed_solves:  # which backends failed how many solves, in one line
        log.warning("%s%s", f"exit {code}: " if code else "", failure_line(out / SUMMARY_NAME))
    return code
