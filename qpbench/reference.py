"""References of a problem set: computed (time-limited, in parallel), cached, or given.

Where the reference of each problem comes from (:func:`bench_references`,
``qpbench bench --reference``):

- ``auto`` (default): Clarabel and PIQP at 1e-10, the answer with the smaller
  KKT residuals kept (:mod:`qpbench.reference_solve`); ``clarabel`` or
  ``piqp``: that solver alone;
- ``none``: no reference. Rows have an empty reference and optimality gap, and
  success is qpbenchmark's rule (found and residuals strictly below the
  tolerances; :mod:`qpbench.metrics`);
- a file (``FILE``): known optimal objectives, a CSV with a header and
  columns ``problem,objective`` (:func:`qpbench.published.read_objectives`).
  Each listed problem's reference is ``optimal`` with that objective (no
  ``x``: the optimality gap is computed, residuals are the solution's own); a
  problem the file does not list has reference status ``unknown``, an empty
  gap and a note saying so.

Computing (:func:`reference_solutions`): each reference solve has a time
limit (the profile's ``reference_time_limit``; ``None`` here means none).
With a limit, or with ``jobs > 1``, the solves run in worker processes
(:func:`qpbench.runner.process.run_tasks`), each task one solver on one
problem, up to ``jobs`` at once; otherwise in this process. Both give the same
answers, whatever ``jobs`` is and in whatever order the tasks finish. A task
past its deadline (:func:`qpbench.runner.process.deadline` of the limit) has
its worker killed and replaced. A solve that times out, fails or whose worker
dies is an ``unknown`` answer with its reason; a
problem left without a reference has status ``unknown`` and its rows an
empty optimality gap, with the reason in the ``reference_note`` column. The
run goes on. ``progress`` is called once per finished problem.

Cache: one Parquet file, ``reference-<sha[:16]>.parquet``
(``reference-<method>-<sha[:16]>.parquet`` for ``clarabel`` / ``piqp``; beside a
single file ``<file stem>.reference-...``), keyed by the set's SHA-256 (the
manifest hash of a problem-set folder; for a folder of ``.npz`` / ``.mat`` files
or a bare Parquet file, a SHA-256 of the files' names and bytes:
:func:`qpbench.formats.content_sha256`). It holds each problem's status,
solution, both solvers' objectives and KKT residuals, which was kept, the note
and the time limit. The full hash and :data:`REFERENCE_VERSION` are checked on
read, so a changed set, a changed method or a corrupt cache is recomputed; an
entry that timed out is recomputed when the limit is now larger. A set built
in memory is not cached; a folder counts as read-only without write
permission or with no write bit at all (as for shared data folders). Writes are atomic; stale
caches of the same method in a problem-set folder are removed. Where
(:func:`cache_folder`): a folder given by the caller (``bench --cache-dir``);
else beside the set when that folder is writable and the set is ours (its
``manifest.json``, or a reference cache of ours, is there); else the user cache folder,
``$XDG_CACHE_HOME/qpbench/references`` (default ``~/.cache/qpbench/references``).
A subset of a
set (``--problems``, ``--every``, ``--limit``) reads the set's cache and adds
what it lacks; it never replaces the cache with fewer problems.
"""

from __future__ import annotations

import logging
import math
import os
import re
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .atomic import write_bytes
from .formats import ProblemSet, content_sha256
from .reference_solve import (  # noqa: F401 - the public names of references live here too
    AGREE_RTOL,
    ALMOST_TOL,
    METHODS,
    REFERENCE_STATUSES,
    REFERENCE_VERSION,
    Candidate,
    ReferenceSolution,
    assemble,
    combine,
    reference_solution,
    relative_difference,
    settle,
    solve_candidate,
)

if TYPE_CHECKING:
    from collections.abc import Callable
    from multiprocessing.context import BaseContext

log = logging.getLogger("qpbench.reference")

#: What ``--reference`` accepts besides a file.
SOURCES = METHODS + ("none",)


# ---------------------------------------------------------------- sources


def bench_references(
    problem_set: ProblemSet,
    source: str = "auto",
    *,
    time_limit: float | None = None,
    jobs: int = 1,
    progress: Callable | str | None = None,
    cache: bool = True,
    context: BaseContext | None = None,
    cache_dir: str | Path | None = None,
) -> list:
    """One reference per record of ``problem_set`` from ``source`` (see the module docstring).

    Returns:
        A list of :class:`ReferenceSolution` (``None`` entries for ``none``).

    Raises:
        InputError: ``source`` is neither a method, ``none``, nor a readable objectives file.
    """
    if source == "none":
        return [None] * len(problem_set.records)
    if source in METHODS:
        return reference_solutions(
            problem_set,
            cache=cache,
            progress=progress,
            method=source,
            time_limit=time_limit,
            jobs=jobs,
            context=context,
            cache_dir=cache_dir,
        )
    from .published import read_objectives

    return from_objectives(problem_set, read_objectives(source), source)


def from_objectives(problem_set: ProblemSet, objectives: dict, source: str | Path = "file") -> list:
    """References from known optimal objectives (``{problem name: objective}``)."""
    refs = []
    for record in problem_set.records:
        f = objectives.get(record.name)
        if f is None:
            refs.append(
                ReferenceSolution(
                    "unknown",
                    solver="file",
                    name=record.name,
                    note=f"no reference: '{record.name}' is not in {source}",
                )
            )
        else:
            refs.append(
                ReferenceSolution(
                    "optimal",
                    objective=float(f),
                    solver="file",
                    name=record.name,
                    note=f"optimal objective {float(f):.10g} from {source}",
                )
            )
    return refs


# ---------------------------------------------------------------- computing


def _compute(
    records: list, method: str, time_limit: float | None, jobs: int, on_done, context=None
) -> dict:
    """``{name: ReferenceSolution}`` of ``records``, in this process or in workers."""
    solvers = ("clarabel", "piqp") if method == "auto" else (method,)
    limited = time_limit is not None and math.isfinite(time_limit)
    out = {}
    if not limited and jobs <= 1:
        for record in records:
            started = time.perf_counter()
            ref = reference_solution(record, method, None)
            out[record.name] = ref
            on_done(ref, time.perf_counter() - started)
        return out
    from .reference_solve import needs_solver, solve_task
    from .runner.process import context as worker_context
    from .runner.process import deadline, run_tasks

    tasks, waiting = [], {}
    timeout = deadline(time_limit) if limited else None
    for record in records:
        if not needs_solver(record):  # no solver involved
            out[record.name] = reference_solution(record, method, time_limit)
            on_done(out[record.name], 0.0)
            continue
        waiting[record.name] = {}
        tasks.extend(
            ((record.name, s), (record, s, time_limit if limited else None), timeout)
            for s in solvers
        )
    ctx = context if context is not None else worker_context(fresh=True)
    for done in run_tasks(solve_task, tasks, jobs, ctx=ctx, name="qpbench-reference"):
        name, solver = done.key
        got = waiting[name]
        got[solver] = done.value if done.status is None else _lost(solver, done, time_limit)
        if len(got) == len(solvers):
            out[name] = assemble(name, [got[s] for s in solvers], time_limit)
            on_done(out[name], sum(c.wall_s for c in got.values() if math.isfinite(c.wall_s)))
    return out


def _lost(solver: str, done, time_limit: float | None) -> Candidate:
    """The ``unknown`` answer of a task that gave none (deadline, dead worker, error)."""
    if done.status == "time_limit":
        why = f"no answer within the time limit of {time_limit:g} s; worker stopped"
        return Candidate(solver, "unknown", None, reason=why, timed_out=True)
    if done.status == "crashed":
        return Candidate(solver, "unknown", None, reason=f"reference {done.lost}")
    return Candidate(solver, "unknown", None, reason=done.lost)


class LogProgress:
    """Progress of reference solves as log lines on stderr (at most one per ``every_s`` seconds, and the last)."""

    def __init__(self, total: int, every_s: float = 5.0):
        self.total, self.every_s, self.done = total, every_s, 0
        self.last = time.monotonic()

    def __call__(self, ref, wall_s: float) -> None:
        self.done += 1
        now = time.monotonic()
        if now - self.last >= self.every_s or self.done == self.total or ref.status != "optimal":
            self.last = now
            log.info(
                "references: %d/%d; %s: %s in %.1f s%s",
                self.done,
                self.total,
                ref.name,
                ref.status,
                wall_s,
                "" if ref.status == "optimal" else f" ({ref.note})",
            )


def reference_solutions(
    problem_set: ProblemSet,
    cache: bool = True,
    progress: Callable | str | None = None,
    *,
    method: str = "auto",
    time_limit: float | None = None,
    jobs: int = 1,
    context: BaseContext | None = None,
    cache_dir: str | Path | None = None,
) -> list[ReferenceSolution]:
    """References of every problem of a set, in order, read from or written to the cache.

    Args:
        problem_set: The set (from :func:`qpbench.formats.load_problems`).
        cache: Use the cache (in :func:`cache_folder`).
        progress: ``None``, a callable wrapping an iterable (e.g. ``tqdm.tqdm``; called
            with ``total=``), or ``"log"`` (:class:`LogProgress`).
        method: ``auto``, ``clarabel`` or ``piqp``.
        time_limit: Limit of each reference solve in [s] (``None``: none).
        jobs: Worker processes solving at once.
        context: ``multiprocessing`` context of the workers (default ``spawn``, a fresh
            interpreter, never a fork of this process, which may hold threads and locks).
        cache_dir: Folder of the cache (default: :func:`cache_folder`'s rule).
    """
    if method not in METHODS:
        raise ValueError(f"unknown reference method '{method}'")
    path = cache_path(problem_set, method, cache_dir) if cache else None
    sha = content_sha256(problem_set)
    names = [r.name for r in problem_set.records]
    limit = math.inf if time_limit is None else float(time_limit)
    known: dict[str, ReferenceSolution] = {}
    if path is not None and path.exists():
        known = {ref.name: ref for ref in (_read_cache(path, sha) or [])}
        if all(n in known and not _stale(known[n], limit) for n in names):
            return [known[n] for n in names]
    todo = [r for r in problem_set.records if r.name not in known or _stale(known[r.name], limit)]
    on_done, close = _progress(progress, len(todo))
    try:
        known.update(_compute(todo, method, time_limit, jobs, on_done, context))
    finally:
        close()
    refs = [known[n] for n in names]
    if path is not None and _make(path.parent):
        _write_cache(path, problem_set, list(known.values()), sha, method)
    return refs


def _progress(progress, total: int):
    """``(on_done(ref, wall_s), close())`` for the ``progress`` argument of :func:`reference_solutions`."""
    if progress is None or total == 0:
        return (lambda ref, wall: None), (lambda: None)
    if progress == "log":
        log.info("references: %d problems to solve", total)
        return LogProgress(total), (lambda: None)
    bar = progress(None, total=total, unit="problem", desc="references")
    return (lambda ref, wall: bar.update(1)), bar.close


def _stale(ref: ReferenceSolution, limit: float) -> bool:
    """A cached reference that timed out under a smaller limit than ``limit`` is recomputed."""
    return bool(ref.timed_out) and ref.time_limit_s < limit


# ---------------------------------------------------------------- cache


def cache_folder(problem_set: ProblemSet, cache_dir: str | Path | None = None) -> Path | None:
    """The folder the references of ``problem_set`` are cached in (``None``: not cached).

    ``cache_dir`` when given; else the set's folder (the folder of a single
    file) when it is writable and the set is ours (``manifest.json`` or a
    ``reference-*.parquet`` of ours there);
    else the user cache folder (:func:`qpbench.cache.user_cache_dir` / ``references``).
    """
    if problem_set.path is None:
        return None
    if cache_dir is not None:
        return Path(cache_dir)
    path = Path(problem_set.path)
    folder = path if path.is_dir() else path.parent
    ours = (folder / "manifest.json").is_file() or any(folder.glob("*reference-*.parquet"))
    if ours and _writable(folder):
        return folder
    from .cache import user_cache_dir

    return user_cache_dir() / "references"


def cache_path(
    problem_set: ProblemSet, method: str = "auto", cache_dir: str | Path | None = None
) -> Path | None:
    """Where the references of ``problem_set`` computed by ``method`` are cached (``None``: not cached)."""
    sha = content_sha256(problem_set)
    folder = cache_folder(problem_set, cache_dir)
    if sha is None or folder is None:
        return None
    tag = "" if method == "auto" else f"{method}-"
    path = Path(problem_set.path)
    if path.is_dir():
        return folder / f"reference-{tag}{sha[:16]}.parquet"
    return folder / f"{path.stem}.reference-{tag}{sha[:16]}.parquet"


_VEC_KEYS = ("x", "y", "z", "z_box")
_FLOAT_KEYS = ("objective", "check_objective", "agreement", "kkt", "check_kkt", "time_limit_s")
_TEXT_KEYS = ("name", "status", "solver", "check_solver", "check_status", "note")


def _to_bytes(refs: list[ReferenceSolution], sha: str) -> bytes:
    import pyarrow as pa

    from .formats import _list_column, table_to_bytes

    cols = {
        **{k: pa.array([getattr(r, k) for r in refs], type=pa.string()) for k in _TEXT_KEYS},
        **{k: _list_column([getattr(r, k) for r in refs]) for k in _VEC_KEYS},
        **{k: pa.array([getattr(r, k) for r in refs], type=pa.float64()) for k in _FLOAT_KEYS},
        "agree": pa.array([r.agree for r in refs], type=pa.bool_()),
        "timed_out": pa.array([bool(r.timed_out) for r in refs], type=pa.bool_()),
    }
    table = pa.table(cols).replace_schema_metadata(
        {"qpbench_set_sha256": sha, "qpbench_reference_version": REFERENCE_VERSION}
    )
    return table_to_bytes(table)


def _read_cache(path: Path, sha: str) -> list[ReferenceSolution] | None:
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        if meta.get(b"qpbench_set_sha256", b"").decode() != sha:
            return None
        if meta.get(b"qpbench_reference_version", b"").decode() != REFERENCE_VERSION:
            return None
        rows = table.to_pylist()
        return [
            ReferenceSolution(
                **{k: r[k] for k in _TEXT_KEYS if k != "note"},
                note=r["note"] or "",
                **{k: math.nan if r[k] is None else float(r[k]) for k in _FLOAT_KEYS},
                **{
                    k: None if r[k] is None else np.array(r[k], dtype=np.float64) for k in _VEC_KEYS
                },
                agree=r["agree"],
                timed_out=bool(r["timed_out"]),
            )
            for r in rows
        ]
    except Exception as exc:  # corrupt cache: recompute
        log.warning("%s: unreadable reference cache, recomputing (%s)", path, exc)
        return None


def _write_cache(path: Path, problem_set: ProblemSet, refs: list, sha: str, method: str) -> None:
    try:
        write_bytes(path, _to_bytes(refs, sha))
    except OSError as exc:
        log.debug("%s: reference cache not written (%s)", path, exc)
        return
    if problem_set.kind == "set" and path.parent == Path(problem_set.path):
        tag = "" if method == "auto" else f"{method}-"
        same_method = re.compile(rf"reference-{re.escape(tag)}[0-9a-f]{{16}}\.parquet")
        for stale in Path(problem_set.path).glob("reference-*.parquet"):
            if stale != path and same_method.fullmatch(stale.name):
                stale.unlink(missing_ok=True)


def _make(folder: Path) -> bool:
    """Create ``folder`` (and parents); whether it is then writable."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return _writable(folder)


def _writable(folder: Path) -> bool:
    """Whether to write into ``folder``: it must be writable and not marked read-only
    (no write bit at all; this holds even for root, who may write anywhere)."""
    try:
        return os.access(folder, os.W_OK) and bool(folder.stat().st_mode & 0o222)
    except OSError:
        return False
