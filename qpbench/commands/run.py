"""``qpbench run``: the main job. Problem sets, bench, closed loop and report into results/.

With no arguments, on a fresh clone:

1. problem sets: ``problems/<scenario>/`` for the paper's four scenarios
   (free, wall, adaptive, narrow), relative to the current folder; a missing
   set is regenerated there by the simulator (every 10th tick of the
   scenario's 20 s, ``paper`` formulation, solved with a QP backend);
2. bench: every available backend on every K-th problem of each set
   (``--bench-every``, default :data:`BENCH_EVERY`: 400 of the 2,000 per
   scenario, every 50th control tick; an online backend integrates the 50 ms
   between two of them per call), sequential mode, default profile, each problem timed 3 times
   (``--repeat``; the report shows the minimum), one CSV per scenario in
   ``results/bench/``;
3. closed loop: every shipped scenario with every available backend in the
   loop, ``results/closed_loop.csv`` and ``results/logs/``. No backend is
   left out: each run has a wall-time budget (``--run-budget``, default
   :data:`RUN_BUDGET_S`) and stops between ticks when it is spent. Its row
   then has status ``budget``, the simulated time it reached
   (``simulated_s``), its real-time factor over that time, and a verdict of
   what it simulated (the trajectory up to the stop is the uncut run's: a
   simulated trajectory does not depend on how long a solve took). Backends
   that keep up with the loop finish their 20 s well within the budget (at
   a real-time factor of 10-100, 0.2-2 s); those that do not (cvxpy,
   qpsolvers' clarabel, highs, osqp, scs, the converged RNN: 0.02-0.8) get
   as far as the budget allows;
4. report: ``results/report.md`` and ``results/plots/``.

Where outputs go: ``--out`` (default ``./results``, relative to the current
folder, also when qpbench is installed as a package). The run works in
``OUT/.partial/`` and, once everything is done, replaces the previous run's
outputs in ``OUT`` (``bench/``, ``logs/``, ``plots/``, ``closed_loop.csv``,
``report.md``, ``run.json``), each by a rename: a run killed half-way leaves
the previous results whole. Other files in ``OUT`` are never touched. The
outputs are recognised as a previous run's by ``OUT/run.json``; if one of
those names exists without it, it is someone else's file and needs
``--force``. ``--resume`` continues an interrupted run from
``OUT/.partial/``. So ``qpbench run`` twice simply refreshes ``results/``.

Exit code: 0, or 1 when a solve failed in the bench or a closed-loop run
raised or failed its verdict (:mod:`qpbench.sim.verdict`).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import shutil
import time
from dataclasses import replace
from pathlib import Path

HELP = "the main job: make missing problem sets, bench every backend, closed loop every scenario, write results/ and report.md"
EXAMPLE = "qpbench run    (quick: qpbench run --duration 0.5 --scenarios wall --backends qpsolvers:daqp,pinv --out /tmp/r)"

log = logging.getLogger("qpbench.run")

#: Outputs of a run inside ``--out`` (replaced as a whole at the end of a run).
OUTPUTS = ("bench", "logs", "plots", "closed_loop.csv", "report.md", "run.json")
#: Staging folder of a run in progress, inside ``--out``.
STAGING = ".partial"
#: Every k-th tick goes into a problem set.
EVERY = 10
#: The bench of ``run`` takes every k-th problem of each set: 400 of each set's 2,000
#: (every 50th control tick, 0.05 s apart over the 20 s), timed 3 times each, so that
#: README's first command (install, compile, bench, closed loop, report) stays within
#: 10 minutes on 2 cores. ``--bench-every 1`` benches all 2,000 (about 3 minutes per set).
BENCH_EVERY = 5
#: Wall-time budget of each closed-loop run [s] (``--run-budget``). The first
#: command of the README runs 17 backends x 5 scenarios: the bench takes about
#: 3 minutes and the 55 runs of the backends that keep up with the loop about
#: 1.5 (20 s each at real-time factors of 10-100); the 30 runs of the 6 slow
#: backends then take at most 30 x 5 s = 2.5 minutes, which keeps the whole
#: job near 7.5 minutes, inside 10 minutes on 2 cores. In 5 s qpsolvers'
#: clarabel, highs, osqp and scs (real-time factors 0.4-0.8 on an idle
#: machine) get through the infeasible start (0.13 s) and the transient to
#: 2-4 s, cvxpy (0.3) to about 1.5 s, the converged RNN (0.02-0.06) to 0.1-0.3 s.
RUN_BUDGET_S = 5.0
#: Timed solves per bench problem (the report shows the minimum: warm caches).
REPEAT = 3
#: Backends that may regenerate a missing problem set, first available wins.
DUMP_BACKENDS = ("qpsolvers:daqp", "clarabel", "proxqp", "qpsolvers:quadprog", "osqp")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="results", metavar="DIR",
                        help="results folder (default: ./results)")
    parser.add_argument("--problems", default="problems", metavar="DIR",
                        help="folder of the problem sets <DIR>/<scenario>/ (default: ./problems; "
                             "missing sets are regenerated there)")
    parser.add_argument("--scenarios", default="all",
                        help="comma-separated scenarios, or 'all' shipped ones (default: all; the bench "
                             "uses the paper's four among them)")
    parser.add_argument("--backends", default="all",
                        help="comma-separated backends, or 'all' available ones (default: all)")
    parser.add_argument("--duration", type=float, default=None, metavar="S",
                        help="closed-loop time per run in [s] (default: the scenario's, 20 s); the bench "
                             "then uses only the problems with t < S (quick runs)")
    parser.add_argument("--bench-every", type=int, default=BENCH_EVERY, metavar="K",
                        help=f"bench every K-th problem of each set (default: {BENCH_EVERY}: 400 of each set's "
                             "2,000, every 50th control tick; 1: all of them, about 4x longer)")
    parser.add_argument("--run-budget", type=float, default=RUN_BUDGET_S, metavar="S",
                        help=f"wall-time budget of each closed-loop run in [s] (default: {RUN_BUDGET_S:g}): a run "
                             "that spends it stops between ticks; its row says how far it got (simulated_s) and "
                             "its verdict is of what it simulated. 0: no budget, every run simulates its full "
                             "duration (slow backends then take minutes per scenario)")
    parser.add_argument("--repeat", type=int, default=REPEAT, metavar="R",
                        help=f"timed solves per bench problem; the report uses the minimum (default: {REPEAT})")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="closed-loop runs in parallel worker processes (default: 1)")
    from .inspect_ import add_memory_argument

    add_memory_argument(parser)
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--force", action="store_true",
                       help="replace bench/, logs/, plots/, closed_loop.csv or report.md in --out even "
                            "if no previous 'qpbench run' wrote them")
    group.add_argument("--resume", action="store_true",
                       help="continue an interrupted run from OUT/.partial/")


def _check_out(out: Path, force: bool) -> None:
    """Refuse to replace outputs that a previous ``qpbench run`` did not write.

    ``run`` only ever replaces the names in :data:`OUTPUTS`; other files and
    folders in ``out`` (e.g. ``results/simulate/``) are left alone. If one of
    those names exists and ``out/run.json`` does not, it is someone else's
    file and ``--force`` is needed.
    """
    from ..exceptions import OutputExistsError

    if not out.exists():
        return
    if not out.is_dir():
        raise OutputExistsError(f"{out}: exists and is not a folder")
    if (out / "run.json").exists() or force:
        return
    clash = sorted(name for name in OUTPUTS if (out / name).exists())
    if clash:
        raise OutputExistsError(
            f"{out}: holds {', '.join(clash)} not written by 'qpbench run' (no run.json); "
            "pass --force to replace them"
        )


def _dump_backend(backends: list[str]) -> str:
    from ..backends import backend_names
    from ..exceptions import BackendNotFound

    available = set(backend_names(available_only=True))
    for name in DUMP_BACKENDS:
        if name in available:
            return name
    raise BackendNotFound(f"no QP backend to generate problem sets with (tried {', '.join(DUMP_BACKENDS)})")


def make_problem_set(scenario: str, folder: Path, backend: str) -> Path:
    """Regenerate a scenario's problem set: every 10th tick of its full run, paper formulation."""
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    log.info("problem set %s missing: simulating %s with %s to dump every %dth tick", folder, scenario,
             backend, EVERY)
    simulate(load_scenario(scenario), backend, formulation="paper", every=EVERY, dump=folder)
    return folder


def _bench_subset(problem_set, duration: float | None, every: int = 1):
    """The problem set and its references: every ``every``-th problem, those with t < duration."""
    from ..reference import reference_solutions
    from ..selection import select_set

    refs = reference_solutions(problem_set)
    if duration is None and every == 1:
        return problem_set, refs
    keep = [
        i for i, r in enumerate(problem_set.records)
        if i % every == 0 and (duration is None or r.t is None or r.t < duration)
    ]
    if not keep:
        keep = [0]
    # the time between two kept records grows by ``every``: an online backend integrates that much per call
    stretched = select_set(problem_set, every=every) if every > 1 else problem_set
    return (replace(stretched, records=[problem_set.records[i] for i in keep]), [refs[i] for i in keep])


def _compress_bench(bench_dir: Path) -> None:
    """Gzip the finished bench CSVs (about 7x smaller; ``qpbench report`` reads them as they are).

    Only a completed run is compressed: an interrupted one keeps its plain,
    appendable CSVs in the staging folder for ``--resume``.
    """
    import gzip

    for csv_path in sorted(bench_dir.glob("*.csv")):
        gz_path = csv_path.with_name(csv_path.name + ".gz")
        with open(csv_path, "rb") as src, gzip.GzipFile(gz_path, "wb", mtime=0) as dst:
            shutil.copyfileobj(src, dst)
        csv_path.unlink()


def _promote(staging: Path, out: Path) -> None:
    """Replace the previous run's outputs in ``out`` by the staged ones (one rename each)."""
    for name in OUTPUTS:
        src = staging / name
        dst = out / name
        if not src.exists():
            continue
        if src.is_dir():
            old = out / f".old-{name}"
            if old.exists():
                shutil.rmtree(old)
            if dst.exists():
                os.replace(dst, old)
            os.replace(src, dst)
            if old.exists():
                shutil.rmtree(old)
        else:
            os.replace(src, dst)
    shutil.rmtree(staging, ignore_errors=True)


def run(args: argparse.Namespace) -> int:
    from ..atomic import write_text
    from ..exceptions import ParamError
    from ..formats import load_problems
    from ..harness.bench import BenchConfig, run_bench
    from ..memory import resolve_budget
    from ..harness.closed_loop import PAPER_SCENARIOS, resolve_backends, resolve_scenarios, run_closed_loop
    from .closed_loop import log_row
    from ..jit import warmup_logged
    from ..report import write_report

    started = time.perf_counter()
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        raise ParamError(f"must be a positive number of seconds, got {args.duration}", key="--duration")
    if args.bench_every < 1:
        raise ParamError(f"must be an integer >= 1, got {args.bench_every}", key="--bench-every")
    if not (args.run_budget >= 0 and math.isfinite(args.run_budget)):
        raise ParamError(f"must be a number of seconds >= 0 (0: no budget), got {args.run_budget}", key="--run-budget")
    run_budget = args.run_budget or None
    if args.repeat < 1:
        raise ParamError(f"must be an integer >= 1, got {args.repeat}", key="--repeat")
    out = Path(args.out)
    problems = Path(args.problems)
    scenarios = resolve_scenarios(args.scenarios)
    backends = resolve_backends(args.backends)
    bench_scenarios = [s for s in scenarios if s in PAPER_SCENARIOS] or scenarios
    _check_out(out, args.force)
    staging = out / STAGING
    if staging.exists() and not args.resume:
        shutil.rmtree(staging)
    staging.mkdir(parents=True, exist_ok=True)

    warmup_logged(log)  # before anything is timed; the worker processes load them from the cache
    missing = [s for s in bench_scenarios if not (problems / s / "problems.parquet").exists()]
    total = len(missing) + len(bench_scenarios) + len(scenarios) * len(backends) + 1
    from tqdm import tqdm

    bar = tqdm(total=total, unit="step", desc="qpbench run", disable=True if args.quiet else None)
    failures = 0
    try:
        for s in missing:
            bar.set_description(f"problem set {s}")
            make_problem_set(s, problems / s, _dump_backend(backends))
            bar.update(1)
        bench_dir = staging / "bench"
        for s in bench_scenarios:
            bar.set_description(f"bench {s}")
            subset, refs = _bench_subset(load_problems(problems / s), args.duration, args.bench_every)
            summary = run_bench(
                subset,
                BenchConfig(backends=list(backends), profile="default", mode="sequential", repeat=args.repeat,
                            memory_budget=resolve_budget(args.memory_budget)),
                bench_dir / f"{s}.csv",
                resume=args.resume,
                force=not args.resume,
                references=refs,
            )
            log.info("bench %s: %s", s, summary.line())
            for line in summary.table().splitlines():
                log.info("bench %s: %s", s, line)
            failures += summary.failures
            bar.update(1)

        def on_row(row):
            bar.set_description(f"closed loop {row['scenario']}")
            bar.update(1)
            if row.get("verdict") not in ("ok", "", None):
                log_row(log, row)  # a WARNING with the reasons

        bar.set_description("closed loop")
        outcome = run_closed_loop(scenarios, backends, staging, duration=args.duration,
                                  formulation="paper", force=not args.resume, resume=args.resume,
                                  jobs=args.jobs, on_row=on_row, run_budget=run_budget)
        failures += outcome.not_ok  # failed runs and runs that failed their verdict
        table = outcome.table
        stopped = table[table["status"] == "budget"]
        bar.set_description("report")
        manifest = {
            "command": "qpbench run",
            "scenarios": scenarios,
            "bench_scenarios": bench_scenarios,
            "backends": backends,
            "duration_s": args.duration,
            "run_budget_s": run_budget,
            "bench_every": args.bench_every,
            "closed_loop_stopped_by_budget": {
                f"{r.scenario}/{r.backend}": round(float(r.simulated_s), 3) for r in stopped.itertuples()
            },
            "closed_loop_not_ok": {
                f"{r.scenario}/{r.backend}": str(r.verdict) for r in table.itertuples()
                if str(r.verdict) not in ("ok", "nan", "")
            },
            "bench_repeat": args.repeat,
            "problems": str(problems),
            "wall_time_s": None,
        }
        write_report([bench_dir, staging / "closed_loop.csv"], staging, force=True)
        _compress_bench(bench_dir)
        bar.update(1)
        manifest["wall_time_s"] = round(time.perf_counter() - started, 1)
        write_text(staging / "run.json", json.dumps(manifest, indent=2) + "\n")
        _promote(staging, out)
    finally:
        bar.close()
    log.info("qpbench run: %s in %.0f s (%d failed solves, failed runs or runs that failed their verdict); report %s", out,
             time.perf_counter() - started, failures, out / "report.md")
    return 1 if failures else 0
