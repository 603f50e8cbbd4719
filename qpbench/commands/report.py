"""``qpbench report``: report.md and PNG plots from bench and closed-loop CSVs."""

from __future__ import annotations

import argparse

from .options import add, pick

HELP = "write report.md and PNG plots from bench, closed-loop and sweep result CSVs (every number recomputed)"
EXAMPLE = "qpbench report results/bench results/closed_loop.csv --out results --force"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "results",
        nargs="+",
        metavar="RESULTS",
        help="bench, closed-loop or sweep CSV files, or folders searched for *.csv (a sweep's "
        "sweep.csv adds the sweep section)",
    )
    add(parser, "--out", help="folder of report.md and plots/")
    add(parser, "--force", help="replace an existing report.md")
    parser.add_argument("--no-plots", action="store_true", help="write report.md only")
    add(parser, "--min-ok-bound")
    parser.add_argument(
        "--prefer",
        choices=("first", "last"),
        help="a (problem, scenario, backend, profile, mode) row in several bench CSVs is an error, and so "
        "is a backend timed with different --repeat counts in one table; first/last: keep the row of the "
        "first/last file given, and report mixed repeat counts with a note",
    )


def run(args: argparse.Namespace) -> int:
    from ..report.recommend import check_bound
    from ..report.write import write_report
    from ..scaling.report import is_scaling_dir, write_scaling_report
    from ..sweep.report import split_sweep_paths, sweep_section

    check_bound(args.min_ok_bound)
    plots = not args.no_plots
    # folders written by ``qpbench scaling``, tables by ``qpbench sweep``: their own sections
    scaling = [r for r in args.results if is_scaling_dir(r)]
    for folder in scaling:
        write_scaling_report(folder, args.out, force=args.force, plots=plots)
    others = [r for r in args.results if r not in scaling]
    if others:
        rest, sweeps = split_sweep_paths(others)
        sections = (lambda out, plots: sweep_section(sweeps, out, plots)) if sweeps else None
        kw = pick(args, "prefer force min_ok_bound")
        write_report(rest, args.out, plots=plots, sections=sections, files=sweeps, **kw)
    return 0
