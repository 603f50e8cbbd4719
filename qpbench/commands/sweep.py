"""``qpbench sweep``: perturbed instances of a scenario (:mod:`qpbench.sweep`), each in closed loop
with each backend, run by an executor of :mod:`qpbench.runner`."""

from __future__ import annotations

import argparse

from ..report.markdown_table import aligned
from .options import add, add_force_resume, check_tables, log, pick, run_bar, strict_exit

HELP = "sample perturbed instances of a scenario and run each in closed loop with each backend (one row per pair)"
EXAMPLE = (
    "qpbench sweep problems/sweeps/wall.toml --backends daqp,osqp,qpoases --out wall-sweep --jobs 2; "
    "qpbench sweep problems/sweeps/narrow.toml --backends daqp --samples 20 --out narrow-sweep "
    "--executor dask --jobs 2"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ..runner import EXECUTORS, default_jobs

    parser.add_argument(
        "sweep",
        metavar="SWEEP.toml",
        help="sweep file: base scenario, distributions, seed, samples",
    )
    add(parser, "--backends", required=True)
    add(parser, "--engine")
    add(
        parser,
        "--out",
        help="folder: sweep.csv, sweep.json and instances/<name>.toml (each re-runs alone with "
        "qpbench simulate --scenario)",
    )
    parser.add_argument("--samples", type=int, metavar="N", help="instances (default: the file's)")
    add(
        parser,
        "--duration",
        help="simulated time of every instance in [s] (default: the file's, else the base's)",
    )
    add(
        parser,
        "--jobs",
        default=default_jobs(),
        help=f"runs at once: local worker processes, or the local Dask cluster's workers "
        f"(default: this machine's cores, {default_jobs()}). Timings are clean only with 1",
    )
    parser.add_argument(
        "--executor",
        choices=EXECUTORS,
        default="local",
        help="local (worker processes on this machine) or dask (default: local)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a running Dask scheduler (tls://HOST:8786 with --security); without it "
        "--executor dask starts a local cluster on 127.0.0.1",
    )
    parser.add_argument(
        "--security",
        metavar="FILE",
        help="TOML or YAML naming ca_file, cert_file, key_file (PEM) for a tls:// scheduler",
    )
    add_force_resume(
        parser,
        force="start again: replace the table and the instances",
        resume="keep the rows with a result and run the rest (missing, error, crashed)",
    )


def run(args: argparse.Namespace) -> int:
    from contextlib import closing

    import pandas as pd

    from ..backends import plugin_files
    from ..jit import warmup_logged
    from ..runner import make_executor
    from ..selection import select_backends
    from ..sweep.runner import CSV_NAME, run_sweep
    from ..sweep.spec import load_sweep

    plugins = plugin_files()  # loaded by the CLI (--plugin, QPBENCH_PLUGINS); every worker too
    spec = load_sweep(args.sweep, samples=args.samples, duration=args.duration)
    backends = select_backends(args.backends)
    check_tables(args.out, [CSV_NAME], args)  # before any worker starts
    warmup_logged(log, backends)

    def warn(row):
        if row["status"] in ("error", "crashed"):
            log.warning(
                "%s / %s: %s (%s)", row["instance"], row["backend"], row["status"], row["error"]
            )

    with (
        closing(make_executor(args.executor, args.jobs, args.scheduler, args.security)) as pool,
        run_bar(args, spec.samples * len(backends), f"sweep {spec.name}", warn) as on_row,
    ):
        if pool.concurrency > 1:
            log.warning(
                "%d closed loops solve at once (%s executor): the timing columns (solve_time_*, "
                "deadline_misses, ticks_over_1ms, real_time_factor) are disturbed by each other "
                "(shared caches, memory bandwidth, clock); each row records host, worker and "
                "concurrent_solves. Take timings with --jobs 1",
                pool.concurrency,
                pool.name,
            )
        kw = pick(args, "force resume engine")
        outcome = run_sweep(spec, backends, args.out, pool, plugins=plugins, on_row=on_row, **kw)
    if not args.quiet:
        print(summary_table(outcome.rows, backends))
    log.info(
        "%d rows (%d run now, %d kept), %d failed to run; table in %s",
        len(outcome.rows),
        outcome.ran,
        outcome.kept,
        outcome.failed,
        outcome.csv_path,
    )
    return strict_exit(args, runs=pd.DataFrame(outcome.rows))


def summary_table(rows: list[dict], backends: list[str]) -> str:
    """Per backend: runs and how many of each verdict."""
    from ..sim.verdict import VERDICTS

    lines = [["backend", "runs", *VERDICTS, "error/crashed", "invalid"]]
    rows = [r for r in rows if str(r.get("noise_floor")) != "True"]  # the machine's own loop
    for b in backends + sorted({r["backend"] for r in rows} - set(backends)):
        mine = [r for r in rows if r["backend"] == b]
        counts = [sum(r["verdict"] == v and r["status"] == "ok" for r in mine) for v in VERDICTS]
        failed = sum(r["status"] in ("error", "crashed") for r in mine)
        invalid = sum(r["status"] == "invalid_scenario" for r in mine)
        lines.append([b, *map(str, [len(mine), *counts, failed, invalid])])
    return aligned(lines)
