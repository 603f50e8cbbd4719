"""The main job (``qpbench run``, :func:`run_all`): problem sets, bench, closed loop and report
into one folder (docs/architecture.md, "The run pipeline"), told phase by phase (:class:`Phases`)."""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import promote, record, write_text
from ..exceptions import positive_count, positive_seconds

if TYPE_CHECKING:
    from ..formats import ProblemSet

log = logging.getLogger("qpbench.run")

#: Outputs of a run inside ``--out`` (replaced as a whole at the end of a run).
OUTPUTS = ("bench", "logs", "figure_logs", "plots", "closed_loop.csv", "report.md", "run.json")
#: Staging folder of a run in progress, inside ``--out``.
STAGING = ".partial"
#: Every k-th tick goes into a problem set.
EVERY = 10
#: The bench of ``run`` takes every k-th problem of each set (every 100th control tick).
BENCH_EVERY = 10
#: The most wall time a closed-loop run may take [s] (``--run-budget``).
RUN_BUDGET_S = 10.0
#: A backend's closed-loop budget is this many times the run its bench median predicts.
BUDGET_MARGIN = 3.0
#: The least closed-loop budget of a backend that keeps up [s] (the loop's own work per tick).
BUDGET_FLOOR_S = 2.0
#: The budget of a backend whose solves alone would take longer than ``run_budget`` [s].
CUT_BUDGET_S = 1.0
#: Closed-loop runs at once in ``run`` (``--jobs``), each in a worker process, at most one per core.
LOOP_JOBS = 2
#: Timed solves per bench problem (the report shows the minimum: warm caches).
REPEAT = 3
#: Backends that may regenerate a missing problem set, first available wins.
DUMP_BACKENDS = ("qpsolvers:daqp", "clarabel", "proxqp", "qpsolvers:quadprog", "osqp")


@dataclass
class Phase:
    """One phase in progress: :meth:`update` counts work done."""

    name: str
    bar: object | None = None

    def update(self, n: int = 1) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def describe(self, text: str) -> None:
        """Show what is being done now beside the bar."""
        if self.bar is not None:
            self.bar.set_postfix_str(text, refresh=False)


@dataclass
class Phases:
    """The phases of a job, each timed and told; ``bars``: ``None`` when stderr is a terminal,
    ``False`` never; ``times_s``: wall time of each finished phase [s], in the order run."""

    log: logging.Logger
    bars: bool | None = None
    times_s: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.bars is None:
            self.bars = sys.stderr.isatty()

    @contextmanager
    def phase(self, name: str, total: int | None = None, unit: str = "step", bar: bool = True):
        """Run a phase, yielding a :class:`Phase`; ``total``: the work units it counts (the bar's
        length); ``bar=False``: its code draws one."""
        self.log.info("%s: started", name)
        progress = None
        if self.bars and bar:
            from tqdm import tqdm

            progress = tqdm(total=total, unit=unit, desc=name, leave=False, file=sys.stderr)
        start = time.perf_counter()
        try:
            yield Phase(name, progress)
        finally:
            if progress is not None:
                progress.close()
        seconds = time.perf_counter() - start
        self.times_s[name] = round(self.times_s.get(name, 0.0) + seconds, 1)
        self.log.info("%s: done in %.1f s", name, seconds)


def default_jobs() -> int:
    """Closed-loop runs at once by default: :data:`LOOP_JOBS`, at most one per core."""
    return max(1, min(LOOP_JOBS, os.cpu_count() or 1))


@dataclass
class RunConfig:
    """What ``qpbench run`` does: ``problems``: folder of the sets ``<problems>/<scenario>/``;
    ``duration``: closed-loop time per run [s] (``None``: the scenario's); ``run_budget``: most
    wall time of a closed-loop run [s]; ``memory_budget``: bytes a bench solve may need;
    ``on_row``: called with each closed-loop row."""

    out: Path
    problems: Path
    scenarios: list[str]
    backends: list[str]
    duration: float | None = None
    bench_every: int = BENCH_EVERY
    run_budget: float | None = RUN_BUDGET_S
    repeat: int = REPEAT
    jobs: int = 1
    memory_budget: int | None = None
    force: bool = False
    resume: bool = False
    progress: bool = True
    on_row: Callable[[dict], None] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.duration is not None:
            self.duration = positive_seconds(self.duration, "--duration")
        if self.run_budget is not None:
            self.run_budget = positive_seconds(self.run_budget, "--run-budget")
        positive_count(self.bench_every, "--bench-every")
        positive_count(self.repeat, "--repeat")
        positive_count(self.jobs, "--jobs")


@dataclass
class RunOutcome:
    """What :func:`run_all` did: failed solves, failed runs and runs that failed their verdict,
    the report, the time it took [s], and the bench's failed solves alone."""

    failures: int
    report: Path
    wall_time_s: float
    failed_solves: int = 0


def _check_out(out: Path, force: bool) -> None:
    """Refuse to replace :data:`OUTPUTS` that ``qpbench run`` did not write, unless ``force``."""
    from ..atomic import check_folder
    from ..exceptions import OutputExistsError

    check_folder(out)
    if not out.exists() or (out / "run.json").exists() or force:
        return
    clash = sorted(name for name in OUTPUTS if (out / name).exists())
    if clash:
        raise OutputExistsError(
            f"{out}: holds {', '.join(clash)} not written by 'qpbench run' (no run.json); "
            "pass --force to replace them"
        )


def _dump_backend() -> str:
    from ..backends import backend_names
    from ..exceptions import BackendNotFound

    available = set(backend_names())
    for name in DUMP_BACKENDS:
        if name in available:
            return name
    tried = ", ".join(DUMP_BACKENDS)
    raise BackendNotFound(f"no QP backend to generate problem sets with (tried {tried})")


def bench_subset(
    problem_set: ProblemSet, duration: float | None, every: int = 1
) -> tuple[ProblemSet, list]:
    """Every ``every``-th problem with ``t < duration``, and their references."""
    from ..reference import reference_solutions
    from ..selection import select_set

    stretched = select_set(problem_set, every=every)
    kept = [r for r in stretched.records if duration is None or r.t is None or r.t < duration]
    subset = replace(stretched, records=kept or stretched.records[:1])
    return subset, reference_solutions(subset)


def _compress_bench(bench_dir: Path) -> None:
    """Gzip the bench CSVs of a completed run (an interrupted one keeps them appendable)."""
    import gzip

    for csv_path in sorted(bench_dir.glob("*.csv")):
        gz_path = csv_path.with_name(csv_path.name + ".gz")
        with open(csv_path, "rb") as src, gzip.GzipFile(gz_path, "wb", mtime=0) as dst:
            shutil.copyfileobj(src, dst)
        record(gz_path)
        csv_path.unlink()


def run_all(config: RunConfig) -> RunOutcome:
    """Problem sets, bench, closed loop and report, each a phase, in ``OUT/.partial/``; then the
    previous run's :data:`OUTPUTS` are replaced, each by a rename."""
    from ..formats import load_problems
    from ..jit import warmup_logged
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario, paper_scenarios

    started = time.perf_counter()
    out, problems = Path(config.out), Path(config.problems)
    paper = paper_scenarios()  # the bench's: the paper's four among those asked, else all asked
    bench_scenarios = [s for s in config.scenarios if s in paper] or list(config.scenarios)
    _check_out(out, config.force)
    staging = out / STAGING
    if staging.exists() and not config.resume:
        shutil.rmtree(staging)
    staging.mkdir(parents=True, exist_ok=True)

    phases = Phases(log, bars=None if config.progress else False)
    missing = [s for s in bench_scenarios if not (problems / s / "problems.parquet").exists()]
    dump = [_dump_backend()] if missing else []
    with phases.phase("compile"):  # only the backends this run runs, before anything is timed
        warmup_logged(log, [*config.backends, *dump])
    for s in missing:
        with phases.phase(f"problem set {s}"):
            log.info("simulating %s with %s to dump every %dth tick", s, dump[0], EVERY)
            simulate(load_scenario(s), dump[0], formulation="paper", every=EVERY, dump=problems / s)
    with phases.phase("references", total=len(bench_scenarios), unit="set") as phase:
        subsets = {}
        for s in bench_scenarios:
            phase.describe(s)
            subsets[s] = bench_subset(
                load_problems(problems / s), config.duration, config.bench_every
            )
            phase.update()
    failures, per_tick_s = _bench(config, subsets, staging / "bench", phases)
    failed_solves = failures
    budgets = closed_loop_budgets(config, per_tick_s)
    table, not_ok = _closed_loop(config, staging, phases, budgets)
    failures += not_ok  # failed runs and runs that failed their verdict
    with phases.phase("report"):
        from ..report.write import write_report

        write_report([staging / "bench", staging / "closed_loop.csv"], staging, force=True)
        _compress_bench(staging / "bench")
    elapsed = time.perf_counter() - started
    manifest = _manifest(config, bench_scenarios, table, budgets)
    manifest["phase_wall_time_s"] = dict(phases.times_s)
    manifest["wall_time_s"] = round(elapsed, 1)
    write_text(staging / "run.json", json.dumps(manifest, indent=2) + "\n")
    promote(staging, out, OUTPUTS)
    return RunOutcome(failures, out / "report.md", elapsed, failed_solves)


def _bench(
    config: RunConfig, subsets: dict, bench_dir: Path, phases
) -> tuple[int, dict[str, float]]:
    """Bench every backend on each scenario's problems: the failed solves, and each backend's
    median over all sets of ``wall_time_min_s`` [s]."""
    import statistics

    from .bench import BenchConfig, run_bench

    failures = 0
    times: dict[str, list[float]] = {}
    bench = BenchConfig(
        list(config.backends), repeat=config.repeat, memory_budget=config.memory_budget
    )
    for s, (subset, refs) in subsets.items():
        with phases.phase(f"bench {s}", bar=False):
            summary = run_bench(
                subset,
                bench,
                bench_dir / f"{s}.csv",
                resume=config.resume,
                force=not config.resume,
                references=refs,
                progress=bool(phases.bars),  # its own bar, one step per solve
            )
        log.info("bench %s: %s", s, summary.line())
        for line in summary.table().splitlines():
            log.debug("bench %s: %s", s, line)
        failures += summary.failures
        for name, stats in summary.backends.items():
            times.setdefault(name, []).extend(stats.times_s)
    return failures, {b: statistics.median(t) for b, t in times.items() if t}


def closed_loop_budgets(config: RunConfig, per_tick_s: dict[str, float]) -> dict[str, float]:
    """Each backend's closed-loop wall-time budget [s]: a bench median ``t`` predicts a run of
    ``ticks * t`` (the longest scenario's); the budget is :data:`BUDGET_MARGIN` times that, within
    :data:`BUDGET_FLOOR_S` and ``run_budget``; :data:`CUT_BUDGET_S` where the prediction exceeds
    ``run_budget``; ``run_budget`` without a bench time."""
    if config.run_budget is None:
        return {}
    from ..sim.scenario import load_scenario

    scenarios = [load_scenario(name) for name in config.scenarios]
    ticks = max(
        (math.ceil((config.duration or sc.duration) / sc.dt) for sc in scenarios), default=0
    )
    run_budget = config.run_budget
    floor = min(BUDGET_FLOOR_S, run_budget)
    budgets = {}
    for backend in config.backends:
        predicted = ticks * per_tick_s.get(backend, math.nan)
        if not math.isfinite(predicted):
            budgets[backend] = run_budget
        elif predicted > run_budget:
            budgets[backend] = min(CUT_BUDGET_S, run_budget)
        else:
            budgets[backend] = round(min(run_budget, max(floor, BUDGET_MARGIN * predicted)), 3)
    return budgets


def _closed_loop(config: RunConfig, staging: Path, phases, budgets: dict[str, float]):
    """Every scenario with every backend in the loop; the table and its runs that are not ok."""
    from ..backends import NOISE_FLOOR
    from .closed_loop import run_closed_loop

    per_scenario = len({*config.backends, NOISE_FLOOR})  # the noise floor's run with the others
    runs = len(config.scenarios) * per_scenario
    left = {s: per_scenario for s in config.scenarios}
    with phases.phase("closed loop", total=runs, unit="run") as phase:
        started = time.perf_counter()

        def on_row(row):
            phase.describe(f"{row['scenario']} {row['backend']}")
            phase.update()
            s = row["scenario"]
            left[s] = left.get(s, 1) - 1
            if left[s] == 0:  # a scenario's last run: one line per scenario
                spent = time.perf_counter() - started
                n = per_scenario
                log.info("closed loop %s: %d runs done (%.1f s into the closed loop)", s, n, spent)
            if config.on_row is not None:
                config.on_row(row)

        outcome = run_closed_loop(
            config.scenarios,
            config.backends,
            staging,
            duration=config.duration,
            force=not config.resume,
            resume=config.resume,
            jobs=config.jobs,
            on_row=on_row,
            run_budget=config.run_budget,
            budgets=budgets or None,
        )
    return outcome.table, outcome.not_ok


def _manifest(config: RunConfig, bench_scenarios: list[str], table, budgets: dict) -> dict:
    """``run.json``: what was asked, the budgets, which runs were cut or not ok."""
    from ..report.recommend import noise_floor_runs

    stopped = table[table["status"] == "budget"]
    return {
        "command": "qpbench run",
        "scenarios": config.scenarios,
        "bench_scenarios": bench_scenarios,
        "backends": config.backends,
        "duration_s": config.duration,
        "run_budget_s": config.run_budget,
        "closed_loop_budget_s": budgets,
        "bench_every": config.bench_every,
        "closed_loop_stopped_by_budget": {
            f"{r.scenario}/{r.backend}": round(float(r.simulated_s), 3)
            for r in stopped.itertuples()
        },
        "closed_loop_not_ok": {
            f"{r.scenario}/{r.backend}": str(r.verdict)
            for r in table[~noise_floor_runs(table)].itertuples()
            if str(r.verdict) not in ("ok", "nan", "")
        },
        "bench_repeat": config.repeat,
        "closed_loop_jobs": config.jobs,
        "problems": str(config.problems),
    }
