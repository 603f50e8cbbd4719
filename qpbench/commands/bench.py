"""``qpbench bench``: every backend on every problem of a set, one CSV row per solve."""

from __future__ import annotations

import argparse
import sys

from ..harness.bench import DEFAULT_SEED
from ..profiles import profile_names
from .options import add, add_force_resume, pick, strict_exit

HELP = (
    "benchmark backends on a problem set: one long-format CSV row per (problem, backend, profile)"
)
EXAMPLE = (
    "qpbench bench problems/wall --backends osqp,proxqp,rnn --out results/bench-wall.csv --repeat 3; "
    "qpbench bench problems/maros_meszaros --problems 'HS*' --limit 5 --backends daqp,clarabel --out hs.csv; "
    "qpbench bench problems/maros_meszaros --backends qpsolvers:osqp --profile qpbenchmark:high_accuracy "
    "--reference none --out mm.csv"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add(parser, "path")
    add(parser, "--backends", required=True)
    add(parser, "--out", metavar="OUT", help="CSV file of results (rows appended as produced)")
    add(
        parser,
        "--profile",
        choices=profile_names(),
        help="settings profile (default: default); qpbenchmark:<settings> applies qpbenchmark's "
        "solver arguments, time limit and success rule verbatim",
    )
    _add_reference_arguments(parser)
    parser.add_argument(
        "--repeat",
        type=int,
        default=1,
        help="timed solves per problem; rows give min and median (default 1)",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=DEFAULT_SEED,
        help=f"seed of the per-problem backend order, recorded in each row (default {DEFAULT_SEED}); "
        "--resume needs the seed of the rows it continues",
    )
    parser.add_argument(
        "--mode",
        default="sequential",
        choices=("sequential", "independent"),
        help="sequential: tick order, state carried (default); independent: reset before each problem",
    )
    parser.add_argument(
        "--time-limit", type=float, help="per-solve time limit in s (default: the profile's)"
    )
    add(
        parser,
        "--isolate",
        help="run solves in a worker process: auto = backends marked risky or seen to crash (default)",
    )
    parser.add_argument(
        "--no-warmup", action="store_true", help="skip the discarded warm-up solve of each backend"
    )
    add(parser, "--memory-budget")
    parser.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="BACKEND.KEY=VALUE",
        help="a solver setting for one backend, over the profile's, e.g. osqp.rho=0.1 or rnn.eps=0.001; repeatable",
    )
    add(parser, "--problems", "--every", "--limit")
    add_force_resume(
        parser,
        force="delete an existing --out and start again",
        resume="keep the rows of an existing --out and run the rest",
    )


def _add_reference_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--reference",
        default="auto",
        metavar="auto|clarabel|piqp|none|FILE",
        help="reference solutions: auto = Clarabel and PIQP, the one with smaller KKT residuals kept (default); "
        "clarabel or piqp alone; none = no reference (qpbenchmark's success rule, empty optimality gap); "
        "FILE = CSV with columns problem,objective of known optimal objectives",
    )
    parser.add_argument(
        "--reference-time-limit",
        type=float,
        metavar="S",
        help="time limit of each reference solve in s (default: the profile's, 60 s); a reference that times out "
        "leaves its problem's rows with an empty optimality gap and the reason",
    )
    parser.add_argument(
        "--cache-dir",
        metavar="DIR",
        help="folder of the reference cache (default: beside the set when that folder is writable and holds "
        "qpbench's manifest.json, else the user cache folder, ~/.cache/qpbench/references)",
    )
    add(
        parser,
        "--jobs",
        default=1,
        help="worker processes computing reference solutions at once (default 1); the benchmark's timed solves "
        "stay one at a time",
    )


def run(args: argparse.Namespace) -> int:
    from ..formats import load_problems
    from ..harness.bench import BenchConfig, run_bench
    from ..memory import resolve_budget
    from ..selection import backend_settings, select_backends, select_set

    # Nothing is written or logged before the input is known to be good: run_bench checks
    # --out, then logs, warms up and calls for the references.
    backends = select_backends(args.backends, floor=False)
    config = BenchConfig(
        backend_settings=backend_settings(args.sets, backends),
        backends=backends,
        warmup=not args.no_warmup,
        memory_budget=resolve_budget(args.memory_budget),
        **pick(args, "profile repeat mode time_limit isolate seed"),
    )
    references = _reference_source(args, config)
    problem_set = select_set(load_problems(args.path), args.pattern, args.every, args.limit)
    summary = run_bench(
        problem_set,
        config,
        args.out,
        progress=not args.quiet and sys.stderr.isatty(),
        references=references,
        make_parent=False,
        **pick(args, "force resume"),
    )
    if not args.quiet:
        print(f"bench: {summary.line()}")
        print(summary.table())
    return strict_exit(args, failed_solves=summary.failures)


def _reference_source(args: argparse.Namespace, config) -> object:
    """``run_bench``'s ``references``: a function of the set
    (:func:`qpbench.reference.bench_references`), called once the input is checked.

    ``--reference none`` also makes the success rule qpbenchmark's (nothing to judge against).
    """
    from dataclasses import replace
    from pathlib import Path

    from tqdm import tqdm

    from ..exceptions import ParamError, positive_count, positive_seconds
    from ..profiles import get_profile
    from ..published import read_objectives
    from ..reference import METHODS, SOURCES, bench_references
    from ..runner.process import context

    source = args.reference
    positive_count(args.jobs, "jobs")
    profile = get_profile(config.profile)
    limit = profile.reference_time_limit
    if args.reference_time_limit is not None:
        limit = positive_seconds(args.reference_time_limit, "reference-time-limit")
    if source == "none":
        config.profile = replace(profile, tolerance=replace(profile.tolerance, rule="qpbenchmark"))
    elif source not in SOURCES:
        if not Path(source).is_file():
            raise ParamError(
                f"'{source}' is neither {', '.join(SOURCES)} nor a file", key="reference"
            )
        read_objectives(source)  # a bad file fails here, before anything is written
    progress = None if args.quiet else tqdm if sys.stderr.isatty() else "log"
    kw = dict(time_limit=limit, jobs=args.jobs, progress=progress, cache_dir=args.cache_dir)

    def references(problem_set):  # the worker processes' context: only a method's solves
        ctx = context() if source in METHODS else None
        return bench_references(problem_set, source, context=ctx, **kw)

    return references
