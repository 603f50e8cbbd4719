"""The per-tick benchmark: every backend on every problem of a set, one row each.

:func:`run_bench` walks the problems in sequence order (:func:`~.bench_plan.sequences`) and
solves each with every backend, in this process (:class:`~.guard.LocalRunner`) or in a worker
(:class:`~.isolation.IsolatedRunner`); a problem's rows are made once all its solves are done
and appended to the CSV before the next problem starts.

``mode="sequential"``: a backend's state is carried along a sequence (as a controller calls
its solver tick after tick) and reset between sequences and after a failure that leaves it
suspect (:data:`~qpbench.statuses.FAILURE_STATUSES`; the next row says ``state_reset``).
``mode="independent"`` resets before every problem.

The backends solve each problem in an order drawn for it (:func:`backend_order`), so the cold
caches the harness leaves between problems do not always fall on the same backend; rows record
``position`` and ``order_seed``.

Resuming keeps the rows in the CSV and skips their keys. In sequential mode a backend with
problems left in a sequence is brought back to its state by replaying, untimed, the earlier
problems of the sequence, resetting where the recorded statuses say the original run did;
deterministic backends then give the rows of an uninterrupted run.
"""

from __future__ import annotations

import hashlib
import logging
import math
import statistics
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..backends import backend_class
from ..statuses import FAILURE_STATUSES
from .bench_plan import (
    ISOLATE,
    MODES,
    BenchConfig,
    Plan,
    backend_settings,
    make_plan,
    open_output,
    record_period,
    references_for,
    sequences,
)
from .bench_summary import DEFAULT_SEED, BackendStats, BenchSummary, as_float, is_failure
from .guard import LocalRunner, Outcome
from .isolation import IsolatedRunner
from .results import ResultsWriter, row_key

if TYPE_CHECKING:
    from collections.abc import Iterable

    from ..formats import ProblemSet

log = logging.getLogger("qpbench.harness")


def backend_order(problem: str, backends: Iterable[str], seed: int = DEFAULT_SEED) -> list[str]:
    """The order in which ``backends`` solve ``problem``: a permutation of the sorted names by
    ``numpy.random.default_rng([seed, *SHA-256(problem name) as 4 words])``, so it depends on
    the seed, the name and the set of backends only (a resumed run repeats it)."""
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
    """The first problem of the run, then the first of each other structure (:func:`_structure`):
    a compiled kernel specialises on the parts present, and the warm-up pays for that."""
    out, seen = [], set()
    for i in [seqs[0][0]] + [i for seq in seqs for i in seq]:
        if i in skipped:  # a problem the backend does not solve is no warm-up either
            continue
        key = _structure(records[i].problem)
        if key not in seen:
            seen.add(key)
            out.append(records[i].problem)
    return out


def _n_box(problem) -> int:
    """Finite bounds of a problem."""
    return sum(
        int(np.isfinite(np.asarray(b, dtype=float)).sum())
        for b in (problem.lb, problem.ub)
        if b is not None
    )


class _BenchRun:
    """The solving part of :func:`run_bench`: runners, warm-up, sequences, rows."""

    def __init__(self, plan: Plan, config: BenchConfig, references: list, done: dict, out: Path):
        self.plan = plan
        self.config = config
        self.references = references
        self.done = done
        self.sequential = config.mode == "sequential"
        self.pname = plan.profile.name
        self.runners = {name: self._runner(name) for name in config.backends}
        self.summary = BenchSummary(
            isolated=[n for n in config.backends if self.runners[n].isolated], seed=int(config.seed)
        )
        # per backend and sequence: keys still to run (to know when replay is needed)
        self.todo = {
            name: [
                any((plan.records[i].name, name, self.pname) not in done for i in seq)
                for seq in plan.seqs
            ]
            for name in config.backends
        }
        self.total_todo = sum(
            1 for r in plan.records for b in config.backends if (r.name, b, self.pname) not in done
        )
        self.writer = ResultsWriter(out, new=not (plan.resuming and out.exists()))
        self.overheads: list[float] = []
        self.bar = None

    def _worker(self, name: str) -> IsolatedRunner:
        plan, config = self.plan, self.config
        return IsolatedRunner(
            name,
            plan.profile,
            plan.settings[name],
            plan.profile.time_limit,
            self.sequential,
            config.repeat,
        )

    def _runner(self, name: str):
        isolate = self.config.isolate
        if isolate == "always" or (
            isolate == "auto" and (backend_class(name).risky or name in self.plan.learned)
        ):
            return self._worker(name)
        return LocalRunner(
            self.plan.instances[name],
            self.plan.profile.time_limit,
            self.sequential,
            self.config.repeat,
        )

    def run(self, progress: bool | str) -> None:
        """Warm up, then every sequence; the output and the workers are closed whatever happens."""
        self.plan.marker.open(
            self.plan.learned, catch_faults=any(not r.isolated for r in self.runners.values())
        )
        if progress == "log" and self.total_todo:
            self.bar = LogBar(self.total_todo, self.writer.path.name)
        elif progress and self.total_todo:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total_todo, unit="solve", desc="bench", leave=False)
        try:
            if self.config.warmup:
                self._warmup()
            for s, seq in enumerate(self.plan.seqs):
                self._sequence(s, seq)
            self.plan.marker.remove()
        finally:
            self.writer.close()
            self.plan.marker.close()
            if self.bar is not None:
                self.bar.close()
            for runner in self.runners.values():
                runner.close()

    def _warmup(self) -> None:
        for name, runner in self.runners.items():
            if any(self.todo[name]):
                skipped = {i for i, b in self.plan.skips if b == name}
                self.plan.marker.mark(("warmup", name, self.pname))
                for problem in _warmup_problems(self.plan.records, self.plan.seqs, skipped):
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
            record = self.plan.records[i]
            solved = []
            order = backend_order(record.name, self.config.backends, self.config.seed)
            for position, name in enumerate(order):
                if not self.todo[name][s]:
                    continue
                key = (record.name, name, self.pname)
                skip = self.plan.skips.get((i, name))
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
        self.plan.marker.mark((f"replay {record.name}", name, self.pname))
        if runner.replay(record.problem) in FAILURE_STATUSES:
            log.warning("%s: replay of %s failed; state reset", name, record.name)
            needs_reset[name] = True

    def _solve(self, name: str, record, needs_reset: dict):
        """One timed (repeated) solve; a backend that overran in this process moves to a worker."""
        self.plan.marker.mark((record.name, name, self.pname))
        outcome = self.runners[name].solve(
            record.problem, repeat=self.config.repeat, reset_before=needs_reset[name]
        )
        needs_reset[name] = self.sequential and outcome.status in FAILURE_STATUSES
        if (
            outcome.status == "time_limit"
            and not self.runners[name].isolated
            and self.config.isolate == "auto"
        ):
            # a solve in this process is never interrupted; a worker is killed at its deadline
            log.warning(
                "%s overran its time limit on %s in this process; it runs in a worker process from now on",
                name,
                record.name,
            )
            self.runners[name].close()
            self.runners[name] = self._worker(name)
            self.plan.learned.append(name)
            self.plan.marker.isolate = list(self.plan.learned)
            self.summary.isolated.append(name)
            needs_reset[name] = self.sequential
        return outcome

    def _row(self, i: int, backend: str, outcome: Outcome, position: int) -> dict:
        """The CSV row of ``backend``'s ``outcome`` on record ``i``, scored against its reference."""
        from ..formats import problem_sizes
        from ..metrics import evaluate, metric_columns

        record, profile = self.plan.records[i], self.plan.profile
        sol, status = outcome.solution, outcome.status
        if sol is not None:
            sol.found = status == "optimal"
            if status == "invalid":
                sol = None
        metrics = evaluate(record, sol, self.references[i], profile.tolerance)
        times = outcome.wall_times_s
        n, m_eq, m_ineq = problem_sizes(record.problem)
        kept = outcome.solution
        return {
            "problem": record.name,
            "scenario": record.scenario,
            "tick": record.tick,
            "t": record.t,
            "backend": backend,
            "profile": profile.name,
            "mode": self.config.mode,
            "status": status,
            "found": bool(metrics["found"]) and status == "optimal",
            "success": bool(metrics["success"]) and status not in FAILURE_STATUSES,
            **{c: metrics[c] for c in metric_columns()},
            "wall_time_min_s": min(times) if times else None,
            "wall_time_median_s": statistics.median(times) if times else None,
            "solver_time_s": None
            if kept is None
            else as_float(getattr(sol, "solver_time_s", None)),
            "iterations": None if kept is None else getattr(kept, "iterations", None),
            "error": outcome.error if status != "optimal" or outcome.error else None,
            "state_reset": outcome.state_reset,
            "isolated": outcome.isolated,
            "position": position,
            "order_seed": int(self.config.seed),
            "repeat": len(times),
            "repeat_exact": outcome.repeat_exact,
            "repeat_note": outcome.repeat_note or None,
            "n": n,
            "m_eq": m_eq,
            "m_ineq": m_ineq,
            "n_box": _n_box(record.problem),
            "problem_set_sha256": self.plan.sha or "",
            "backend_version": self.plan.versions.get(backend),
        }

    def _write_rows(self, i: int, solved: list) -> None:
        """Rows (metrics against the reference) once every backend has solved problem ``i``."""
        backends = self.config.backends
        batch = []
        for position, name, outcome in sorted(solved, key=lambda item: backends.index(item[1])):
            row = self._row(i, name, outcome, position)
            if i in self.plan.notes and outcome.status != "skipped":
                row["error"] = "; ".join(filter(None, [self.plan.notes[i], row["error"]]))
            batch.append(row)
            if row["wall_time_min_s"] is not None:
                self.summary.timed_s += row["wall_time_min_s"]
                if row["solver_time_s"] is not None and math.isfinite(row["solver_time_s"]):
                    self.overheads.append(row["wall_time_min_s"] - row["solver_time_s"])
        self.writer.write_rows(batch)
        for row in batch:
            self.done[row_key(row)] = row
        self.summary.new_rows += len(batch)
        if self.bar is not None and batch:
            self.bar.update(len(batch))

    def finish(self, started: float) -> BenchSummary:
        """The summary over every row of this run's keys (resumed and new)."""
        summary, pname = self.summary, self.pname
        wanted = {(r.name, b, pname) for r in self.plan.records for b in self.config.backends}
        summary.backends = {name: BackendStats() for name in self.config.backends}
        for key, row in self.done.items():
            if key not in wanted:
                continue
            summary.rows += 1
            summary.backends[key[1]].add(row)
            if is_failure(str(row["status"]), row["reference_status"] or None):
                summary.failures += 1
        if self.overheads:
            summary.overhead_median_s = statistics.median(self.overheads)
            summary.overhead_rows = len(self.overheads)
        summary.elapsed_s = time.perf_counter() - started
        return summary


class LogBar:
    """Off a terminal, the bench's progress bar as log lines: at most one per ``every_s``
    seconds, with the solves done, the time so far and the time left at this pace."""

    def __init__(self, total: int, name: str, every_s: float = 10.0):
        self.total, self.name, self.every_s, self.n = total, name, every_s, 0
        self.started = self.last = time.monotonic()

    def update(self, n: int) -> None:
        self.n += n
        now = time.monotonic()
        if now - self.last >= self.every_s and self.n < self.total:
            self.last = now
            spent = now - self.started
            log.info(
                "bench %s: %d/%d solves in %.0f s, about %.0f s left",
                self.name,
                self.n,
                self.total,
                spent,
                spent * (self.total - self.n) / self.n,
            )

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
) -> BenchSummary:
    """Benchmark ``config.backends`` on ``problem_set`` (loaded and validated); rows to ``out``.

    Everything that can fail on user input is checked before ``out`` is created or changed.
    ``force``: start ``out`` again; ``resume``: run only the keys it lacks. ``references``: one
    per record (``None`` entries for none), or a function of the set returning them; computed
    (and cached) if ``None``. ``progress``: a bar on stderr (``"log"``: :class:`LogBar`).

    Raises:
        OutputExistsError: ``out`` exists and neither ``force`` nor ``resume``.
        ParamError, BackendNotFound, InputError: bad configuration or a foreign ``out``.
    """
    started = time.perf_counter()
    out = Path(out)
    plan = make_plan(problem_set, config, out, force, resume)
    references = references_for(problem_set, plan, references)
    done = open_output(plan, out, force)  # from here on, the output is created or changed
    bench_run = _BenchRun(plan, config, references, done, out)
    bench_run.run(progress)
    return bench_run.finish(started)


__all__ = [
    "DEFAULT_SEED",
    "ISOLATE",
    "MODES",
    "BackendStats",
    "BenchConfig",
    "BenchSummary",
    "backend_order",
    "backend_settings",
    "is_failure",
    "record_period",
    "run_bench",
    "sequences",
]
