"""``qpbench bench``: every backend on every problem of a set, one CSV row per solve."""

from __future__ import annotations

import argparse
import logging
import sys

from ..harness.bench import DEFAULT_SEED
from ..profiles import PROFILES
from .inspect_ import add_memory_argument

HELP = "benchmark backends on a problem set: one long-format CSV row per (problem, backend, profile)"
EXAMPLE = ("qpbench bench problems/wall --backends osqp,proxqp,rnn --out results/bench-wall.csv --repeat 3; "
           "qpbench bench problems/maros_meszaros --problems 'HS*' --limit 5 --backends daqp,clarabel --out hs.csv")

log = logging.getLogger("qpbench")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "problems",
        metavar="PROBLEMS",
        help="problem-set folder, qpbenchmark .parquet, folder of .npz or .mat, or one .npz/.mat file",
    )
    parser.add_argument(
        "--backends", required=True, help="comma-separated backend names, or 'all' (every available backend)"
    )
    parser.add_argument("--out", required=True, help="CSV file of results (rows appended as they are produced)")
    parser.add_argument("--profile", default="default", choices=sorted(PROFILES), help="settings profile (default: default)")
    parser.add_argument("--repeat", type=int, default=1, help="timed solves per problem; rows give min and median (default 1)")
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
    parser.add_argument("--time-limit", type=float, default=None, help="per-solve time limit in s (default: the profile's)")
    parser.add_argument(
        "--isolate",
        default="auto",
        choices=("auto", "always", "never"),
        help="run solves in a worker process: auto = backends marked risky or seen to crash (default)",
    )
    parser.add_argument("--no-warmup", action="store_true", help="skip the discarded warm-up solve of each backend")
    add_memory_argument(parser)
    parser.add_argument(
        "--set",
        dest="sets",
        action="append",
        default=[],
        metavar="BACKEND.KEY=VALUE",
        help="a solver setting for one backend, over the profile's, e.g. osqp.rho=0.1 or rnn.eps=0.001; repeatable",
    )
    parser.add_argument(
        "--plugin",
        action="append",
        default=[],
        metavar="MODULE_OR_FILE",
        help="import a module (or .py file) that registers extra backends; repeatable (also QPBENCH_PLUGINS)",
    )
    from .list_ import add_selection_arguments

    add_selection_arguments(parser)
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--force", action="store_true", help="delete an existing --out and start again")
    group.add_argument("--resume", action="store_true", help="keep the rows of an existing --out and run the rest")


def run(args: argparse.Namespace) -> int:
    from ..atomic import check_output
    from ..backends import backend_names, resolve_name
    from ..exceptions import ParamError
    from ..formats import load_problems
    from ..harness.bench import BenchConfig, run_bench
    from ..harness.plugins import load_plugins, plugin_specs
    from ..jit import warmup_logged
    from ..memory import resolve_budget
    from .simulate import parse_overrides

    # Nothing is written before the input is known to be good.
    check_output(args.out, force=args.force, resume=args.resume)
    plugins = plugin_specs(args.plugin)
    load_plugins(plugins)
    if args.backends.strip() == "all":
        backends = backend_names(available_only=True)
    else:
        backends = [resolve_name(b.strip()) for b in args.backends.split(",") if b.strip()]
    if not backends:
        raise ParamError("no backend given", key="backends")
    per_backend: dict[str, dict] = {}
    for key, value in parse_overrides(args.sets).items():
        backend, _, setting = key.rpartition(".")
        if backend not in backends or not setting:
            raise ParamError(
                f"'{key}' names no backend of this run (expected BACKEND.KEY with BACKEND in --backends)",
                key="--set",
            )
        per_backend.setdefault(backend, {})[setting] = value
    config = BenchConfig(
        backend_settings=per_backend,
        backends=backends,
        profile=args.profile,
        repeat=args.repeat,
        mode=args.mode,
        time_limit=args.time_limit,
        isolate=args.isolate,
        warmup=not args.no_warmup,
        plugins=plugins,
        seed=args.seed,
        memory_budget=resolve_budget(args.memory_budget),
    )
    config.validate()
    from ..selection import select_set

    problem_set = select_set(load_problems(args.problems), args.pattern, args.every, args.limit)
    log.info("%s: %d problems; backends: %s", args.problems, len(problem_set), ", ".join(backends))
    warmup_logged(log)  # no compile inside a timed solve, here or in a worker
    progress = not args.quiet and sys.stderr.isatty()
    summary = run_bench(problem_set, config, args.out, force=args.force, resume=args.resume, progress=progress)
    if not args.quiet:
        print(f"bench: {summary.line()}")
        print(summary.table())
    return summary.exit_code
