"""What a bench run will do, checked before anything is written.

:class:`BenchConfig` says what to run and checks its values; :func:`make_plan` checks it
against the problem set and an existing output (backend names, a resumed file's mode, seed and
set) and returns a :class:`Plan`; :func:`open_output` is the run's first write.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..backends import backend_class
from ..exceptions import InputError, ParamError, positive_seconds
from ..profiles import Profile, get_profile
from .bench_summary import DEFAULT_SEED
from .results import ExistingResults, InflightMarker, read_results, row_key

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..formats import ProblemRecord, ProblemSet

log = logging.getLogger("qpbench.harness")

MODES = ("sequential", "independent")
ISOLATE = ("auto", "always", "never")


@dataclass
class BenchConfig:
    """What to run, checked when made.

    Attributes:
        profile: Profile name or :class:`~qpbench.profiles.Profile`.
        repeat: Timed solves per (problem, backend); the row has their min and median.
        time_limit: Per-solve limit [s]; ``None``: the profile's.
        isolate: ``auto`` (backends marked ``risky`` or seen to crash in this process),
            ``always`` or ``never``.
        warmup: Discarded solves per backend before the first timed one: the first problem,
            and the first of each other structure (parts present).
        settings: Solver settings for every backend; ``backend_settings``: per backend name.
        seed: Seed of the per-problem backend order (:func:`~qpbench.harness.bench.backend_order`).
        memory_budget: Bytes a solve may need (:mod:`qpbench.memory`; ``None``: the default).
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
    memory_budget: int | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParamError(
                f"unknown mode '{self.mode}' (choose from {', '.join(MODES)})", key="mode"
            )
        if self.isolate not in ISOLATE:
            raise ParamError(
                f"unknown isolation '{self.isolate}' (choose from {', '.join(ISOLATE)})",
                key="isolate",
            )
        if int(self.repeat) < 1:
            raise ParamError(f"repeat must be >= 1, got {self.repeat}", key="repeat")
        if self.time_limit is not None:
            self.time_limit = positive_seconds(self.time_limit, "time-limit")
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, (int, np.integer))
            or self.seed < 0
        ):
            raise ParamError(f"seed must be an integer >= 0, got {self.seed!r}", key="seed")
        if not self.backends:
            raise ParamError("no backend to run", key="backends")
        if len(set(self.backends)) != len(self.backends):
            raise ParamError(f"backend listed twice in {','.join(self.backends)}", key="backends")


def record_period(problem_set: ProblemSet) -> float | None:
    """Time [s] between two records of a set dumped by ``qpbench simulate --dump`` (its
    manifest's ``generator``: ``dt`` times the stride ``every``), if known."""
    generator = (getattr(problem_set, "manifest", None) or {}).get("generator") or {}
    try:
        return float(generator["dt"]) * int(generator.get("every", 1))
    except (KeyError, TypeError, ValueError):
        return None


def backend_settings(name: str, config: BenchConfig, problem_set: ProblemSet) -> dict:
    """Settings for backend ``name``: the run's, its own, and for an online backend (``rnn``)
    ``dt`` = the time between two records (:func:`record_period`), which it integrates per call."""
    settings = {**config.settings, **config.backend_settings.get(name, {})}
    if backend_class(name).online and "dt" not in settings:
        period = record_period(problem_set)
        if period is not None:
            settings["dt"] = period
    return settings


def sequences(records: list[ProblemRecord], mode: str) -> list[list[int]]:
    """Indices of ``records`` grouped into sequences.

    Sequential: one per scenario (first-appearance order), sorted by tick (stable); a record
    without a scenario is a sequence of its own. Independent: one per record, in file order.
    """
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
            raise InputError(
                f"holds rows of mode '{row['mode']}', this run is '{mode}'; use --force to start again",
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


@dataclass
class Plan:
    """A checked run before anything is written.

    Attributes:
        seqs: The records' sequences (:func:`sequences`).
        profile: The profile in force, with the run's time limit.
        instances: In-process backend instances (a bad name failed while making them).
        sha: Content SHA-256 of the set.
        resuming: An existing output is continued; ``existing``: its rows.
        learned: Backends known to crash in this process (from the in-flight ``marker``).
        skips: ``(record index, backend) -> reason`` of the solves not made (:func:`skipped_solves`).
        notes: ``record index -> warning`` written in its rows' ``error`` column.
    """

    records: list
    seqs: list
    profile: Profile
    settings: dict
    instances: dict
    versions: dict
    sha: str | None
    resuming: bool
    existing: ExistingResults
    learned: list
    marker: InflightMarker
    skips: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)
    budget: int | None = None


def _check_records(problem_set) -> list:
    records = list(problem_set.records)
    if not records:
        raise InputError("problem set is empty", path=getattr(problem_set, "path", None))
    names = [r.name for r in records]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InputError(
            f"problem name '{dup}' appears twice; rows are keyed by name", path=problem_set.path
        )
    return records


def _learn_from_crash(plan: Plan, config: BenchConfig) -> None:
    """A backend that died in this process while solving (in-flight marker of the interrupted
    run) goes to a worker from now on (under ``--isolate auto``)."""
    learned, inflight, crash = plan.marker.read()
    plan.learned[:] = learned
    done_keys = {row_key(r) for r in plan.existing.rows}
    if not (inflight and crash and inflight not in done_keys and len(inflight) == 3):
        return
    suspect = inflight[1]
    if suspect in plan.instances and suspect not in plan.learned:
        plan.learned.append(suspect)
        log.warning(
            "the previous run died while %s was solving %s in this process (%s); %s",
            suspect,
            inflight[0],
            crash.splitlines()[0],
            "it runs in a worker process from now on"
            if config.isolate == "auto"
            else "use --isolate auto or always to isolate it",
        )


def make_plan(
    problem_set: ProblemSet, config: BenchConfig, out: Path, force: bool, resume: bool
) -> Plan:
    """Every check that can fail on user input, before ``out`` is created or changed."""
    from ..atomic import check_output
    from ..backends import get_backend
    from ..formats import content_sha256

    check_output(out, force=force, resume=resume, make_parent=True)
    profile = get_profile(config.profile)
    run_profile = profile.with_time_limit(
        config.time_limit if config.time_limit is not None else float(profile.time_limit)
    )
    records = _check_records(problem_set)
    settings = {name: backend_settings(name, config, problem_set) for name in config.backends}
    instances = {name: get_backend(name, run_profile, **settings[name]) for name in config.backends}
    skips, notes = skipped_solves(records, config)
    plan = Plan(
        records=records,
        seqs=sequences(records, config.mode),
        profile=run_profile,
        settings=settings,
        instances=instances,
        versions={name: type(b).version() for name, b in instances.items()},
        sha=content_sha256(problem_set),
        resuming=resume and out.exists() and not force,
        existing=ExistingResults([]),
        learned=[],
        marker=InflightMarker(InflightMarker.for_output(out)),
        skips=skips,
        notes=notes,
        budget=config.memory_budget,
    )
    if plan.resuming:
        plan.existing = read_results(out, repair=False)
        _check_existing(plan.existing, out, config.mode, plan.sha, int(config.seed))
        _learn_from_crash(plan, config)
    return plan


def skipped_solves(records: list[ProblemRecord], config: BenchConfig) -> tuple[dict, dict]:
    """``(skips, notes)``: the solves not made and why, and the warnings of the rest.

    A clearly nonconvex problem is skipped by every backend, a slightly indefinite one solved
    with a warning (:mod:`qpbench.formats.convexity`); one too large for a dense-only backend
    or the memory budget is skipped by that backend (:func:`qpbench.memory.skip_reason`).
    """
    from ..formats.convexity import assess_convexity
    from ..memory import resolve_budget, skip_reason

    budget = config.memory_budget if config.memory_budget is not None else resolve_budget(None)
    skips, notes = {}, {}
    for i, record in enumerate(records):
        if record.convexity is None:
            record.convexity = assess_convexity(record.problem.P)
        reason = record.convexity.skip_reason
        if record.convexity.warning:
            notes[i] = f"warning: {record.convexity.warning}"
            log.warning("%s: %s", record.name, record.convexity.warning)
        for name in config.backends:
            why = reason or skip_reason(record.problem, backend_class(name).sparse, budget)
            if why:
                skips[(i, name)] = why
    return skips, notes


def references_for(
    problem_set: ProblemSet, plan: Plan, references: list | Callable[[ProblemSet], list] | None
) -> list:
    """One reference per record: ``references`` as given, or computed by it (a function of a
    problem set; ``None``: :func:`qpbench.reference.reference_solutions`) for the records some
    backend solves within the memory budget (the others' status is ``unknown``)."""
    from dataclasses import replace

    from ..memory import resolve_budget, sparse_solver_bytes
    from ..reference import ReferenceSolution

    if references is None or callable(references):
        from ..reference import reference_solutions

        compute = reference_solutions if references is None else references
        budget = resolve_budget(None) if plan.budget is None else plan.budget
        wanted = [
            i
            for i, r in enumerate(plan.records)
            if any((i, name) not in plan.skips for name in plan.settings)
            and sparse_solver_bytes(r.problem) <= budget
        ]
        subset = replace(problem_set, records=[plan.records[i] for i in wanted])
        computed = dict(zip(wanted, compute(subset))) if wanted else {}
        references = [
            computed[i] if i in computed else ReferenceSolution("unknown", name=r.name)
            for i, r in enumerate(plan.records)
        ]
    if len(references) != len(plan.records):
        raise InputError(
            f"{len(references)} reference solutions for {len(plan.records)} problems",
            path=problem_set.path,
        )
    return references


def open_output(plan: Plan, out: Path, force: bool) -> dict:
    """Create or repair ``out`` (the first write of the run); the rows already done, by key."""
    if plan.resuming:
        plan.existing = read_results(out, repair=True)
    elif force and out.exists():
        out.unlink()
        plan.marker.path.unlink(missing_ok=True)
    return plan.existing.by_key()
