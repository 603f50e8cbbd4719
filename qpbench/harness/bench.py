"""The per-tick benchmark (``qpbench bench``): every backend on every problem of a set, one row
each (:func:`run_bench`); modes, resuming and the order: docs/architecture.md, "The bench"."""

from __future__ import annotations

import hashlib
import logging
import math
import statistics
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..backends import backend_class
from ..exceptions import InputError, ParamError, check_choice, positive_count, positive_seconds
from ..profiles import Profile, get_profile
from ..selection import parse_list
from ..statuses import FAILURE_STATUSES
from .guard import ISOLATE, IsolatedRunner, LocalRunner, Outcome, wants_worker
from .results import ExistingResults, InflightMarker, ResultsWriter, read_results, row_key

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable

    from ..formats import ProblemRecord, ProblemSet

log = logging.getLogger("qpbench.harness")

#: Seed of the per-problem backend order unless ``--seed`` says otherwise.
DEFAULT_SEED = 0
MODES = ("sequential", "independent")


@dataclass
class BenchConfig:
    """What to run, checked when made: ``profile``: a name or :class:`~qpbench.profiles.Profile`;
    ``repeat``: timed solves per (problem, backend); ``mode``: :data:`MODES`; ``time_limit``: per
    solve [s] (``None``: the profile's); ``isolate``: :data:`ISOLATE`; ``warmup``: discarded
    solves first; ``settings``: of every backend, ``backend_settings`` per backend name;
    ``seed``: of :func:`backend_order`; ``memory_budget``: bytes a solve may need."""

    backends: list[str]
    profile: str | Profile = "default"
    repeat: int = 1
    mode: str = "sequential"
    time_limit: float | None = None
    isolate: str = "auto"
    warmup: bool = True
    settings: dict = field(default_factory=dict)
    backend_settings: dict = field(default_factory=dict)
    seed: int = DEFAULT_SEED
    memory_budget: int | None = None

    def __post_init__(self) -> None:
        check_choice(self.mode, MODES, "mode", "mode")
        check_choice(self.isolate, ISOLATE, "isolation", "isolate")
        positive_count(self.repeat, "repeat")
        if self.time_limit is not None:
            self.time_limit = positive_seconds(self.time_limit, "time-limit")
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParamError(f"seed must be an integer >= 0, got {seed!r}", key="seed")
        parse_list(list(self.backends), "backends")


def record_period(problem_set: ProblemSet) -> float | None:
    """Time [s] between two records of a set dumped by ``qpbench simulate --dump`` (its
    manifest's ``generator``: ``dt`` times the stride ``every``), if known."""
    generator = (getattr(problem_set, "manifest", None) or {}).get("generator") or {}
    try:
        return float(generator["dt"]) * int(generator.get("every", 1))
    except (KeyError, TypeError, ValueError):
        return None


def backend_settings(name: str, config: BenchConfig, problem_set: ProblemSet) -> dict:
    """Settings for backend ``name``: the run's, its own, and an online backend's ``dt``."""
    settings = {**config.settings, **config.backend_settings.get(name, {})}
    if backend_class(name).online and "dt" not in settings:
        period = record_period(problem_set)
        if period is not None:
            settings["dt"] = period
    return settings


def sequences(records: list[ProblemRecord], mode: str) -> list[list[int]]:
    """Indices of ``records`` in sequences: one per scenario sorted by tick, or per record."""
    if mode == "independent":
        return [[i] for i in range(len(records))]
    groups: dict[object, list[int]] = {}
    for i, rec in enumerate(records):
        key = ("scenario", rec.scenario) if rec.scenario is not None else ("single", i)
        groups.setdefault(key, []).append(i)
    return [
        sorted(idx, key=lambda i: (records[i].tick is None, records[i].tick or 0))
        for idx in groups.values()
    ]


def _check_existing(existing: ExistingResults, path: Path, mode: str, sha, seed: int) -> None:
    """A resumed file's rows must be of this run's mode, seed and problem set."""
    for row in existing.rows:
        if row["mode"] != mode:
            key, why = "mode", f"holds rows of mode '{row['mode']}', this run is '{mode}'; "
        elif row["order_seed"] != str(seed):
            key, seeded = "order_seed", row["order_seed"]
            why = f"holds rows ordered with seed {seeded or 'none'}, this run's is {seed}; "
            why += f"resume with --seed {seeded} or "
        elif sha and row["problem_set_sha256"] and row["problem_set_sha256"] != sha:
            key, why = "problem_set_sha256", "holds rows of another problem set (SHA-256 differs); "
        else:
            continue
        raise InputError(why + "use --force to start again", path=path, key=key)


def skipped_solves(
    records: list[ProblemRecord], backends: list[str], budget: int
) -> tuple[dict, dict]:
    """``(skips, notes)``: why ``(record index, backend)`` is not solved; a record's warning."""
    from ..formats.convexity import assess_convexity
    from ..memory import skip_reason

    skips, notes = {}, {}
    for i, record in enumerate(records):
        if record.convexity is None:
            record.convexity = assess_convexity(record.problem.P)
        reason = record.convexity.skip_reason
        if record.convexity.warning:
            notes[i] = f"warning: {record.convexity.warning}"
            log.warning("%s: %s", record.name, record.convexity.warning)
        for name in backends:
            why = reason or skip_reason(record.problem, backend_class(name).sparse, budget)
            if why:
                skips[(i, name)] = why
    return skips, notes


def backend_order(problem: str, backends: Iterable[str], seed: int = DEFAULT_SEED) -> list[str]:
    """The order in which ``backends`` solve ``problem``: a permutation of the sorted names by
    ``numpy.random.default_rng([seed, *SHA-256(problem name) as 4 words])``."""
    digest = hashlib.sha256(str(problem).encode("utf-8")).digest()
    words = [int.from_bytes(digest[i : i + 8], "little") for i in range(0, 32, 8)]
    names = sorted(backends)
    perm = np.random.default_rng([int(seed), *words]).permutation(len(names))
    return [names[i] for i in perm]


def _structure(problem) -> tuple[bool, ...]:
    """Which parts a problem has (equalities, inequalities, bounds) and whether ``P`` is sparse."""
    import scipy.sparse as spa

    return (
        problem.A is not None,
        problem.G is not None,
        problem.lb is not None or problem.ub is not None,
        spa.issparse(problem.P),
    )


def _warmup_problems(records, seqs, skipped=frozenset()) -> list:
    """The first problem of each structure, in run order, not ``skipped``."""
    out, seen = [], set()
    for i in (i for seq in seqs for i in seq):
        if i in skipped:
            continue
        key = _structure(records[i].problem)
        if key not in seen:
            seen.add(key)
            out.append(records[i].problem)
    return out


class _BenchRun:
    """One run of :func:`run_bench`: made, it has made every check that can fail on user input,
    before ``out`` is created or changed; ``learned``: backends seen to crash in this process."""

    def __init__(
        self,
        problem_set: ProblemSet,
        config: BenchConfig,
        out: Path,
        force: bool,
        resume: bool,
        make_parent: bool = True,
    ):
        from ..atomic import check_output
        from ..backends import get_backend
        from ..formats import content_sha256
        from ..memory import resolve_budget

        check_output(out, force=force, resume=resume, make_parent=make_parent)
        self.config, self.out = config, out
        profile = get_profile(config.profile)
        self.profile = profile.with_time_limit(float(config.time_limit or profile.time_limit))
        self.records = records = list(problem_set.records)
        if not records:
            raise InputError("problem set is empty", path=getattr(problem_set, "path", None))
        names = [r.name for r in records]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            why = f"problem name '{dup}' appears twice; rows are keyed by name"
            raise InputError(why, path=problem_set.path)
        self.seqs = sequences(records, config.mode)
        self.settings = {
            name: backend_settings(name, config, problem_set) for name in config.backends
        }
        self.instances = {
            name: get_backend(name, self.profile, **self.settings[name]) for name in config.backends
        }
        self.versions = {name: type(b).version() for name, b in self.instances.items()}
        self.budget = resolve_budget(None) if config.memory_budget is None else config.memory_budget
        self.skips, self.notes = skipped_solves(records, config.backends, self.budget)
        self.sha = content_sha256(problem_set)
        self.resuming = resume and out.exists() and not force
        self.existing = ExistingResults([])
        self.marker = InflightMarker(out)
        self.learned: list[str] = []
        if self.resuming:
            self.existing = read_results(out, repair=False)
            _check_existing(self.existing, out, config.mode, self.sha, int(config.seed))
            self._learn_from_crash()

    def _learn_from_crash(self) -> None:
        """A backend that died in this process while solving goes to a worker from now on."""
        self.learned, inflight, crash = self.marker.read()
        done_keys = {row_key(r) for r in self.existing.rows}
        if not (inflight and crash and inflight not in done_keys and len(inflight) == 3):
            return
        suspect = inflight[1]
        if suspect in self.instances and suspect not in self.learned:
            self.learned.append(suspect)
            then = "it runs in a worker process from now on"
            if self.config.isolate != "auto":
                then = "use --isolate auto or always to isolate it"
            msg = "the previous run died while %s was solving %s in this process (%s); %s"
            log.warning(msg, suspect, inflight[0], crash.splitlines()[0], then)

    def start(self, problem_set: ProblemSet, references, force: bool) -> None:
        """References, warm-up, then ``out`` created or repaired (the run's first write)."""
        from ..jit import warmup_logged

        config, out = self.config, self.out
        references = self._references_for(problem_set, references)
        log.info("%d problems; backends: %s", len(problem_set), ", ".join(config.backends))
        warmup_logged(log, config.backends, loop=False)  # no compile inside a timed solve
        if self.resuming:
            self.existing = read_results(out, repair=True)
        elif force and out.exists():
            out.unlink()
            self.marker.path.unlink(missing_ok=True)
        self.references, self.done = references, {row_key(r): r for r in self.existing.rows}
        self.sequential = config.mode == "sequential"
        self.pname = self.profile.name
        self.runners = {name: self._runner(name) for name in config.backends}
        self.summary = BenchSummary(
            isolated=[n for n in config.backends if self.runners[n].isolated], seed=int(config.seed)
        )
        left = {
            name: [(r.name, name, self.pname) not in self.done for r in self.records]
            for name in config.backends
        }
        # per backend and sequence: keys still to run (to know when replay is needed)
        self.todo = {name: [any(left[name][i] for i in seq) for seq in self.seqs] for name in left}
        self.total_todo = sum(sum(v) for v in left.values())
        self.writer = ResultsWriter(out, new=not (self.resuming and out.exists()))
        self.overheads: list[float] = []
        self.bar = None

    def _references_for(
        self, problem_set: ProblemSet, references: list | Callable[[ProblemSet], list] | None
    ) -> list:
        """One reference per record: ``references`` as given, or computed by it (a function of a
        problem set; ``None``: :func:`qpbench.reference.reference_solutions`) for the records some
        backend solves within the memory budget."""
        from ..memory import sparse_solver_bytes
        from ..reference import ReferenceSolution, reference_solutions

        if references is None or callable(references):
            compute = references or reference_solutions
            wanted = [
                i
                for i, r in enumerate(self.records)
                if any((i, name) not in self.skips for name in self.settings)
                and sparse_solver_bytes(r.problem) <= self.budget
            ]
            subset = replace(problem_set, records=[self.records[i] for i in wanted])
            computed = dict(zip(wanted, compute(subset))) if wanted else {}
            references = [
                computed[i] if i in computed else ReferenceSolution("unknown", name=r.name)
                for i, r in enumerate(self.records)
            ]
        if len(references) != len(self.records):
            raise InputError(
                f"{len(references)} reference solutions for {len(self.records)} problems",
                path=problem_set.path,
            )
        return references

    def _runner(self, name: str, isolate: bool = False):
        limit, repeat = self.profile.time_limit, self.config.repeat
        if isolate or wants_worker(self.config.isolate, name, self.learned):
            settings = self.settings[name]
            return IsolatedRunner(name, self.profile, settings, limit, self.sequential, repeat)
        return LocalRunner(self.instances[name], limit, self.sequential, repeat)

    def run(self, progress: bool | str) -> None:
        """Warm up, then every sequence; the output and the workers are closed whatever happens."""
        catch_faults = any(not r.isolated for r in self.runners.values())
        self.marker.open(self.learned, catch_faults=catch_faults)
        if progress == "log" and self.total_todo:
            self.bar = LogBar(self.total_todo, self.writer.path.name)
        elif progress and self.total_todo:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total_todo, unit="solve", desc="bench", leave=False)
        try:
            if self.config.warmup:
                self._warmup()
            for s, seq in enumerate(self.seqs):
                self._sequence(s, seq)
            self.marker.remove()
        finally:
            self.writer.close()
            self.marker.close()
            if self.bar is not None:
                self.bar.close()
            for runner in self.runners.values():
                runner.close()

    def _warmup(self) -> None:
        for name, runner in self.runners.items():
            if any(self.todo[name]):
                skipped = {i for i, b in self.skips if b == name}
                self.marker.mark(("warmup", name, self.pname))
                for problem in _warmup_problems(self.records, self.seqs, skipped):
                    runner.warmup(problem)

    def _sequence(self, s: int, seq: list[int]) -> None:
        """One sequence: each problem solved by every backend with work left in it."""
        active = [name for name in self.config.backends if self.todo[name][s]]
        if not active:
            return
        needs_reset = dict.fromkeys(active, False)
        if self.sequential:
            for name in active:
                self.runners[name].reset()
        for i in seq:
            record = self.records[i]
            solved = []
            order = backend_order(record.name, self.config.backends, self.config.seed)
            for position, name in enumerate(order):
                if not self.todo[name][s]:
                    continue
                key = (record.name, name, self.pname)
                skip = self.skips.get((i, name))
                if key in self.done:
                    if self.sequential and skip is None:
                        self._replay(name, record, self.done[key]["status"], needs_reset)
                elif skip is not None:  # never handed to the backend; its state is untouched
                    solved.append((position, name, Outcome("skipped", error=skip)))
                else:
                    solved.append((position, name, self._solve(name, record, needs_reset)))
            self._write_rows(i, solved)

    def _replay(self, name: str, record, status: str, needs_reset: dict) -> None:
        """Restore the state the original run had after ``record`` (resume)."""
        runner = self.runners[name]
        if status in FAILURE_STATUSES:
            needs_reset[name] = True
            return
        if needs_reset[name]:
            runner.reset()
            needs_reset[name] = False
        self.marker.mark((f"replay {record.name}", name, self.pname))
        if runner.replay(record.problem) in FAILURE_STATUSES:
            log.warning("%s: replay of %s failed; state reset", name, record.name)
            needs_reset[name] = True

    def _solve(self, name: str, record, needs_reset: dict):
        """One timed (repeated) solve; a backend that overran in this process moves to a worker
        (a solve in this process is never interrupted; a worker is killed at its deadline)."""
        self.marker.mark((record.name, name, self.pname))
        runner = self.runners[name]
        outcome = runner.solve(
            record.problem, repeat=self.config.repeat, reset_before=needs_reset[name]
        )
        needs_reset[name] = self.sequential and outcome.status in FAILURE_STATUSES
        if outcome.status == "time_limit" and not runner.isolated and self.config.isolate == "auto":
            msg = "%s overran its time limit on %s in this process; it runs in a worker process from now on"
            log.warning(msg, name, record.name)
            runner.close()
            self.runners[name] = self._runner(name, isolate=True)
            self.learned.append(name)
            self.marker.isolate = list(self.learned)
            self.summary.isolated.append(name)
            needs_reset[name] = self.sequential
        return outcome

    def _row(self, i: int, backend: str, outcome: Outcome, position: int) -> dict:
        """The CSV row of ``backend``'s ``outcome`` on record ``i``."""
        from ..formats.records import box_bounds
        from ..metrics import evaluate, metric_columns

        record, profile = self.records[i], self.profile
        kept, status = outcome.solution, outcome.status
        if kept is not None:
            kept.found = status == "optimal"
        sol = None if status == "invalid" else kept
        metrics = evaluate(record, sol, self.references[i], profile.tolerance)
        times = outcome.wall_times_s
        error = outcome.error if status != "optimal" or outcome.error else None
        if i in self.notes and status != "skipped":
            error = "; ".join(filter(None, [self.notes[i], error]))
        return {
            "problem": record.name,
            **{k: getattr(record, k) for k in ("scenario", "tick", "t")},
            "backend": backend,
            "profile": profile.name,
            "mode": self.config.mode,
            "status": status,
            "found": bool(metrics["found"]) and status == "optimal",
            "success": bool(metrics["success"]) and status not in FAILURE_STATUSES,
            **{c: metrics[c] for c in metric_columns()},
            "wall_time_min_s": min(times) if times else None,
            "wall_time_median_s": statistics.median(times) if times else None,
            "solver_time_s": _float(getattr(sol, "solver_time_s", None)),
            "iterations": getattr(kept, "iterations", None),
            "error": error,
            **{k: getattr(outcome, k) for k in ("state_reset", "isolated", "repeat_exact")},
            "position": position,
            "order_seed": int(self.config.seed),
            "repeat": len(times),
            "repeat_note": outcome.repeat_note or None,
            **dict(zip(("n", "m_eq", "m_ineq"), record.sizes)),
            "n_box": box_bounds(record.problem),
            "problem_set_sha256": self.sha or "",
            "backend_version": self.versions.get(backend),
        }

    def _write_rows(self, i: int, solved: list) -> None:
        """Rows once every backend has solved problem ``i``."""
        backends = self.config.backends
        solved = sorted(solved, key=lambda item: backends.index(item[1]))
        batch = [self._row(i, name, outcome, position) for position, name, outcome in solved]
        for row in batch:
            if row["wall_time_min_s"] is not None:
                self.summary.timed_s += row["wall_time_min_s"]
                if row["solver_time_s"] is not None and math.isfinite(row["solver_time_s"]):
                    self.overheads.append(row["wall_time_min_s"] - row["solver_time_s"])
        self.writer.write_rows(batch)
        self.done.update((row_key(row), row) for row in batch)
        self.summary.new_rows += len(batch)
        if self.bar is not None and batch:
            self.bar.update(len(batch))

    def finish(self, started: float) -> BenchSummary:
        """The summary over every row of this run's keys (resumed and new)."""
        summary, pname = self.summary, self.pname
        wanted = {(r.name, b, pname) for r in self.records for b in self.config.backends}
        summary.backends = {name: BackendStats() for name in self.config.backends}
        for key, row in self.done.items():
            if key in wanted:
                summary.backends[key[1]].add(row)
        if self.overheads:
            summary.overhead_median_s = statistics.median(self.overheads)
            summary.overhead_rows = len(self.overheads)
        summary.elapsed_s = time.perf_counter() - started
        return summary


@dataclass
class BackendStats:
    """One backend's rows (a line of the closing table): ``times_s``: ``wall_time_min_s`` [s];
    ``failures``: failed solves by status; ``isolated``: rows solved in a worker."""

    rows: int = 0
    successes: int = 0
    times_s: list = field(default_factory=list)
    violations: list = field(default_factory=list)
    failures: dict = field(default_factory=dict)
    isolated: int = 0

    @property
    def n_failures(self) -> int:
        return sum(self.failures.values())

    def add(self, row: dict) -> None:
        """Count one row (a new row's values or a resumed row's strings)."""
        self.rows += 1
        self.successes += _truth(row.get("success"))
        self.isolated += _truth(row.get("isolated"))
        t = _float(row.get("wall_time_min_s"))
        if t is not None and math.isfinite(t):
            self.times_s.append(t)
        v = _float(row.get("constraint_violation"))
        if v is not None and not math.isnan(v):
            self.violations.append(v)
        # a failed solve: a harness failure status, or not optimal where the reference is
        status, reference = str(row.get("status")), row.get("reference_status")
        if status in FAILURE_STATUSES or (reference == "optimal" and status != "optimal"):
            if status != "skipped":
                self.failures[status] = self.failures.get(status, 0) + 1


@dataclass
class BenchSummary:
    """What a bench run did: each backend's :class:`BackendStats` over this run's keys;
    ``elapsed_s`` [s]; ``timed_s``: sum of the new rows' ``wall_time_min_s`` [s];
    ``overhead_median_s``: median of ``wall_time_min_s - solver_time_s`` [s] over the new rows."""

    new_rows: int = 0
    backends: dict = field(default_factory=dict)
    elapsed_s: float = 0.0
    timed_s: float = 0.0
    overhead_median_s: float = math.nan
    overhead_rows: int = 0
    isolated: list = field(default_factory=list)
    seed: int = DEFAULT_SEED

    @property
    def rows(self) -> int:
        return sum(s.rows for s in self.backends.values())

    @property
    def failures(self) -> int:
        """Rows counted as failed solves."""
        return sum(s.n_failures for s in self.backends.values())

    def line(self) -> str:
        """The closing line: rows, failed and unsuccessful solves by backend, times."""

        def counted(label: str, counts: dict) -> str:
            counts = {b: n for b, n in counts.items() if n}
            each = ", ".join(f"{b} {n}" for b, n in counts.items())
            return f"{sum(counts.values())} {label}" + (f" ({each})" if counts else "")

        failed = counted("failed solves", {b: s.n_failures for b, s in self.backends.items()})
        unsuccessful = {b: s.rows - s.successes for b, s in self.backends.items()}
        text = (
            f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s; {failed}; "
            f"{counted('without success', unsuccessful)}; "
            f"timed solves {self.timed_s:.3f} s; backend order seed {self.seed}"
        )
        if self.overhead_rows:
            text += (
                f"; harness overhead (wall - solver-reported time) median "
                f"{self.overhead_median_s * 1e6:.1f} us over {self.overhead_rows} solves"
            )
        if self.isolated:
            text += f"; isolated: {', '.join(self.isolated)}"
        return text

    def table(self) -> str:
        """Per backend: rows, success %, time p50/p99 [us], max constraint violation (problem
        units), failures by status; ``*`` marks a backend solved in a worker process."""
        from ..report.markdown_table import aligned

        lines = [["backend", "rows", "success %", "time p50 (us)", "time p99 (us)"]]
        lines[0] += ["max violation", "failures"]
        for name, st in self.backends.items():
            times = np.asarray(st.times_s, dtype=float)
            fails = ", ".join(f"{k} {v}" for k, v in sorted(st.failures.items())) or "0"
            lines.append(
                [
                    name + (" *" if st.isolated else ""),
                    str(st.rows),
                    f"{100.0 * st.successes / st.rows:.1f}" if st.rows else "-",
                    *(
                        f"{np.percentile(times, q) * 1e6:.1f}" if times.size else "-"
                        for q in (50, 99)
                    ),
                    f"{max(st.violations):.3g}" if st.violations else "-",
                    fails if not st.n_failures else f"{st.n_failures} ({fails})",
                ]
            )
        out = aligned(lines, free_last=True)
        if any(st.isolated for st in self.backends.values()):
            out += "\n* some or all rows solved in a worker process (times taken inside it)"
        return out


def _truth(value) -> bool:
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1")
    return bool(value)


def _float(value) -> float | None:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


class LogBar:
    """Off a terminal, the bench's progress bar as log lines, at most one per ``every_s`` [s]."""

    def __init__(self, total: int, name: str, every_s: float = 10.0):
        self.total, self.name, self.every_s, self.n = total, name, every_s, 0
        self.started = self.last = time.monotonic()

    def update(self, n: int) -> None:
        self.n += n
        now = time.monotonic()
        if now - self.last >= self.every_s and self.n < self.total:
            self.last = now
            spent = now - self.started
            left = spent * (self.total - self.n) / self.n
            msg = "bench %s: %d/%d solves in %.0f s, about %.0f s left"
            log.info(msg, self.name, self.n, self.total, spent, left)

    def close(self) -> None:
        pass


def run_bench(
    problem_set: ProblemSet,
    config: BenchConfig,
    out: str | Path,
    *,
    force: bool = False,
    resume: bool = False,
    references: list | None = None,
    progress: bool | str = False,
    make_parent: bool = True,
) -> BenchSummary:
    """Benchmark ``config.backends`` on ``problem_set``; rows to ``out``. ``force``: start ``out``
    again; ``resume``: run only the keys it lacks; ``references``: one per record, or a function
    of the set returning them; ``progress``: a bar on stderr (``"log"``: :class:`LogBar`);
    ``make_parent``: create ``out``'s folder."""
    started = time.perf_counter()
    bench_run = _BenchRun(problem_set, config, Path(out), force, resume, make_parent)
    bench_run.start(problem_set, references, force)
    bench_run.run(progress)
    return bench_run.finish(started)
