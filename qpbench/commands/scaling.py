"""``qpbench scaling``: solve time against arm and obstacle size, on generated arms of 4 to 64 links.

Exit code: 0 once the outputs are written, whatever the solves gave; with ``--strict``, 1 when a
solve failed (one line says how many); 2 on bad input.
"""

from __future__ import annotations

import argparse
import logging
import shutil
import sys
from pathlib import Path

from .options import add, add_force_resume, strict_exit

HELP = "scaling study: generated arms of 4-64 links and point clouds of 1-1,000 points; solve time against QP size"
EXAMPLE = (
    "qpbench scaling --backends daqp,qpoases,piqp,osqp,clarabel --out scaling/ ; "
    "qpbench report scaling/ --out scaling-report/"
)

log = logging.getLogger("qpbench")

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
        help="'default' (9 sizes: n4-p1-m1,m10,m100,m1000 and n4..n64-p2-m16) or comma-separated "
        "nN-pP-mM names: N links, P key points per link, a cloud of M points",
    )

    def option(flag, text, spec="", **kw):
        # the default is ScalingConfig's field of the same name, and the help text says it
        value = getattr(d, flag[2:].replace("-", "_"))
        parser.add_argument(flag, default=value, help=f"{text} (default {value:{spec}})", **kw)

    option("--driver", "backend solving the closed loop whose ticks are dumped")
    option("--duration", "simulated seconds per size", type=float)
    option("--every", "keep every K-th tick", type=int)
    option("--repeat", "timed solves per tick, minimum kept", type=int)
    option("--seed", "seed of the arms, clouds and backend order", type=int)
    option("--profile", "settings profile")
    option(
        "--dense-limit",
        "skip dense-only backends when n x rows exceeds this",
        ",",
        type=int,
        metavar="ENTRIES",
    )
    option(
        "--slow-limit",
        "skip a backend on the larger sizes of an axis once its median solve exceeds S seconds",
        type=float,
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
    add(parser, "--strict")


def _config(args):
    from ..exceptions import ParamError, positive_seconds
    from ..profiles import get_profile
    from ..scaling.runner import ScalingConfig
    from ..scaling.sizes import parse_sizes
    from ..selection import select_backend, select_backends

    backends = select_backends(args.backends)
    get_profile(args.profile)
    positive_seconds(args.duration, "--duration")
    positive_seconds(args.slow_limit, "--slow-limit")
    for key, value, ok in (
        ("--every", args.every, args.every >= 1),
        ("--repeat", args.repeat, args.repeat >= 1),
        ("--seed", args.seed, args.seed >= 0),
        ("--dense-limit", args.dense_limit, args.dense_limit >= 1),
    ):
        if not ok:
            raise ParamError(f"out of range: {value}", key=key)
    if args.duration / 0.001 < args.every:
        raise ParamError(
            f"{args.duration} s at 1 kHz keeps no tick with --every {args.every}", key="--every"
        )
    return ScalingConfig(
        backends=backends,
        sizes=parse_sizes(args.sizes),
        driver=select_backend(args.driver, "--driver"),
        duration=args.duration,
        every=args.every,
        repeat=args.repeat,
        seed=args.seed,
        profile=args.profile,
        dense_limit=args.dense_limit,
        slow_limit=args.slow_limit,
        keep_sets=args.keep_sets,
    )


def run(args: argparse.Namespace) -> int:
    from ..atomic import check_output
    from ..jit import warmup_logged
    from ..scaling.runner import SUMMARY_NAME, failure_line, run_scaling

    config = _config(args)  # every input checked before anything is written
    out = Path(args.out)
    check_output(out, force=True, kind="dir")  # a folder (or nothing); its table is checked below
    if out.exists():
        check_output(out / SUMMARY_NAME, force=args.force, resume=args.resume)
    if args.force:
        for name in OWNED:
            target = out / name
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
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
