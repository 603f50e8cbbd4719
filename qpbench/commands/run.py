"""``qpbench run``: the main job (:func:`qpbench.harness.pipeline.run_all`): problem sets, bench,
closed loop and report into results/, the recommendation printed last."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..harness.pipeline import (
    BENCH_EVERY,
    LOOP_JOBS,
    REPEAT,
    RUN_BUDGET_S,
    SWEEP_BUDGET_S,
    default_jobs,
)
from .options import add, add_force_resume, log, pick, strict_exit

HELP = (
    "the main job: make missing problem sets, bench every backend, closed loop every scenario, "
    "write results/ and report.md"
)
EXAMPLE = "qpbench run    (quick: qpbench run --quick)"

#: Wall time of a quick run's perturbed runs [s].
QUICK_SWEEP_BUDGET_S = 30.0
#: What ``--quick`` sets, unless given: a short run of every scenario with a few fast backends
#: that need no compiled kernel of their own, into ``./quick`` (``results/`` is left alone).
QUICK = dict(
    out="quick",
    backends="daqp,osqp,clarabel,pinv",
    duration=1.0,
    bench_every=10,
    repeat=1,
    sweep_budget=QUICK_SWEEP_BUDGET_S,
)
#: The defaults without ``--quick``.
FULL = dict(
    out="results",
    backends="all",
    bench_every=BENCH_EVERY,
    repeat=REPEAT,
    sweep_budget=SWEEP_BUDGET_S,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a short run with the same report sections, into ./quick: every scenario for "
        f"{QUICK['duration']:g} s with {QUICK['backends']}, every {QUICK['bench_every']}th "
        f"problem timed {QUICK['repeat']} time (options given too override these)",
    )
    parser.add_argument("--out", metavar="DIR", help="results folder (default: ./results)")
    parser.add_argument(
        "--problems",
        default="problems",
        metavar="DIR",
        help="folder of the problem sets <DIR>/<scenario>/ (default: ./problems; "
        "missing sets are regenerated there)",
    )
    parser.add_argument(
        "--scenarios",
        help="comma-separated scenarios, or 'all' shipped ones (default: the shipped ones with "
        "[scenario] in_run = true: the paper's four, adaptive_fast and the spatial ones; the "
        "bench uses the paper's and the spatial ones among them)",
    )
    add(
        parser,
        "--backends",
        help="comma-separated backends, or 'all' available ones (default: all)",
    )
    add(
        parser,
        "--duration",
        help="closed-loop time per run in [s] (default: the scenario's, 20 s); the bench "
        "then uses only the problems with t < S (quick runs)",
    )
    parser.add_argument(
        "--bench-every",
        type=int,
        metavar="K",
        help=f"bench every K-th problem of each set (default: {BENCH_EVERY}: 50 of each set's "
        "2,000, every 400th control tick; 1: all of them, about 40x longer)",
    )
    add(
        parser,
        "--run-budget",
        default=RUN_BUDGET_S,
        help=f"the most wall time a closed-loop run may take in [s] (default: {RUN_BUDGET_S:g}); "
        "each backend's budget follows from its per-tick time in the bench (run.json lists "
        "them); a run that spends it stops between ticks and its row says how far it got "
        "(simulated_s). 0: no budget (slow backends then take minutes per scenario)",
    )
    parser.add_argument(
        "--sweep-budget",
        type=float,
        metavar="S",
        help=f"wall time of the perturbed runs in [s] (default: {SWEEP_BUDGET_S:g}, "
        f"{QUICK_SWEEP_BUDGET_S:g} with --quick): each backend ok and real time in every run gets "
        "the instances of <problems>/sweeps/<scenario>.toml its recommendation needs while the "
        "budget buys them, cheapest first, else none (docs/sweeps.md)",
    )
    add(parser, "--min-ok-bound")
    parser.add_argument(
        "--repeat",
        type=int,
        metavar="R",
        help=f"timed solves per bench problem; the report uses the minimum (default: {REPEAT})",
    )
    add(
        parser,
        "--jobs",
        default=default_jobs(),
        help=f"closed-loop runs at once, each in a worker process of its own (default: "
        f"{LOOP_JOBS}, at most one per core; the bench's timed solves stay one at a time)",
    )
    add(parser, "--memory-budget", "--engine")
    add_force_resume(
        parser,
        force="replace bench/, logs/, plots/, closed_loop.csv or report.md in --out even "
        "if no previous 'qpbench run' wrote them",
        resume="continue an interrupted run from OUT/.partial/",
    )


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from ..harness.closed_loop import CSV_NAME, log_row
    from ..harness.pipeline import PERTURBED, RunConfig, run_all
    from ..memory import resolve_budget
    from ..report.recommend import read_sweeps
    from ..selection import select_backends, select_scenarios
    from ..sim.scenario import run_scenarios

    for key, value in (QUICK if args.quick else FULL).items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    config = RunConfig(  # checks the numbers first, before any scenario is loaded
        out=Path(args.out),
        problems=Path(args.problems),
        run_budget=args.run_budget or None,
        progress=not args.quiet,
        scenarios=[],
        backends=[],
        memory_budget=resolve_budget(args.memory_budget),
        **pick(
            args, "duration bench_every repeat jobs force resume sweep_budget min_ok_bound engine"
        ),
        on_row=lambda row: (
            log_row(log, row) if row.get("verdict") not in ("ok", "", None) else None
        ),
    )
    config.scenarios = select_scenarios(args.scenarios or ",".join(run_scenarios()))
    config.backends = select_backends(args.backends, floor=False)
    outcome = run_all(config)
    log.info("qpbench run: %s in %.0f s; report %s", args.out, outcome.wall_time_s, outcome.report)
    table = pd.read_csv(Path(args.out) / CSV_NAME)
    sweeps = read_sweeps(sorted((Path(args.out) / PERTURBED).glob("*/sweep.csv")))
    # the exit code, then the recommendation as the last lines printed
    kw = dict(runs=table, failed_solves=outcome.failed_solves, recommend=True, sweeps=sweeps)
    return strict_exit(args, **kw)
