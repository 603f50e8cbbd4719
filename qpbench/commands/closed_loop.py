"""``qpbench closed-loop``: every scenario with every backend in the loop, tabulated.

Guarded (see :mod:`qpbench.harness.closed_loop`): per tick, an exception or
a non-finite answer of the backend is a tick without a solution (statuses
``error``, ``invalid`` in the tick log, counts in the row); a late answer is
applied like any other (``deadline_misses`` counts ticks slower than dt)
unless ``--deadline`` drops it (status ``time_limit``, ``deadline_dropped``); per run,
``--isolate`` runs a backend in a worker
process with a deadline (``--run-time-limit``), so a hang or a crash in native
code becomes a ``time_limit`` or ``crashed`` row and the other runs go on.
Plugin backends (``qpbench --plugin FILE``, ``QPBENCH_PLUGINS``, entry
points) run here and in the workers. ``--run-budget`` gives each run a wall-time
budget: a run that spends it stops between ticks (status ``budget``, the row
says how far it got).

Every run gets a verdict (:mod:`qpbench.sim.verdict`) with the reasons; a
run that is not ``ok`` is printed as a WARNING. The last lines printed are the
recommendation (:mod:`qpbench.report.recommend`). Exit code: 0 once the table
is written, whatever the verdicts; with ``--strict``, 1 when a run in the
table is not ``ok`` or not real time (one line says why); 2 on bad input.
"""

from __future__ import annotations

import argparse
import logging
from typing import TYPE_CHECKING

from ..statuses import FORMULATIONS
from .options import add_force_resume, add_set, add_strict, strict_exit

if TYPE_CHECKING:
    import pandas as pd

# The command protocol (HELP, EXAMPLE, a logger, add_arguments, run), the same shape in every
# command module: cli.py reads these names; the repetition is that interface, not shared logic.
HELP = "run scenarios in closed loop with each backend solving every tick; one table row per (scenario, backend)"
EXAMPLE = "qpbench closed-loop --scenarios wall,narrow --backends qpsolvers:daqp,rnn,pinv --out results/closed-loop"

log = logging.getLogger("qpbench.closed_loop")


def _add_selection_arguments(parser: argparse.ArgumentParser) -> None:
    """What to run: scenarios, backends, output folder, duration, formulation."""
    parser.add_argument(
        "--scenarios",
        default="all",
        help="comma-separated scenario names or TOML paths, or 'all' (default: all)",
    )
    parser.add_argument(
        "--backends",
        default="all",
        help="comma-separated backend names, or 'all' available ones (default: all)",
    )
    parser.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output folder: closed_loop.csv and logs/<scenario>__<backend>.parquet",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulated time per run in [s] (default: each scenario's T)",
    )
    parser.add_argument(
        "--formulation",
        choices=FORMULATIONS,
        default="paper",
        help="per-tick QP: paper (hard task equality, eq. 11) or soft (default: paper)",
    )
    add_set(
        parser,
        "set a value over every scenario file's (repeatable), as simulate --set, e.g. "
        "--set key_points.kind=closest",
    )


def _add_execution_arguments(parser: argparse.ArgumentParser) -> None:
    """How the runs are run: parallel jobs, per-tick deadline, isolation, limits."""
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="runs in parallel, each in a worker process of its own (default: 1; timing is "
        "cleanest with 1)",
    )
    parser.add_argument(
        "--deadline",
        type=float,
        default=None,
        metavar="SECONDS",
        help="per-tick deadline in [s]: a later answer is dropped (status time_limit; soft "
        "fallback, else zero velocity) and the runs depend on the machine's speed "
        "(default: none, every answer is applied; deadline_misses counts ticks slower "
        "than dt)",
    )
    parser.add_argument(
        "--isolate",
        default="auto",
        choices=("auto", "always", "never"),
        help="run a backend's runs in a worker process with a deadline, so a hang or crash is a "
        "row: auto = backends marked risky (default)",
    )
    parser.add_argument(
        "--run-time-limit",
        type=float,
        default=None,
        metavar="S",
        help="deadline of an isolated run in [s], worker start and warm-up included (default: "
        "max(600, 50 x simulated seconds))",
    )
    parser.add_argument(
        "--run-budget",
        type=float,
        default=None,
        metavar="S",
        help="wall-time budget of each run in [s]: a run that spends it stops between ticks "
        "(status budget; simulated_s says how far it got, the verdict is of what was "
        "simulated) (default: none, every run simulates its full duration)",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _add_selection_arguments(parser)
    _add_execution_arguments(parser)
    add_force_resume(  # what to do with a table already in the output folder
        parser,
        force="replace an existing table and its logs",
        resume="keep the rows already done (same formulation and duration) and run the rest",
    )
    add_strict(parser)


def run(args: argparse.Namespace) -> int:
    from ..harness.closed_loop import log_row, run_closed_loop
    from ..jit import warmup_logged
    from ..selection import parse_overrides, select_backends, select_scenarios
    from ..sim.scenario import load_scenario

    scenarios = select_scenarios(args.scenarios)
    overrides = parse_overrides(args.overrides)
    for name in scenarios if overrides else ():
        load_scenario(name, overrides=overrides)  # a bad key or value: one line naming it, exit 2
    backends = select_backends(args.backends)
    warmup_logged(log, backends)  # compiled here once: the worker processes load them
    bar = None
    total = len(scenarios) * len(backends)
    if not args.quiet:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="run", desc="closed loop", leave=False, disable=None)

    def on_row(row):
        if bar is not None:
            bar.update(1)
        log_row(log, row)

    try:
        outcome = run_closed_loop(
            scenarios,
            backends,
            args.out,
            duration=args.duration,
            formulation=args.formulation,
            force=args.force,
            resume=args.resume,
            jobs=args.jobs,
            on_row=on_row,
            isolate=args.isolate,
            run_time_limit=args.run_time_limit,
            deadline=args.deadline,
            run_budget=args.run_budget,
            overrides=overrides,
        )
    finally:
        if bar is not None:
            bar.close()
    log.info(
        "%d runs (%d new, %d kept), %d failed to run, %d failed their verdict; table in %s",
        len(outcome.table),
        outcome.ran,
        outcome.skipped,
        outcome.errors,
        outcome.not_ok,
        outcome.csv_path,
    )
    if not args.quiet and len(outcome.table):
        print(summary_table(outcome.table))
    code = strict_exit(args, runs=outcome.table)
    if not args.quiet and len(outcome.table):
        from ..report.recommend import recommend, render

        print("\n" + render(recommend(outcome.table)), end="")
    return code


def summary_table(table: pd.DataFrame) -> str:
    """One line per run: verdict, how far it got, tracking and force error after the transient,
    closest key point, p99 solve time and ticks over the 1 ms budget (plain text, aligned)."""
    import math

    def num(value, scale=1.0, spec=".3g"):
        try:
            value = float(value)
        except (TypeError, ValueError):
            return "-"
        return "-" if math.isnan(value) else format(value * scale, spec)

    header = (
        "scenario",
        "backend",
        "verdict",
        "simulated s",
        "tracking max mm",
        "force err max N",
        "d_min mm",
        "body mm",
        "solve p99 us",
        "ticks > dt",
    )
    rows = [header]
    for r in table.to_dict("records"):
        rows.append(
            (
                str(r.get("scenario")),
                str(r.get("backend")),
                str(r.get("verdict") or r.get("status")),
                num(r.get("simulated_s"), spec=".4g"),
                num(r.get("tracking_max_after_2s"), 1e3),
                num(r.get("force_error_max_after_2s")),
                num(r.get("min_obstacle_distance"), 1e3, ".4g"),
                num(r.get("min_body_distance"), 1e3, ".4g"),
                num(r.get("solve_time_p99_s"), 1e6, ".4g"),
                num(r.get("deadline_misses"), spec=".0f"),
            )
        )
    widths = [max(len(row[c]) for row in rows) for c in range(len(header))]
    return "\n".join(
        "  ".join(
            cell.ljust(w) if c < 3 else cell.rjust(w)
            for c, (cell, w) in enumerate(zip(row, widths))
        )
        for row in rows
    )
