"""The main job (``qpbench run``, :func:`run_all`): problem sets, bench, closed loop and report
into one folder (docs/architecture.md, "The run pipeline"), told phase by phase (:class:`Phases`)."""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import sys
import threading
import time
from collections.abc import Callable
from contextlib import closing, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..atomic import promote, record, write_text
from ..exceptions import positive_count, positive_seconds
from ..report.recommend import MIN_OK_BOUND, check_bound

if TYPE_CHECKING:
    from ..formats import ProblemSet

log = logging.getLogger("qpbench.run")

#: Outputs of a run inside ``--out`` (replaced as a whole at the end of a run).
OUTPUTS = (
    "bench",
    "logs",
    "figure_logs",
    "perturbed",
    "plots",
    "closed_loop.csv",
    "report.md",
    "run.json",
)
#: Folder of the perturbed runs inside ``--out``: ``perturbed/<scenario>/``, a sweep's folder each.
PERTURBED = "perturbed"
#: Wall time of the perturbed runs of ``run`` [s] (``--sweep-budget``).
SWEEP_BUDGET_S = 60.0
#: Instances sampled at a time while looking for the valid ones a sweep needs.
SAMPLE_CHUNK = 16
#: Staging folder of a run in progress, inside ``--out``.
STAGING = ".partial"
#: Every k-th tick goes into a problem set.
EVERY = 10
#: The bench of ``run`` takes every k-th problem of each set (every 400th control tick).
BENCH_EVERY = 40
#: The most wall time a closed-loop run may take [s] (``--run-budget``).
RUN_BUDGET_S = 10.0
#: A backend's closed-loop budget is this many times the run its bench mean predicts.
BUDGET_MARGIN = 3.0
#: The least closed-loop budget of a backend that keeps up [s] (the loop's own work per tick).
BUDGET_FLOOR_S = 2.0
#: The budget of a backend that cannot be recommended by this run [s]: its solves alone would
#: take longer than ``run_budget``, or the perturbed runs could not afford it.
CUT_BUDGET_S = 0.25
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
    """What ``qpbench run`` does (its options): ``problems``: folder of the sets
    ``<problems>/<scenario>/``; ``duration``, ``run_budget``, ``sweep_budget`` [s];
    ``memory_budget`` [bytes]; ``on_row``: called with each closed-loop row."""

    out: Path
    problems: Path
    scenarios: list[str]
    backends: list[str]
    duration: float | None = None
    bench_every: int = BENCH_EVERY
    run_budget: float | None = RUN_BUDGET_S
    engine: str = "compiled"
    repeat: int = REPEAT
    jobs: int = 1
    memory_budget: int | None = None
    force: bool = False
    resume: bool = False
    progress: bool = True
    on_row: Callable[[dict], None] | None = field(default=None, repr=False)
    sweep_budget: float = SWEEP_BUDGET_S
    min_ok_bound: float = MIN_OK_BOUND

    def __post_init__(self) -> None:
        self.sweep_budget = positive_seconds(self.sweep_budget, "--sweep-budget")
        self.min_ok_bound = check_bound(self.min_ok_bound)
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

    name = next((name for name in DUMP_BACKENDS if name in backend_names()), None)
    if name is None:
        tried = ", ".join(DUMP_BACKENDS)
        raise BackendNotFound(f"no QP backend to generate problem sets with (tried {tried})")
    return name


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
    from ..jit import kernels_for, warmup_logged
    from ..sim.loop import simulate
    from ..sim.scenario import load_scenario

    started = time.perf_counter()
    out, problems = Path(config.out), Path(config.problems)
    bench_scenarios = bench_sets(config.scenarios)
    _check_out(out, config.force)
    staging = out / STAGING
    if staging.exists() and not config.resume:
        shutil.rmtree(staging)
    staging.mkdir(parents=True, exist_ok=True)

    phases = Phases(log, bars=None if config.progress else False)
    missing = [s for s in bench_scenarios if not (problems / s / "problems.parquet").exists()]
    dump = [_dump_backend()] if missing else []
    with phases.phase("compile"):  # only the backends this run runs, before anything is timed
        # here what the bench times; the closed loop's kernels in a worker, beside it and then
        # behind the bench (None: nothing left for it)
        here = (*config.backends, *dump), bool(missing)
        behind = _compile_behind(config.backends, kernels_for(*here))
        warmup_logged(log, *here)
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
    failed_solves, per_tick_s = _bench(config, subsets, staging / "bench", phases)
    if behind is not None:
        with phases.phase("compile, closed loop"):  # what is left of it, then loaded here
            _meet_halfway(behind)
            behind.join()
            warmup_logged(log, config.backends)
    specs = sweep_specs(config)
    budgets = closed_loop_budgets(config, per_tick_s, specs)
    table, not_ok = _closed_loop(config, staging, phases, budgets)
    perturbed = _perturbed(config, staging / PERTURBED, phases, table, specs)
    with phases.phase("report"):
        from ..report.write import write_report
        from ..sweep.report import split_sweep_paths, sweep_section

        swept = (staging / PERTURBED).is_dir()
        _, sweeps = split_sweep_paths([staging / PERTURBED]) if swept else ([], [])
        write_report(
            [staging / "bench", staging / "closed_loop.csv"],
            staging,
            force=True,
            sections=(lambda out, plots: sweep_section(sweeps, out, plots=False))
            if sweeps
            else None,
            files=sweeps,
            min_ok_bound=config.min_ok_bound,
            jobs=config.jobs,  # the figures on as many cores as the runs
        )
        _compress_bench(staging / "bench")
    elapsed = time.perf_counter() - started
    manifest = _manifest(config, bench_scenarios, table, budgets)
    manifest.update(perturbed=perturbed, phase_wall_time_s=dict(phases.times_s))
    manifest["wall_time_s"] = round(elapsed, 1)
    write_text(staging / "run.json", json.dumps(manifest, indent=2) + "\n")
    promote(staging, out, OUTPUTS)
    return RunOutcome(failed_solves + not_ok, out / "report.md", elapsed, failed_solves)


def bench_sets(scenarios: list[str]) -> list[str]:
    """The scenarios among ``scenarios`` whose problem sets the bench solves: the paper's and the
    spatial ones, else all of them."""
    from ..sim.scenario import load_scenario, paper_scenarios
    from .closed_loop import arm_family

    paper = paper_scenarios()
    spatial = [s for s in scenarios if arm_family(load_scenario(s)) == "spatial"]
    return [s for s in scenarios if s in paper or s in spatial] or list(scenarios)


def _compile_behind(backends: list[str], here: tuple[str, ...] = ()) -> threading.Thread | None:
    """Compile the closed loop's kernels for ``backends`` not prepared (or being prepared,
    ``here``) in this process into numba's on-disk cache, in a worker process, while this
    process benches: the thread that waits for it (a failure only leaves the compile to the
    closed loop), or ``None`` when none is left."""
    from ..jit import kernels_for, prepare, prepared

    todo = [k for k in kernels_for(backends) if k not in prepared() and k not in here]
    if not todo:
        return None

    def wait() -> None:
        from ..runner.process import context, run_tasks

        started = time.perf_counter()
        tasks = [("compile", todo, None)]
        for done in run_tasks(prepare, tasks, 1, ctx=context(fresh=True), name="qpbench-compile"):
            said = done.value.line() if done.lost is None else done.lost
            log.info("closed loop's %s (in a worker, %.1f s)", said, time.perf_counter() - started)

    thread = threading.Thread(target=wait, name="qpbench-compile", daemon=True)
    thread.todo = tuple(todo)
    thread.start()
    return thread


def _meet_halfway(behind: threading.Thread) -> None:
    """While the worker of :func:`_compile_behind` still compiles (its groups in order), compile
    its engines here from the last one back: the two meet in the middle (at most one group is
    compiled twice)."""
    from ..jit import ENGINE, prepare

    for group in reversed(behind.todo):
        if not behind.is_alive() or not group.startswith(ENGINE):
            return
        prepare([group])


def _bench(
    config: RunConfig, subsets: dict, bench_dir: Path, phases
) -> tuple[int, dict[str, float]]:
    """Bench every backend on each scenario's problems: the failed solves, and each backend's
    mean over all sets of ``wall_time_min_s`` [s] (a mean, as a run's time is a sum)."""
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
    return failures, {b: statistics.fmean(t) for b, t in times.items() if t}


def closed_loop_budgets(
    config: RunConfig, per_tick_s: dict[str, float], specs: dict | None = None
) -> dict[str, float]:
    """Each backend's closed-loop wall-time budget [s] (docs/methodology.md, "Closed loop"): a
    bench mean ``t`` predicts a run of ``ticks * t`` (the longest scenario's); the budget is
    :data:`BUDGET_MARGIN` times that, within :data:`BUDGET_FLOOR_S` and ``run_budget``
    (``run_budget`` without a bench time); :data:`CUT_BUDGET_S` for a backend on the Python
    engine whose prediction, or whose perturbed runs in the sweeps ``specs`` at ``t`` a tick,
    the run cannot afford."""
    if config.run_budget is None:
        return {}
    from ..engine.compiled import SOLVERS
    from ..report.recommend import TOLERATED_NOT_OK, least_runs
    from ..sim.scenario import load_scenario

    scenarios = [load_scenario(name) for name in config.scenarios]
    ticks = max(
        (math.ceil((config.duration or sc.duration) / sc.dt) for sc in scenarios), default=0
    )
    swept_ticks = least_runs(config.min_ok_bound, TOLERATED_NOT_OK) * sum(
        _length(sp) / float(sp.base_raw["simulation"]["dt"]) for sp in (specs or {}).values()
    )
    compiled = SOLVERS if config.engine == "compiled" else ()
    run_budget = config.run_budget
    budgets = {}
    for backend in config.backends:
        t = per_tick_s.get(backend, math.nan)
        late = ticks * t > run_budget or swept_ticks * t > config.sweep_budget * config.jobs
        if not math.isfinite(t):
            budgets[backend] = run_budget
        elif late and backend not in compiled:
            budgets[backend] = min(CUT_BUDGET_S, run_budget)
        else:
            margin_s = BUDGET_MARGIN * ticks * t
            budgets[backend] = round(min(run_budget, max(BUDGET_FLOOR_S, margin_s)), 3)
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
                msg = "closed loop %s: %d runs done (%.1f s into the closed loop)"
                log.info(msg, s, per_scenario, spent)
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
            engine=config.engine,
        )
    return outcome.table, outcome.not_ok


def sweep_plan(costs_s: dict[str, float], worker_s: float, target: int) -> dict[str, int]:
    """Perturbed instances a scenario per backend (docs/sweeps.md, step 3): cheapest first, each
    gets ``target`` while the worker time left buys them, else none. ``worker_s`` [s] over all
    workers; ``costs_s``: a backend's cost of one instance in every swept scenario [s]."""
    plan, left = {}, max(0.0, worker_s)
    for backend in sorted(costs_s, key=lambda b: (costs_s[b], b)):
        cost = max(0.0, costs_s[backend]) * target
        plan[backend] = target if cost <= left else 0
        left -= cost if plan[backend] else 0.0
    return plan


@dataclass
class Draws:
    """A sweep's instances drawn so far, :data:`SAMPLE_CHUNK` at a time, and the time it took [s]."""

    spec: object
    drawn: list = field(default_factory=list)
    seconds: float = 0.0

    def first(self, valid: int) -> list:
        """The first instances, as few as hold ``valid`` valid ones (drawing more if needed)."""
        from ..sweep.spec import sample_instances

        while sum(i.invalid is None for i in self.drawn) < valid:
            t0 = time.perf_counter()
            stop = len(self.drawn) + SAMPLE_CHUNK
            self.drawn += sample_instances(replace(self.spec, samples=stop), len(self.drawn))
            self.seconds += time.perf_counter() - t0
        rows = [k for k, i in enumerate(self.drawn) if i.invalid is None]
        return self.drawn[: rows[valid - 1] + 1] if valid else []

    def cost_per_valid(self) -> float:
        """Time [s] to draw one valid instance, as measured so far."""
        valid = sum(i.invalid is None for i in self.drawn)
        return self.seconds / valid if valid else 0.0


def _draw_ahead(draws: dict[str, Draws], valid: int) -> dict[str, threading.Event]:
    """Draw each scenario's first ``valid`` valid instances in a thread, in order, while the
    workers run the scenarios before it; an event per scenario, set once its instances are
    drawn (all set if a draw fails: the scenario's sweep then draws again, and says why)."""
    ready = {s: threading.Event() for s in draws}

    def draw() -> None:
        try:
            for s, d in draws.items():
                d.first(valid)
                ready[s].set()
        finally:
            for event in ready.values():
                event.set()

    threading.Thread(target=draw, name="qpbench-draw", daemon=True).start()
    return ready


def sweep_specs(config: RunConfig) -> dict:
    """Each scenario's sweep of the run, ``<problems>/sweeps/<name>.toml`` where that file
    exists (its instances as short as ``--duration`` when that is shorter)."""
    from ..sweep.spec import load_sweep

    paths = {s: Path(config.problems) / "sweeps" / f"{s}.toml" for s in config.scenarios}
    specs = {s: load_sweep(p) for s, p in paths.items() if p.is_file()}
    if config.duration is None:
        return specs
    return {
        s: load_sweep(paths[s], duration=_length(sp, config.duration)) for s, sp in specs.items()
    }


def _perturbed(config: RunConfig, folder: Path, phases, table, specs: dict) -> dict:
    """The perturbed runs of the backends ok and real time in every nominal run (the
    candidates), each sweep of ``specs`` in ``folder/<scenario>/``, as many instances as
    :func:`sweep_plan` funds; what was planned and spent, for ``run.json``."""
    from ..backends import plugin_files
    from ..report.recommend import TOLERATED_NOT_OK, least_runs, recommend
    from ..runner import make_executor

    started = time.perf_counter()
    candidates = list(recommend(table).overall.passed)
    target = least_runs(config.min_ok_bound, TOLERATED_NOT_OK)
    about = {"scenarios": list(specs), "candidates": candidates, "budget_s": config.sweep_budget}
    about.update(min_ok_bound=config.min_ok_bound, target_per_scenario=target)
    if not specs or not candidates:
        return about
    with phases.phase("perturbed runs"):
        draws = {s: Draws(spec) for s, spec in specs.items()}
        costs, around_s = _instance_costs(draws, candidates, table)
        # the instances are drawn here, the runs made by the workers: the drawing of the first
        # scenario's target is reserved first (the others are drawn while the workers run)
        sampling_s = target * next(iter(draws.values())).cost_per_valid()
        spent = time.perf_counter() - started
        worker_s = (config.sweep_budget - spent - sampling_s) * config.jobs
        plan = sweep_plan(costs, worker_s, target)
        funded = sum(plan[b] * costs[b] for b in plan)
        about.update(
            instance_cost_s={b: round(c, 4) for b, c in costs.items()},
            run_overhead_s={s: round(c, 4) for s, c in around_s.items()},
            instances_per_scenario=plan,
            predicted_s=round(spent + sampling_s + funded / config.jobs, 1),
        )
        folder.mkdir(parents=True, exist_ok=True)
        ready = _draw_ahead(draws, max(plan.values(), default=0))
        with closing(make_executor("local", config.jobs)) as pool:
            for s, d in draws.items():
                ready[s].wait()
                _sweep_scenario(s, d, plan, folder / s, pool, plugin_files(), config.resume)
    about["wall_time_s"] = round(time.perf_counter() - started, 1)
    log.info(
        "perturbed runs: instances a scenario %s (target %d) in %.1f s (budget %g s)",
        ", ".join(f"{b} {n}" for b, n in plan.items()),
        target,
        about["wall_time_s"],
        config.sweep_budget,
    )
    return about


def _length(spec, most: float | None = None) -> float:
    """An instance's simulated time [s]: the sweep's duration, else its base scenario's; at most
    ``most``."""
    length = float(spec.duration or spec.base_raw["simulation"]["duration"])
    return length if most is None else min(length, most)


def _instance_costs(draws: dict[str, Draws], candidates: list[str], table):
    """Each candidate's cost of one instance in every swept scenario [s], and the cost of a run
    around its loop [s] by scenario, as docs/sweeps.md (step 2) measures them."""
    from .closed_loop import LoopTask, run_row

    runs = table.set_index(["scenario", "backend"])

    def loop_s(s: str, b: str) -> float:
        """The loop's share of an instance of scenario ``s``'s sweep [s]."""
        run = runs.loc[(s, b)]
        per_s = min(run["wall_time_s"], run["tick_time_p99_s"] * run["ticks"]) / run["simulated_s"]
        return float(per_s) * _length(draws[s].spec) if math.isfinite(per_s) else 0.0

    def task(d: Draws) -> LoopTask:  # the first valid instance, as the sweep runs it
        inst, bands = d.first(1)[-1], (d.spec.force_band, d.spec.tracking_band)
        name, text = f"{inst.name}.toml", inst.text
        return LoopTask(name, candidates[0], scenario_text=text, bands=bands, p99_interval=False)

    tasks = {s: task(d) for s, d in draws.items()}
    run_row(next(iter(tasks.values())))  # untimed: the first run's imports and kernels
    around = {}
    for s, t in tasks.items():
        t0 = time.process_time()
        run_row(t)
        around[s] = max(0.0, time.process_time() - t0 - loop_s(s, candidates[0]))
    costs = {b: sum(around[s] + loop_s(s, b) for s in draws) for b in candidates}
    return costs, around


def _sweep_scenario(
    scenario: str, draws: Draws, plan: dict, folder: Path, pool, plugins, resume
) -> None:
    """One scenario's perturbed runs into ``folder``: each backend on the first ``plan[b]`` valid
    instances, the backends with the same count in one sweep (the later adding to its table)."""
    from ..sweep.runner import run_sweep

    counts = sorted({n for n in plan.values() if n > 0}, reverse=True)
    if not counts:  # no backend could afford one: the sweep's folder says it was due
        spec = replace(draws.spec, samples=max(1, len(draws.drawn)))
        run_sweep(spec, [], folder, pool, force=True, instances=[])
    for k, n in enumerate(counts):
        backends = [b for b, m in plan.items() if m == n]
        instances = draws.first(n)
        spec = replace(draws.spec, samples=len(draws.drawn))
        again = resume or k > 0
        log.info("perturbed runs %s: %s, %d instances each", scenario, ", ".join(backends), n)
        kw = dict(force=not again, resume=again, plugins=plugins, instances=instances)
        run_sweep(spec, backends, folder, pool, **kw)


def _manifest(config: RunConfig, bench_scenarios: list[str], table, budgets: dict) -> dict:
    """``run.json``: what was asked, the budgets, which runs were cut or not ok."""
    from ..report.inputs import noise_floor_runs

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
