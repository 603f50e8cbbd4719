"""``qpbench closed-loop``: every scenario with every backend in the loop
(:mod:`qpbench.harness.closed_loop`), tabulated, the recommendation printed last."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ..report.markdown_table import aligned
from .options import add, add_force_resume, log, pick, run_bar, strict_exit

if TYPE_CHECKING:
    import pandas as pd

HELP = "run scenarios in closed loop with each backend solving every tick; one table row per (scenario, backend)"
EXAMPLE = "qpbench closed-loop --scenarios wall,narrow --backends qpsolvers:daqp,rnn,pinv --out results/closed-loop"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scenarios",
        default="all",
        help="comma-separated scenario names or TOML paths, or 'all' (default: all)",
    )
    add(parser, "--backends", default="all")
    add(
        parser,
        "--out",
        help="output folder: closed_loop.csv and logs/<scenario>__<backend>.parquet",
    )
    add(parser, "--duration", help="simulated time per run in [s] (default: each scenario's)")
    add(parser, "--formulation", "--set", "--deadline", "--engine")
    add(
        parser,
        "--jobs",
        default=1,
        help="runs in parallel, each in a worker process of its own (default: 1; timing is "
        "cleanest with 1)",
    )
    add(
        parser,
        "--isolate",
        help="run a backend's runs in a worker process with a deadline, so a hang or crash is a "
        "row: auto = backends marked risky (default)",
    )
    parser.add_argument(
        "--run-time-limit",
        type=float,
        metavar="S",
        help="deadline of an isolated run in [s], worker start and warm-up included (default: "
        "max(600, 50 x simulated seconds))",
    )
    add(
        parser,
        "--run-budget",
        help="wall-time budget of each run in [s]: a run that spends it stops between ticks "
        "(status budget; simulated_s says how far it got) (default: none)",
    )
    add_force_resume(
        parser,
        force="replace an existing table and its logs",
        resume="keep the rows already done (same formulation and duration) and run the rest",
    )


def run(args: argparse.Namespace) -> int:
    from ..harness.closed_loop import log_row, run_closed_loop
    from ..jit import warmup_logged
    from ..selection import parse_overrides, select_backends, select_scenarios
    from ..sim.scenario import load_scenario

    scenarios = select_scenarios(args.scenarios)
    overrides = parse_overrides(args.overrides)
    for name in scenarios if overrides else ():
        # a bad key or value (a settle time against the duration run): one line naming it, exit 2
        load_scenario(name, overrides=overrides, duration=args.duration)
    backends = select_backends(args.backends)
    warmup_logged(log, backends)  # compiled here once: the worker processes load them
    total = len(scenarios) * len(backends)
    with run_bar(args, total, "closed loop", lambda row: log_row(log, row), leave=False) as on_row:
        settings = pick(
            args,
            "duration formulation force resume jobs isolate run_time_limit deadline run_budget "
            "engine",
        )
        outcome = run_closed_loop(
            scenarios, backends, args.out, on_row=on_row, overrides=overrides, **settings
        )
    log.info(
        "%d runs (%d new, %d kept), %d failed to run, %d failed their verdict; table in %s",
        len(outcome.table),
        outcome.ran,
        outcome.skipped,
        outcome.errors,
        outcome.not_ok,
        outcome.csv_path,
    )
    shown = len(outcome.table) > 0
    if not args.quiet and shown:
        print(summary_table(outcome.table) + "\n")
    return strict_exit(args, runs=outcome.table, recommend=shown)


def summary_table(table: pd.DataFrame) -> str:
    """One line per run: verdict, how far it got, errors after the transient, closest key point
    and body, p99 solve time, ticks slower than dt."""
    from ..report.markdown_table import MM, US, Column, fmt

    columns = (
        Column("simulated s", "simulated_s", 1.0, ".4g"),
        Column("tracking max mm", "tracking_max_after_2s", MM, ".3g"),
        Column("force err max N", "force_error_max_after_2s", 1.0, ".3g"),
        Column("d_min mm", "min_obstacle_distance", MM, ".4g"),
        Column("body mm", "min_body_distance", MM, ".4g"),
        Column("solve p99 us", "solve_time_p99_s", US, ".4g"),
        Column("ticks > dt", "deadline_misses", 1.0, ".4g"),
    )
    rows = [("scenario", "backend", "verdict", *(c.header for c in columns))]
    for r in table.to_dict("records"):
        figures = (fmt(c.value(r)) for c in columns)
        verdict = r.get("verdict") or r.get("status")
        if str(r.get("noise_floor")) == "True":  # x = 0: its verdict judges nothing
            verdict = "noise floor"
        rows.append((str(r.get("scenario")), str(r.get("backend")), str(verdict), *figures))
    return aligned(rows, "lll")
