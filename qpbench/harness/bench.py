"""The per-tick benchmark: every backend on every problem of a set, one row each.

:func:`run_bench` walks the problems in sequence order, problem by problem,
and solves each with every backend (a :class:`~qpbench.harness.guard.LocalRunner`
in this process or an :class:`~qpbench.harness.isolation.IsolatedRunner` in a
worker). The rows of a problem are appended to the CSV and ``fsync``-ed before
the next problem starts.

Sequences (``mode="sequential"``): problems of the same ``scenario`` form one
sequence, in tick order (file order breaks ties); a problem without a scenario
is a sequence of its own. Each backend's state is carried along a sequence
(the way a controller calls its solver tick after tick) and reset between
sequences. After a failure that leaves the state suspect (``error``,
``time_limit``, ``invalid``, ``crashed``) the backend is reset and the next
row says ``state_reset = True``. ``mode="independent"`` resets before every
problem.

Order of the backends: each problem is solved by every backend in an order
drawn for that problem (:func:`backend_order`: a permutation of the sorted
backend names from a generator seeded with ``(seed, SHA-256 of the problem
name)``). A backend that ran first on one problem runs later on another, so
the cold caches the harness leaves between two problems (metrics, CSV write,
``fsync``) do not always fall on the same backend. The rows record the
``position`` (0 = first) and the ``order_seed``; the order depends only on the
seed, the problem's name and the set of backends, so a resumed run solves in
the order the interrupted one did. All backends of a problem are solved before
any of its rows is made (metrics and references are outside the sequence of
solves).

Resuming (``resume=True``): rows already in the CSV are kept and their keys
``(problem, backend, profile)`` skipped. In sequential mode a backend that
still has problems left in a sequence is brought back to the state it had by
replaying, untimed and unrecorded, the earlier problems of that sequence,
following the recorded statuses (a recorded failure means "reset here", as the
original run did). Deterministic backends then produce the same rows as an
uninterrupted run.
"""

from __future__ import annotations

import logging
import math
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..backends import backend_class
from ..exceptions import InputError, ParamError
from ..profiles import Profile, get_profile
from ..statuses import FAILURE_STATUSES
from .guard import LocalRunner
from .isolation import IsolatedRunner
from .results import (
    ExistingResults,
    InflightMarker,
    ResultsWriter,
    read_results,
    row_key,
)

log = logging.getLogger("qpbench.harness")

MODES = ("sequential", "independent")
#: Seed of the per-problem backend order unless ``--seed`` says otherwise.
DEFAULT_SEED = 0
ISOLATE = ("auto", "always", "never")


@dataclass
class BenchConfig:
    """What to run.

    Attributes:
        backends: Backend names.
        profile: Profile name or :class:`~qpbench.profiles.Profile`.
        repeat: Timed solves per (problem, backend); the row has their min and median.
        mode: ``sequential`` or ``independent``.
        time_limit: Per-solve limit in [s]; ``None`` = the profile's.
        isolate: ``auto`` (only backends marked ``risky`` or seen to crash in
            this process), ``always`` or ``never``.
        warmup: Discarded solves per backend before the first timed one: the
            first problem, and the first of each other structure (parts present).
        settings: Extra solver settings passed to every backend.
        backend_settings: Extra settings per backend name (over ``settings``).
        seed: Seed of the per-problem backend order (:func:`backend_order`).
    """

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

    def validate(self) -> None:
        if self.mode not in MODES:
            raise ParamError(f"unknown mode '{self.mode}' (choose from {', '.join(MODES)})", key="mode")
        if self.isolate not in ISOLATE:
            raise ParamError(f"unknown isolation '{self.isolate}' (choose from {', '.join(ISOLATE)})", key="isolate")
        if int(self.repeat) < 1:
            raise ParamError(f"repeat must be >= 1, got {self.repeat}", key="repeat")
        if self.time_limit is not None and not (self.time_limit > 0 and math.isfinite(self.time_limit)):
            raise ParamError(f"time limit must be a positive number of seconds, got {self.time_limit}", key="time-limit")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ParamError(f"seed must be an integer >= 0, got {self.seed!r}", key="seed")
        if not self.backends:
            raise ParamError("no backend to run", key="backends")
        if len(set(self.backends)) != len(self.backends):
            raise ParamError(f"backend listed twice in {','.join(self.backends)}", key="backends")


@dataclass
class BackendStats:
    """One backend's rows in a bench run (a line of the closing table).

    Attributes:
        rows: Rows of the backend.
        successes: Rows with ``success`` true.
        times_s: ``wall_time_min_s`` of the rows that have one, in [s].
        violations: ``constraint_violation`` of the rows that have one (an ``x``).
        failures: Failed solves (:func:`is_failure`) by status.
        isolated: Rows solved in a worker process.
    """

    rows: int = 0
    successes: int = 0
    times_s: list = field(default_factory=list)
    violations: list = field(default_factory=list)
    failures: dict = field(default_factory=dict)
    isolated: int = 0

    @property
    def n_failures(self) -> int:
        return sum(self.failures.values())

    @property
    def unsuccessful(self) -> int:
        return self.rows - self.successes

    def add(self, row: dict) -> None:
        """Count one row (a new row's values or a resumed row's strings)."""
        self.rows += 1
        if _truth(row.get("success")):
            self.successes += 1
        if _truth(row.get("isolated")):
            self.isolated += 1
        t = _float(row.get("wall_time_min_s"))
        if t is not None and math.isfinite(t):
            self.times_s.append(t)
        v = _float(row.get("constraint_violation"))
        if v is not None and not math.isnan(v):
            self.violations.append(v)
        status = str(row.get("status"))
        if is_failure(status, row.get("reference_status") or None):
            self.failures[status] = self.failures.get(status, 0) + 1


@dataclass
class BenchSummary:
    """What a bench run did (the data of the closing line and table).

    Attributes:
        rows: Rows of this run's keys in the CSV (resumed and new).
        new_rows: Rows written by this invocation.
        failures: Rows counted as failed solves (see :func:`is_failure`).
        statuses: Count of each status over ``rows``.
        backends: Per backend (in the run's order), its :class:`BackendStats`.
        elapsed_s: Duration of this invocation in [s].
        timed_s: Sum of the reported wall times (min over repeats) of the new rows in [s].
        overhead_median_s: Median over new rows of ``wall_time_min_s - solver_time_s``
            (our timed region minus what the solver reports), NaN if no backend reports a time.
        overhead_rows: Rows with both times.
        isolated: Backends that ran in a worker process.
        seed: Seed of the backend order.
    """

    rows: int = 0
    new_rows: int = 0
    failures: int = 0
    statuses: dict = field(default_factory=dict)
    backends: dict = field(default_factory=dict)
    elapsed_s: float = 0.0
    timed_s: float = 0.0
    overhead_median_s: float = math.nan
    overhead_rows: int = 0
    isolated: list = field(default_factory=list)
    seed: int = DEFAULT_SEED

    @property
    def exit_code(self) -> int:
        return 1 if self.failures else 0

    @property
    def failures_by_backend(self) -> dict:
        """Failed solves per backend (only backends with some)."""
        return {b: s.n_failures for b, s in self.backends.items() if s.n_failures}

    @property
    def unsuccessful_by_backend(self) -> dict:
        """Rows without ``success`` per backend (only backends with some)."""
        return {b: s.unsuccessful for b, s in self.backends.items() if s.unsuccessful}

    def line(self) -> str:
        """The closing line: rows, failed and unsuccessful solves by backend, times."""

        def by_backend(counts: dict) -> str:
            return " (" + ", ".join(f"{b} {n}" for b, n in counts.items()) + ")" if counts else ""

        unsuccessful = self.unsuccessful_by_backend
        text = (
            f"{self.rows} rows ({self.new_rows} new) in {self.elapsed_s:.1f} s; "
            f"{self.failures} failed solves{by_backend(self.failures_by_backend)}; "
            f"{sum(unsuccessful.values())} without success{by_backend(unsuccessful)}; "
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
        """Per backend: rows, success %, time p50/p99, max constraint violation, failures by status.

        Plain text with aligned columns; times in [us] (``wall_time_min_s``),
        violation in the problem's units over the rows with an ``x``; a
        backend solved in a worker process (some rows) is marked ``*``.
        """
        header = ["backend", "rows", "success %", "time p50 (us)", "time p99 (us)", "max violation", "failures"]
        lines = [header]
        for name, st in self.backends.items():
            times = np.asarray(st.times_s, dtype=float)
            viol = np.asarray(st.violations, dtype=float)
            fails = ", ".join(f"{k} {v}" for k, v in sorted(st.failures.items())) or "0"
            lines.append([
                name + (" *" if st.isolated else ""),
                str(st.rows),
                f"{100.0 * st.successes / st.rows:.1f}" if st.rows else "-",
                f"{np.percentile(times, 50) * 1e6:.1f}" if times.size else "-",
                f"{np.percentile(times, 99) * 1e6:.1f}" if times.size else "-",
                f"{viol.max():.3g}" if viol.size else "-",
                fails if not st.n_failures else f"{st.n_failures} ({fails})",
            ])
        widths = [max(len(r[j]) for r in lines) for j in range(len(header))]
        out = []
        for r in lines:
            cells = [r[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(r[1:-1], widths[1:-1])] + [r[-1]]
            out.append("  ".join(cells).rstrip())
        if any(st.isolated for st in self.backends.values()):
            out.append("* some or all rows solved in a worker process (times taken inside it)")
        return "\n".join(out)


def _truth(value) -> bool:
    """A boolean cell: ``True`` / ``"True"`` (a resumed row) is true."""
    if isinstance(value, str):
        return value.strip().lower() in ("true", "1")
    return bool(value)


def backend_order(problem: str, backends, seed: int = DEFAULT_SEED) -> list[str]:
    """The order in which ``backends`` solve ``problem``: a seeded permutation.

    The permutation of the sorted names is drawn by
    ``numpy.random.default_rng([seed, *SHA-256(problem name) as 4 words])``:
    it depends on the seed, the problem's name and the set of backends only
    (not on the order given, nor on what ran before), so a resumed run
    repeats it.
    """
    import hashlib

    digest = hashlib.sha256(str(problem).encode("utf-8")).digest()
    words = [int.from_bytes(digest[i : i + 8], "little") for i in range(0, 32, 8)]
    names = sorted(backends)
    perm = np.random.default_rng([int(seed), *words]).permutation(len(names))
    return [names[i] for i in perm]


def record_period(problem_set) -> float | None:
    """Time in [s] between two consecutive records of a dumped sequence, if known.

    A set dumped by ``qpbench simulate --dump`` records its control period
    ``dt`` and the stride ``every`` in its manifest's ``generator``.
    """
    generator = (getattr(problem_set, "manifest", None) or {}).get("generator") or {}
    try:
        return float(generator["dt"]) * int(generator.get("every", 1))
    except (KeyError, TypeError, ValueError):
        return None


def backend_settings(name: str, config: BenchConfig, problem_set) -> dict:
    """Settings for backend ``name``: the run's, its own, plus ``dt`` for an online backend.

    An online backend (the ``rnn`` network) integrates for ``dt`` per call:
    replaying a set that keeps every K-th tick, that is K control periods, the
    time the controller's state evolves between two records.
    """
    settings = {**config.settings, **config.backend_settings.get(name, {})}
    if backend_class(name).online and "dt" not in settings:
        period = record_period(problem_set)
        if period is not None:
            settings["dt"] = period
    return settings


def is_failure(status: str, reference_status: str | None) -> bool:
    """A failed solve: a harness failure status, or not ``optimal`` where the reference is."""
    return status in FAILURE_STATUSES or (reference_status == "optimal" and status != "optimal")


def sequences(records, mode: str) -> list[list[int]]:
    """Indices of ``records`` grouped into sequences, each in tick order.

    Sequential: one sequence per scenario (first-appearance order), sorted by
    tick (stable); records without a scenario are one-problem sequences.
    Independent: one sequence per record, in file order.
    """
    if mode == "independent":
        return [[i] for i in range(len(records))]
    groups: dict[object, list[int]] = {}
    order: list[object] = []
    for i, rec in enumerate(records):
        key = ("scenario", rec.scenario) if rec.scenario is not None else ("single", i)
        if key not in groups:
            groups[key] = []
            order.append(key)
        groups[key].append(i)
    out = []
    for key in order:
        idx = groups[key]
        idx.sort(key=lambda i: (records[i].tick is None, records[i].tick if records[i].tick is not None else 0))
        out.append(idx)
    return out


def _structure(problem) -> tuple[bool, ...]:
    """Which parts a problem has (equalities, inequalities, bounds) and whether ``P`` is sparse."""
    import scipy.sparse as spa

    return (problem.A is not None, problem.G is not None, problem.lb is not None or problem.ub is not None,
            spa.issparse(problem.P))


def _warmup_problems(records, seqs) -> list:
    """The first problem of the run, then the first of each other structure (:func:`_structure`).

    A backend's first solve of a structure may pay one-off costs (a compiled
    kernel specialises on which parts are present): the discarded warm-up
    solves pay them, not a timed one.
    """
    out, seen = [], set()
    for i in [seqs[0][0]] + [i for seq in seqs for i in seq]:
        key = _structure(records[i].problem)
        if key not in seen:
            seen.add(key)
            out.append(records[i].problem)
    return out


def _n_box(problem) -> int:
    n = 0
    if problem.lb is not None:
        n += int(np.isfinite(np.asarray(problem.lb, dtype=float)).sum())
    if problem.ub is not None:
        n += int(np.isfinite(np.asarray(problem.ub, dtype=float)).sum())
    return n


def _float(value) -> float | None:
    if value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


class _RowMaker:
    """Builds a row from a record, a backend outcome and the record's reference."""

    def __init__(self, problem_set, profile: Profile, mode: str, sha: str | None, versions: dict):
        from ..formats import problem_sizes

        self.problem_sizes = problem_sizes
        self.profile = profile
        self.mode = mode
        self.sha = sha or ""
        self.versions = versions

    def __call__(self, record, backend: str, outcome, reference, position: int | None = None,
                 seed: int | None = None) -> dict:
        from ..metrics import evaluate, metric_columns

        sol = outcome.solution
        status = outcome.status
        if sol is not None:
            sol.found = status == "optimal"
            if status == "invalid":
                sol = None
        metrics = evaluate(record, sol, reference, self.profile.tolerance)
        times = outcome.wall_times_s
        n, m_eq, m_ineq = self.problem_sizes(record.problem)
        error = outcome.error if status != "optimal" or outcome.error else None
        return {
            "problem": record.name,
            "scenario": record.scenario,
            "tick": record.tick,
            "t": record.t,
            "backend": backend,
            "profile": self.profile.name,
            "mode": self.mode,
            "status": status,
            "found": bool(metrics["found"]) and status == "optimal",
            "success": bool(metrics["success"]) and status not in FAILURE_STATUSES,
            **{c: metrics[c] for c in metric_columns()},
            "wall_time_min_s": min(times) if times else None,
            "wall_time_median_s": statistics.median(times) if times else None,
            "solver_time_s": _float(getattr(sol, "solver_time_s", None)) if outcome.solution is not None else None,
            "iterations": getattr(outcome.solution, "iterations", None) if outcome.solution is not None else None,
            "error": error,
            "state_reset": outcome.state_reset,
            "isolated": outcome.isolated,
            "position": position,
            "order_seed": seed,
            "repeat": len(times),
            "n": n,
            "m_eq": m_eq,
            "m_ineq": m_ineq,
            "n_box": _n_box(record.problem),
            "problem_set_sha256": self.sha,
            "backend_version": self.versions.get(backend),
        }


def _check_existing(existing: ExistingResults, path: Path, config_mode: str, sha: str | None,
                    seed: int = DEFAULT_SEED) -> None:
    for row in existing.rows:
        if row["mode"] != config_mode:
            raise InputError(
                f"holds rows of mode '{row['mode']}', this run is '{config_mode}'; use --force to start again",
                path=path,
                key="mode",
            )
        if row["order_seed"] != str(seed):
            raise InputError(
                f"holds rows ordered with seed {row['order_seed'] or 'none'}, this run's is {seed}; "
                f"resume with --seed {row['order_seed']} or use --force to start again",
                path=path,
                key="order_seed",
            )
        if sha and row["problem_set_sha256"] and row["problem_set_sha256"] != sha:
            raise InputError(
                "holds rows of another problem set (SHA-256 differs); use --force to start again",
                path=path,
                key="problem_set_sha256",
            )


def run_bench(
    problem_set,
    config: BenchConfig,
    out: str | Path,
    *,
    force: bool = False,
    resume: bool = False,
    references: list | None = None,
    progress: bool = False,
) -> BenchSummary:
    """Benchmark ``config.backends`` on ``problem_set``; write rows to ``out`` (CSV).

    Everything that can fail on user input (backend names, the existing
    output, the problems' names) is checked before ``out`` is created or
    changed.

    Args:
        problem_set: A :class:`~qpbench.formats.ProblemSet` (already loaded and validated).
        config: What to run.
        out: CSV path.
        force: Delete an existing ``out`` and start again.
        resume: Keep the rows of an existing ``out`` and run the missing keys only.
        references: Reference solutions (one per record, ``None`` entries for none), or a function
            of the problem set that returns them; computed (and cached) if ``None``.
        progress: Show a progress bar on stderr.

    Raises:
        OutputExistsError: ``out`` exists and neither ``force`` nor ``resume``.
        ParamError, BackendNotFound, InputError: bad configuration or a foreign ``out``.
    """
    from ..atomic import check_output
    from ..backends import get_backend
    from ..formats import content_sha256

    started = time.perf_counter()
    config.validate()
    out = Path(out)
    check_output(out, force=force, resume=resume, make_parent=True)  # the command checked the user's path
    profile = get_profile(config.profile)
    time_limit = float(config.time_limit) if config.time_limit is not None else float(profile.time_limit)
    run_profile = profile.with_time_limit(time_limit)
    sequential = config.mode == "sequential"
    records = list(problem_set.records)
    if not records:
        raise InputError("problem set is empty", path=getattr(problem_set, "path", None))
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(f"problem name '{dup}' appears twice; rows are keyed by name", path=problem_set.path)

    # Backends: build the in-process ones now (a bad name fails before any write).
    settings = {name: backend_settings(name, config, problem_set) for name in config.backends}
    instances = {name: get_backend(name, run_profile, **settings[name]) for name in config.backends}
    versions = {name: type(b).version() for name, b in instances.items()}

    # Existing output.
    existing = ExistingResults([])
    marker = InflightMarker(InflightMarker.for_output(out))
    learned: list[str] = []
    sha = content_sha256(problem_set)
    resuming = resume and out.exists() and not force
    if resuming:
        existing = read_results(out, repair=False)
        _check_existing(existing, out, config.mode, sha, int(config.seed))
        learned, inflight, crash = marker.read()
        done_keys = {row_key(r) for r in existing.rows}
        if inflight and crash and inflight not in done_keys and len(inflight) == 3:
            suspect = inflight[1]
            if suspect in instances and suspect not in learned:
                learned.append(suspect)
                log.warning(
                    "the previous run died while %s was solving %s in this process (%s); %s",
                    suspect,
                    inflight[0],
                    crash.splitlines()[0],
                    "it runs in a worker process from now on"
                    if config.isolate == "auto"
                    else "use --isolate auto or always to isolate it",
                )

    if references is None:
        from ..reference import reference_solutions

        references = reference_solutions(problem_set)
    elif callable(references):  # computed now that the input is known to be good
        references = references(problem_set)
    if len(references) != len(records):
        raise InputError(f"{len(references)} reference solutions for {len(records)} problems", path=problem_set.path)

    # From here on, the output is created or changed.
    if resuming:
        existing = read_results(out, repair=True)
    elif force and out.exists():
        out.unlink()
        if marker.path.exists():
            marker.path.unlink()
    done = existing.by_key()

    def isolated(name: str) -> bool:
        if config.isolate == "always":
            return True
        if config.isolate == "never":
            return False
        return backend_class(name).risky or name in learned

    runners = {}
    for name in config.backends:
        if isolated(name):
            runners[name] = IsolatedRunner(name, run_profile, settings[name], time_limit, sequential)
        else:
            runners[name] = LocalRunner(instances[name], time_limit, sequential)
    summary = BenchSummary(isolated=[n for n in config.backends if runners[n].isolated], seed=int(config.seed))
    make_row = _RowMaker(problem_set, run_profile, config.mode, sha, versions)
    pname = run_profile.name
    seqs = sequences(records, config.mode)

    # Keys still to run, per backend and sequence (to know when replay is needed).
    todo = {
        name: [any((records[i].name, name, pname) not in done for i in seq) for seq in seqs] for name in config.backends
    }
    total_todo = sum(1 for r in records for b in config.backends if (r.name, b, pname) not in done)

    writer = ResultsWriter(out, new=not (resuming and out.exists()))
    marker.open(learned, catch_faults=any(not r.isolated for r in runners.values()))
    bar = None
    if progress and total_todo:
        from tqdm import tqdm

        bar = tqdm(total=total_todo, unit="solve", desc="bench", leave=False)
    overheads = []
    try:
        if config.warmup:
            firsts = _warmup_problems(records, seqs)
            for name, runner in runners.items():
                if any(todo[name]):
                    marker.mark(("warmup", name, pname))
                    for problem in firsts:
                        runner.warmup(problem)
        for s, seq in enumerate(seqs):
            active = [name for name in config.backends if todo[name][s]]
            if not active:
                continue
            needs_reset = {name: False for name in active}
            if sequential:
                for name in active:
                    runners[name].reset()
            prev = None
            for i in seq:
                record = records[i]
                order = backend_order(record.name, config.backends, config.seed)
                solved = []
                for position, name in enumerate(order):
                    if not todo[name][s]:
                        continue
                    key = (record.name, name, pname)
                    runner = runners[name]
                    if key in done:
                        if sequential:  # replay to restore the state the original run had
                            status = done[key]["status"]
                            if status in FAILURE_STATUSES:
                                needs_reset[name] = True
                            else:
                                if needs_reset[name]:
                                    runner.reset()
                                    needs_reset[name] = False
                                marker.mark((f"replay {record.name}", name, pname))
                                if runner.replay(record.problem) in FAILURE_STATUSES:
                                    log.warning("%s: replay of %s failed; state reset", name, record.name)
                                    needs_reset[name] = True
                        continue
                    marker.mark(key)
                    outcome = runner.solve(
                        record.problem,
                        repeat=config.repeat,
                        reset_before=needs_reset[name],
                        prev_problem=prev,
                    )
                    needs_reset[name] = sequential and outcome.status in FAILURE_STATUSES
                    if outcome.status == "time_limit" and not runner.isolated and config.isolate == "auto":
                        # In this process a solve is never interrupted (an exception raised
                        # into foreign code can break it): a backend that overran once goes
                        # to a worker process, which is killed at its deadline.
                        log.warning(
                            "%s overran its time limit on %s in this process; it runs in a worker process from now on",
                            name,
                            record.name,
                        )
                        runner.close()
                        runners[name] = IsolatedRunner(name, run_profile, settings[name], time_limit, sequential)
                        learned.append(name)
                        marker.isolate = list(learned)
                        summary.isolated.append(name)
                        needs_reset[name] = sequential
                    solved.append((position, name, outcome))
                # rows (metrics against the reference) once every backend has solved the problem
                batch = []
                for position, name, outcome in sorted(solved, key=lambda item: config.backends.index(item[1])):
                    row = make_row(record, name, outcome, references[i], position, int(config.seed))
                    batch.append(row)
                    if row["wall_time_min_s"] is not None:
                        summary.timed_s += row["wall_time_min_s"]
                        if row["solver_time_s"] is not None and math.isfinite(row["solver_time_s"]):
                            overheads.append(row["wall_time_min_s"] - row["solver_time_s"])
                writer.write_rows(batch)
                for row in batch:
                    done[row_key(row)] = row
                summary.new_rows += len(batch)
                if bar is not None and batch:
                    bar.update(len(batch))
                prev = record.problem if sequential else None
        marker.remove()
    finally:
        writer.close()
        marker.close()
        if bar is not None:
            bar.close()
        for runner in runners.values():
            runner.close()

    wanted = {(r.name, b, pname) for r in records for b in config.backends}
    summary.backends = {name: BackendStats() for name in config.backends}
    for key, row in done.items():
        if key not in wanted:
            continue
        summary.rows += 1
        status = str(row["status"])
        summary.statuses[status] = summary.statuses.get(status, 0) + 1
        summary.backends[key[1]].add(row)
        ref = row["reference_status"] or None
        if is_failure(status, ref):
            summary.failures += 1
    if overheads:
        summary.overhead_median_s = statistics.median(overheads)
        summary.overhead_rows = len(overheads)
    summary.elapsed_s = time.perf_counter() - started
    return summary


__all__ = [
    "BackendStats", "BenchConfig", "BenchSummary", "backend_order", "is_failure", "run_bench", "sequences",
]
