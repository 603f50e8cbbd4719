"""Reference solutions of a problem set (docs/methodology.md): computed by :data:`METHODS`,
cached (:func:`cache_path`) or read from known objectives. ``kkt`` is the worst of qpsolvers'
primal residual, dual residual and duality gap at an answer (``inf`` without one); a
reference's ``note`` says each solver's answer, which was kept and why.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np
import qpsolvers

from .atomic import write_bytes
from .cache import user_cache_dir, writable
from .formats import ProblemRecord, ProblemSet, content_sha256, solver_problem, table_to_bytes
from .metrics import objective
from .runner.process import context as worker_context
from .runner.process import deadline, run_tasks
from .statuses import CERTIFIED_INFEASIBLE, describe_exception

if TYPE_CHECKING:
    from collections.abc import Callable
    from multiprocessing.context import BaseContext

log = logging.getLogger("qpbench.reference")

#: Bumped when the way references are computed changes (invalidates caches).
REFERENCE_VERSION = "3"
CLARABEL_SETTINGS = dict(
    tol_gap_abs=1e-10,
    tol_gap_rel=1e-10,
    tol_feas=1e-10,
    tol_ktratio=1e-8,
    tol_infeas_abs=1e-10,
    tol_infeas_rel=1e-10,
    max_iter=500,
)
PIQP_SETTINGS = dict(
    eps_abs=1e-10,
    eps_rel=0.0,
    check_duality_gap=True,
    eps_duality_gap_abs=1e-10,
    eps_duality_gap_rel=0.0,
    max_iter=500,
)
SOLVER_SETTINGS = {"clarabel": CLARABEL_SETTINGS, "piqp": PIQP_SETTINGS}
#: Ways of computing a reference, by their solvers: both settled by residuals, or one alone.
METHODS = {"auto": ("clarabel", "piqp"), "clarabel": ("clarabel",), "piqp": ("piqp",)}
#: What ``--reference`` accepts besides a file.
SOURCES = (*METHODS, "none")
#: Relative objective difference within which the two solvers agree.
AGREE_RTOL = 1e-7
#: KKT residual accepting Clarabel's ``AlmostSolved`` and refuting an infeasibility claim.
ALMOST_TOL = 1e-7

_VEC_KEYS = ("x", "y", "z", "z_box")


@dataclass
class ReferenceSolution:
    """High-accuracy solution of one problem: ``status`` (optimal, infeasible or ``unknown``),
    ``x, y, z, z_box`` when optimal; the kept answer's ``objective``/``kkt``, the other's
    ``check_*``, their relative objective difference ``agreement``; ``time_limit_s`` [s]."""

    status: str
    x: np.ndarray | None = None
    y: np.ndarray | None = None
    z: np.ndarray | None = None
    z_box: np.ndarray | None = None
    objective: float = math.nan
    solver: str = "clarabel"
    check_solver: str | None = None
    check_status: str | None = None
    check_objective: float = math.nan
    agree: bool | None = None
    agreement: float = math.nan
    kkt: float = math.nan
    check_kkt: float = math.nan
    name: str | None = None
    note: str = ""
    time_limit_s: float = math.inf
    timed_out: bool = False

    def __post_init__(self):
        for k in _VEC_KEYS:
            if getattr(self, k) is not None:
                setattr(self, k, np.asarray(getattr(self, k), dtype=np.float64))


def _worst_residual(solution) -> float:
    if solution.x is None or not np.all(np.isfinite(solution.x)):
        return math.inf
    s = solution if solution.found else dataclasses.replace(solution, found=True)
    return max(s.primal_residual(), s.dual_residual(), s.duality_gap())


def _status(solver: str, solution) -> str:
    """The reference status of ``solver``'s qpsolvers solution (``unknown``: no verdict)."""
    if solver == "clarabel":
        from .backends.clarabel_ import CLARABEL_STATUSES

        name = str(solution.extras.get("status")).split(".")[-1]
        if name == "AlmostSolved":
            return "optimal" if _worst_residual(solution) <= ALMOST_TOL else "unknown"
        status = CLARABEL_STATUSES.get(name.removeprefix("Almost"))  # Almost...Infeasible as well
    else:
        from .backends.piqp_ import PIQP_STATUSES

        raw = getattr(solution.extras.get("info"), "status", None)  # a piqp status enum
        status = PIQP_STATUSES.get(getattr(raw, "name", None))
    return status if status in ("optimal", "time_limit", *CERTIFIED_INFEASIBLE) else "unknown"


@dataclass
class Candidate:
    """One reference solver's answer; ``wall_s`` [s]; ``kkt`` from ``solution`` by default."""

    solver: str
    status: str
    solution: object | None
    objective: float = math.nan
    reason: str = ""
    timed_out: bool = False
    wall_s: float = math.nan
    kkt: float | None = None

    def __post_init__(self):
        if self.kkt is None:
            self.kkt = math.inf if self.solution is None else float(_worst_residual(self.solution))

    def describe(self) -> str:
        """``solver status`` with its objective and KKT residual, or the reason for no verdict."""
        text = f"{self.solver} {self.status}"
        if self.status == "optimal":
            text += f" f = {self.objective:.10g} (KKT {self.kkt:.2g})"
        return text + (f" ({self.reason})" if self.reason else "")


def solve_candidate(record: ProblemRecord, solver: str, time_limit: float = math.inf) -> Candidate:
    """One reference solver's answer (vectors only; later than ``time_limit`` [s]: none)."""
    settings = dict(SOLVER_SETTINGS[solver])
    limited = math.isfinite(time_limit)
    if limited and solver == "clarabel":
        settings["time_limit"] = float(time_limit)
    started = time.perf_counter()
    try:
        with warnings.catch_warnings(action="ignore"):
            sol = qpsolvers.solve_problem(solver_problem(record.problem), solver=solver, **settings)
        error = ""
    except Exception as exc:  # a solver crash is an "unknown" reference, not a traceback
        log.debug("reference: %s failed: %s", solver, exc)
        sol, error = None, describe_exception(exc)
    wall = time.perf_counter() - started
    status = "unknown" if sol is None else _status(solver, sol)
    if limited and (wall > time_limit or status == "time_limit"):
        why = f"no answer within the time limit of {time_limit:g} s"
        return Candidate(solver, "unknown", None, reason=why, timed_out=True, wall_s=wall)
    if status != "optimal":
        return Candidate(solver, status, None, reason=error, wall_s=wall)
    vectors = SimpleNamespace(**{k: getattr(sol, k) for k in _VEC_KEYS})  # picklable
    kkt = _worst_residual(sol)
    return Candidate(solver, status, vectors, objective(record, sol.x), wall_s=wall, kkt=kkt)


def solve_task(task: tuple) -> Candidate:
    """:func:`solve_candidate` of ``(record, solver, time_limit)``, in a worker."""
    return solve_candidate(*task)


def needs_solver(record: ProblemRecord) -> bool:
    """``False`` for a problem without any constraint (solved by least squares at once)."""
    p = record.problem
    no_bounds = all(v is None or np.all(np.isinf(v)) for v in (p.lb, p.ub))
    return not (p.G is None and p.A is None and no_bounds)


def _unconstrained(record: ProblemRecord) -> ReferenceSolution:
    problem = solver_problem(record.problem)
    P, q = problem.P, problem.q
    P = P.toarray() if hasattr(P, "toarray") else P  # no constraint at all: small
    x, *_ = np.linalg.lstsq(P, -q, rcond=None)
    if float(np.max(np.abs(P @ x + q))) > 1e-9 * max(1.0, float(np.max(np.abs(q)))):
        note = "no constraints and P x = -q has no solution: unbounded"
        return ReferenceSolution("dual_infeasible", solver="lstsq", name=record.name, note=note)
    no_box = problem.lb is None and problem.ub is None
    return ReferenceSolution(
        "optimal",
        x=x,
        y=np.empty(0),
        z=np.empty(0),
        z_box=np.empty(0) if no_box else np.zeros(q.shape[0]),
        objective=objective(record, x),
        solver="lstsq",
        name=record.name,
        note="no constraints: P x = -q solved by least squares",
    )


def reference_solution(record: ProblemRecord, method: str = "auto") -> ReferenceSolution:
    """The reference of one problem by ``method`` (:data:`METHODS`), solved in this process."""
    if not needs_solver(record):
        return _unconstrained(record)
    return assemble(record.name, [solve_candidate(record, s) for s in METHODS[method]])


def settle(first: Candidate, second: Candidate) -> tuple[Candidate, Candidate, str, str]:
    """``(kept, other, status, why)`` of two answers (docs/methodology.md)."""
    if first.status == second.status == "optimal":
        keep, other = (first, second) if first.kkt <= second.kkt else (second, first)
        return keep, other, "optimal", f"kept {keep.solver}: smaller KKT residuals"
    swap = second.status == "optimal" or first.status == "unknown" != second.status
    keep, other = (second, first) if swap else (first, second)
    if keep.status == "optimal":
        if other.status == "unknown" or keep.kkt <= ALMOST_TOL:
            return keep, other, "optimal", f"kept {keep.solver}: the only optimal answer"
        keep, other = other, keep
    if keep.status == "unknown":
        return keep, other, "unknown", "no reference: no verdict from either solver"
    if other.status not in (keep.status, "unknown", "optimal"):
        return keep, other, "unknown", "no reference: the solvers' verdicts contradict each other"
    return keep, other, keep.status, f"kept {keep.solver}'s verdict {keep.status}"


def assemble(
    name: str | None, candidates: list[Candidate], time_limit: float = math.inf
) -> ReferenceSolution:
    """The reference of one answer or two (:func:`settle`); two agree when their statuses match
    and, when optimal, ``|f1 - f2| / max(1, |f1|, |f2|) <= AGREE_RTOL``."""
    fields: dict = {}
    if len(candidates) == 1:
        (keep,) = candidates
        status, note = keep.status, f"{keep.describe()}; {keep.solver} alone (no cross-check)"
    else:
        first, second = candidates
        f1, f2 = first.objective, second.objective
        agreement = abs(f1 - f2) / max(1.0, abs(f1), abs(f2))
        agree = first.status == second.status and (
            first.status != "optimal" or agreement <= AGREE_RTOL
        )
        keep, other, status, why = settle(first, second)
        verdict = "agree" if agree else "disagree"
        if first.status == second.status == "optimal":
            verdict += f" (objectives differ by {agreement:.2g} relative)"
        note = f"{first.describe()}; {second.describe()}; {verdict}; {why}"
        if not agree:
            log.warning("reference of '%s': %s", name, note)
        fields = {f"check_{k}": getattr(other, k) for k in ("solver", "status", "objective", "kkt")}
        fields.update(agree=agree, agreement=agreement)
    if status == "optimal":
        fields.update({k: getattr(keep.solution, k) for k in _VEC_KEYS}, objective=keep.objective)
    fields.update(time_limit_s=time_limit, timed_out=any(c.timed_out for c in candidates))
    return ReferenceSolution(
        status, solver=keep.solver, kkt=keep.kkt, name=name, note=note, **fields
    )


def bench_references(problem_set: ProblemSet, source: str = "auto", **options) -> list:
    """One reference per record from ``source``, said in the log: a method (``options``: those
    of :func:`reference_solutions`), ``none`` or a file of known optimal objectives."""
    if source in METHODS:
        folder = cache_folder(problem_set, options.get("cache_dir"))
        where = "references: not cached (set built in memory)"
        log.info("%s", f"reference cache: {folder}" if folder else where)
        return reference_solutions(problem_set, method=source, **options)
    log.info("%s", f"references: {source} (not cached)")
    if source == "none":
        return [None] * len(problem_set.records)
    from .published import read_objectives

    objectives, refs = read_objectives(source), []
    for record in problem_set.records:
        f = float(objectives.get(record.name, math.nan))
        ref = ReferenceSolution("optimal", objective=f, solver="file", name=record.name)
        ref.note = f"optimal objective {f:.10g} from {source}"
        if math.isnan(f):
            ref.status, ref.note = "unknown", f"no reference: '{record.name}' is not in {source}"
        refs.append(ref)
    return refs


def _compute(
    records: list, method: str, time_limit: float, jobs: int, on_done, context=None
) -> dict:
    """``{name: ReferenceSolution}``: in this process without a time limit and with one job,
    else each solve a worker's task."""
    solvers = METHODS[method]
    limited = math.isfinite(time_limit)
    timeout = deadline(time_limit) if limited else None
    out, tasks = {}, []
    for record in records:
        if (not limited and jobs <= 1) or not needs_solver(record):
            started = time.perf_counter()
            out[record.name] = reference_solution(record, method)
            on_done(out[record.name], time.perf_counter() - started)
        else:
            tasks += [((record.name, s), (record, s, time_limit), timeout) for s in solvers]
    ctx = context or worker_context(fresh=True)
    got: dict[str, dict] = {}
    for done in run_tasks(solve_task, tasks, jobs, ctx=ctx, name="qpbench-reference"):
        name, solver = done.key
        answers = got.setdefault(name, {})
        answers[solver] = done.value if done.status is None else _lost(solver, done, time_limit)
        if len(answers) == len(solvers):
            out[name] = assemble(name, [answers[s] for s in solvers], time_limit)
            on_done(out[name], sum(c.wall_s for c in answers.values() if math.isfinite(c.wall_s)))
    return out


def _lost(solver: str, done, time_limit: float) -> Candidate:
    """The ``unknown`` answer of a task that gave none (deadline, dead worker, error)."""
    if done.status == "time_limit":
        why = f"no answer within the time limit of {time_limit:g} s; worker stopped"
        return Candidate(solver, "unknown", None, reason=why, timed_out=True)
    why = f"reference {done.lost}" if done.status == "crashed" else done.lost
    return Candidate(solver, "unknown", None, reason=why)


def _progress(progress, total: int):
    """``(on_done(ref, wall_s), close())`` for the ``progress`` argument; ``"log"``: a line
    at most every 5 s, the last one and every failure."""
    if progress is None:
        return (lambda ref, wall: None), (lambda: None)
    if progress != "log":
        bar = progress(None, total=total, unit="problem", desc="references")
        return (lambda ref, wall: bar.update(1)), bar.close
    log.info("references: %d problems to solve", total)
    done, last = 0, time.monotonic()

    def on_done(ref, wall_s: float) -> None:
        nonlocal done, last
        done += 1
        if time.monotonic() - last >= 5.0 or done == total or ref.status != "optimal":
            last = time.monotonic()
            why = "" if ref.status == "optimal" else f" ({ref.note})"
            log.info(f"references: {done}/{total}; {ref.name}: {ref.status} in {wall_s:.1f} s{why}")

    return on_done, (lambda: None)


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
    """References of every problem of a set, in order, read from or added to the cache.
    ``progress``: ``None``, a tqdm-like callable or ``"log"``; ``time_limit`` [s] per solve;
    ``jobs`` workers started by ``context`` (default: ``spawn``)."""
    path = cache_path(problem_set, method, cache_dir) if cache else None
    sha = content_sha256(problem_set)
    limit = math.inf if time_limit is None else float(time_limit)
    known: dict[str, ReferenceSolution] = {}
    if path is not None and path.exists():
        known = {ref.name: ref for ref in (_read_cache(path, sha) or [])}
    todo = [  # missing, or timed out under a smaller limit
        r
        for r in problem_set.records
        if r.name not in known or (known[r.name].timed_out and known[r.name].time_limit_s < limit)
    ]
    if todo:
        on_done, close = _progress(progress, len(todo))
        try:
            known.update(_compute(todo, method, limit, jobs, on_done, context))
        finally:
            close()
        if path is not None and writable(path.parent):
            _write_cache(path, problem_set, list(known.values()), sha)
    return [known[r.name] for r in problem_set.records]


def cache_folder(problem_set: ProblemSet, cache_dir: str | Path | None = None) -> Path | None:
    """Where references of ``problem_set`` are cached: ``cache_dir``; else the set's folder when
    writable and ours; else ``user_cache_dir()/references`` (``None``: built in memory)."""
    if problem_set.path is None:
        return None
    if cache_dir is not None:
        return Path(cache_dir)
    path = Path(problem_set.path)
    folder = path if path.is_dir() else path.parent
    ours = (folder / "manifest.json").is_file() or any(folder.glob("*reference-*.parquet"))
    return folder if ours and writable(folder) else user_cache_dir() / "references"


def cache_path(
    problem_set: ProblemSet, method: str = "auto", cache_dir: str | Path | None = None
) -> Path | None:
    """The cache file of ``problem_set``'s references by ``method`` (``None``: not cached)."""
    sha = content_sha256(problem_set)
    folder = cache_folder(problem_set, cache_dir)
    if sha is None or folder is None:
        return None
    tag = "" if method == "auto" else f"{method}-"
    path = Path(problem_set.path)
    stem = "" if path.is_dir() else f"{path.stem}."
    return folder / f"{stem}reference-{tag}{sha[:16]}.parquet"


def _meta(sha: str) -> dict[bytes, bytes]:
    return {
        b"qpbench_set_sha256": sha.encode(),
        b"qpbench_reference_version": REFERENCE_VERSION.encode(),
    }


def _read_cache(path: Path, sha: str) -> list[ReferenceSolution] | None:
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
        meta = table.schema.metadata or {}
        if any(meta.get(k) != v for k, v in _meta(sha).items()):  # another set or version
            return None
        return [ReferenceSolution(**r) for r in table.to_pylist()]
    except Exception as exc:  # corrupt cache: recompute
        log.warning("%s: unreadable reference cache, recomputing (%s)", path, exc)
        return None


def _write_cache(path: Path, problem_set: ProblemSet, refs: list, sha: str) -> None:
    """Write atomically; remove stale caches of the same method in a problem-set folder."""
    import pyarrow as pa

    table = pa.Table.from_pylist([vars(r) for r in refs]).replace_schema_metadata(_meta(sha))
    try:
        write_bytes(path, table_to_bytes(table))
    except OSError as exc:
        log.debug("%s: reference cache not written (%s)", path, exc)
        return
    if problem_set.kind == "set" and path.parent == Path(problem_set.path):
        prefix = path.name.removesuffix(".parquet")[:-16]  # reference-[<method>-]
        for stale in path.parent.glob(prefix + "[0-9a-f]" * 16 + ".parquet"):
            if stale != path:
                stale.unlink(missing_ok=True)
