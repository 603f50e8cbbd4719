"""``qpbench closed-loop``: every scenario with every backend in the loop, tabulated."""

from __future__ import annotations

import argparse
import logging

HELP = "run scenarios in closed loop with each backend solving every tick; one table row per (scenario, backend)"
EXAMPLE = "qpbench closed-loop --scenarios wall,narrow --backends qpsolvers:daqp,rnn,pinv --out results/closed-loop"

log = logging.getLogger("qpbench.closed_loop")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenarios", default="all",
                        help="comma-separated scenario names or TOML paths, or 'all' (default: all)")
    parser.add_argument("--backends", default="all",
                        help="comma-separated backend names, or 'all' available ones (default: all)")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output folder: closed_loop.csv and logs/<scenario>__<backend>.parquet")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="simulated time per run in [s] (default: each scenario's T)")
    parser.add_argument("--formulation", choices=("paper", "soft"), default="paper",
                        help="per-tick QP: paper (hard task equality, eq. 11) or soft (default: paper)")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="runs in parallel worker processes (default: 1; timing is cleanest with 1)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--force", action="store_true", help="replace an existing table and its logs")
    group.add_argument("--resume", action="store_true",
                       help="keep the rows already done (same formulation and duration) and run the rest")


def run(args: argparse.Namespace) -> int:
    from ..harness.closed_loop import resolve_backends, resolve_scenarios, run_closed_loop

    scenarios = resolve_scenarios(args.scenarios)
    backends = resolve_backends(args.backends)
    bar = None
    total = len(scenarios) * len(backends)
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="run", desc="closed loop", leave=False, disable=None)

    def on_row(row):
        if bar is not None:
            bar.update(1)
        log.info("%s / %s: %s%s", row["scenario"], row["backend"], row["status"],
                 f" ({row['error']})" if row["status"] != "ok" else "")

    try:
        outcome = run_closed_loop(scenarios, backends, args.out, duration=args.duration,
                                  formulation=args.formulation, force=args.force,
                                  resume=args.resume, jobs=args.jobs, on_row=on_row)
    finally:
        if bar is not None:
            bar.close()
    log.info("%d runs (%d new, %d kept), %d failed; table in %s", len(outcome.table), outcome.ran,
             outcome.skipped, outcome.errors, outcome.csv_path)
    return 1 if outcome.errors else 0
