"""High-accuracy reference solutions, cross-checked, cached per problem set.

How a reference is computed (:func:`reference_solution`):

1. Clarabel (interior point) through :func:`qpsolvers.solve_problem` with
   ``tol_gap_abs = tol_gap_rel = tol_feas = 1e-10``, ``tol_ktratio = 1e-8``,
   ``tol_infeas_abs = tol_infeas_rel = 1e-10``, ``max_iter = 500``. Its status is
   read from ``Solution.extras["status"]`` (Clarabel's ``SolverStatus``):
   ``Solved`` -> ``optimal``; ``PrimalInfeasible`` / ``AlmostPrimalInfeasible`` ->
   ``primal_infeasible``; ``DualInfeasible`` / ``AlmostDualInfeasible`` ->
   ``dual_infeasible`` (unbounded objective); ``AlmostSolved`` -> ``optimal`` when
   qpsolvers' residuals and duality gap are all below 1e-7, anything else ->
   ``unknown``. A problem without any constraint is solved directly:
   ``P x = -q`` by least squares, ``optimal`` when the residual is below
   1e-9 max(1, |q|), else ``dual_infeasible``.
2. Cross-check with PIQP (a second, independent interior-point code with
   infeasibility detection) through qpsolvers at ``eps_abs = 1e-10``,
   ``eps_rel = 0`` and the duality-gap check on. ``agreement`` is the two
   solvers' relative objective difference ``|f1 - f2| / max(1, |f1|, |f2|)``
   (NaN unless both are optimal); they agree when both give the same status
   and, when optimal, ``agreement <= 1e-7``.

Which answer is kept is decided by the evidence, never by the solver's name
(:func:`settle`). Each solver's worst KKT residual ``kkt`` is
``max(primal residual, dual residual, duality gap)`` of qpsolvers at its
answer (``inf`` without one):

- both optimal: the one with the smaller ``kkt`` (agreeing or not);
- one optimal: it is kept if the other has no verdict (``unknown``) or if
  its ``kkt <= 1e-7`` (a point that satisfies the optimality conditions
  refutes the other's infeasibility claim); otherwise the other's
  infeasibility is kept;
- neither optimal: the common status; one ``unknown`` and one infeasibility
  verdict: the verdict; two different verdicts: ``unknown``.

The result records both objectives and residuals (``objective``/``kkt`` of the
kept answer, ``check_objective``/``check_kkt`` of the other), which solver was
kept (``solver``), ``agreement`` and ``agree``; a disagreement is logged.

The objective is ``1/2 x'Px + q'x + offset`` (:func:`qpbench.metrics.objective`).

Cache (:func:`reference_solutions`): one Parquet file beside the set,
``<folder>/reference-<sha[:16]>.parquet`` (or ``<file stem>.reference-<sha[:16]>.parquet``
beside a single file), keyed by the set's SHA-256 (the manifest hash of a
problem-set folder; for a folder of ``.npz`` / ``.mat`` files or a bare Parquet
file, a SHA-256 of the files' names and bytes: :func:`qpbench.formats.content_sha256`).
The full hash and :data:`REFERENCE_VERSION` are stored in the file's metadata and
checked on read, so a changed set, a changed method or a corrupt cache is
recomputed. A set built in memory, or one in a read-only folder (no write
permission, or no write bit at all, as for shared data folders), is not cached.
Writes are atomic; stale ``reference-*.parquet`` files in a problem-set folder are
removed.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import qpsolvers

from .atomic import write_bytes
from .formats import ProblemRecord, ProblemSet, content_sha256, solver_problem
from .metrics import objective

log = logging.getLogger(__name__)

#: Bumped when the way references are computed changes (invalidates caches).
REFERENCE_VERSION = "2"
#: Statuses a reference can have.
REFERENCE_STATUSES = ("optimal", "primal_infeasible", "dual_infeasible", "unknown")

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
#: Relative objective agreement required between the two solvers.
AGREE_RTOL = 1e-7
#: Residual bound accepting Clarabel's ``AlmostSolved``.
ALMOST_TOL = 1e-7


@dataclass
class ReferenceSolution:
    """High-accuracy solution of one problem.

    Attributes:
        status: ``optimal``, ``primal_infeasible``, ``dual_infeasible`` or ``unknown``.
        x, y, z, z_box: Primal and dual solution (qpsolvers' sign convention);
            ``None`` unless optimal.
        objective: ``1/2 x'Px + q'x + offset`` (NaN unless optimal).
        solver: Solver whose solution is kept (``clarabel``, ``piqp``, ``lstsq``).
        check_solver: Second solver used for the cross-check.
        check_status: Its status.
        check_objective: Its objective (NaN unless optimal).
        agree: Whether the two solvers agree (see the module docstring).
        agreement: Relative objective difference of the two solvers (NaN
            unless both are optimal; dimensionless).
        kkt: Worst KKT residual of the kept answer (``inf`` without one).
        check_kkt: Worst KKT residual of the other solver's answer.
        name: Problem name.
    """

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
    extras: dict = field(default_factory=dict)

    @property
    def is_optimal(self) -> bool:
        return self.status == "optimal"


def _clarabel_status(solution) -> str:
    import clarabel

    status = solution.extras.get("status")
    S = clarabel.SolverStatus
    if status == S.Solved:
        return "optimal"
    if status in (S.PrimalInfeasible, S.AlmostPrimalInfeasible):
        return "primal_infeasible"
    if status in (S.DualInfeasible, S.AlmostDualInfeasible):
        return "dual_infeasible"
    if status == S.AlmostSolved and _worst_residual(solution) <= ALMOST_TOL:
        return "optimal"
    return "unknown"


def _piqp_status(solution) -> str:
    import piqp

    info = solution.extras.get("info")
    status = getattr(info, "status", None)
    if status == piqp.PIQP_SOLVED:
        return "optimal"
    if status == piqp.PIQP_PRIMAL_INFEASIBLE:
        return "primal_infeasible"
    if status == piqp.PIQP_DUAL_INFEASIBLE:
        return "dual_infeasible"
    return "unknown"


def _worst_residual(solution) -> float:
    s = solution
    if s.x is None or not np.all(np.isfinite(s.x)):
        return math.inf
    if not s.found:
        import dataclasses

        s = dataclasses.replace(s, found=True)
    return max(s.primal_residual(), s.dual_residual(), s.duality_gap())


def _solve(problem, solver: str, settings: dict):
    """(solution or None, status) of one qpsolvers solve; never raises for solver trouble."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = qpsolvers.solve_problem(problem, solver=solver, **settings)
    except Exception as exc:  # a solver crash is an "unknown" reference, not a traceback
        log.debug("reference: %s failed: %s", solver, exc)
        return None, "unknown"
    status = _clarabel_status(sol) if solver == "clarabel" else _piqp_status(sol)
    return sol, status


def _unconstrained(record: ProblemRecord) -> ReferenceSolution:
    P, q = record.problem.P, record.problem.q
    P = P.toarray() if hasattr(P, "toarray") else P  # no constraint at all: small problems in practice
    x, *_ = np.linalg.lstsq(P, -q, rcond=None)
    res = float(np.max(np.abs(P @ x + q)))
    if res > 1e-9 * max(1.0, float(np.max(np.abs(q)))):
        return ReferenceSolution("dual_infeasible", solver="lstsq", name=record.name)
    n = q.shape[0]
    return ReferenceSolution(
        "optimal",
        x=x,
        y=np.empty(0),
        z=np.empty(0),
        z_box=np.empty(0) if record.problem.lb is None and record.problem.ub is None else np.zeros(n),
        objective=objective(record, x),
        solver="lstsq",
        name=record.name,
    )


def _is_unconstrained(p) -> bool:
    no_bounds = all(
        v is None or np.all(np.isinf(v)) for v in (p.lb, p.ub)
    )
    return p.G is None and p.A is None and no_bounds


def relative_difference(f1: float, f2: float) -> float:
    """``|f1 - f2| / max(1, |f1|, |f2|)`` (NaN when either is NaN)."""
    if math.isnan(f1) or math.isnan(f2):
        return math.nan
    return abs(f1 - f2) / max(1.0, abs(f1), abs(f2))


@dataclass
class Candidate:
    """One reference solver's answer: its name, status, solution (or ``None``) and objective."""

    solver: str
    status: str
    solution: object | None
    objective: float = math.nan

    @property
    def kkt(self) -> float:
        """Worst of qpsolvers' primal residual, dual residual and duality gap (``inf`` without x)."""
        if self.solution is None:
            return math.inf
        return float(_worst_residual(self.solution))


def settle(first: Candidate, second: Candidate) -> tuple[Candidate, Candidate, str]:
    """``(kept, other, status)`` by the rules of the module docstring (names play no part)."""
    k1, k2 = first.kkt, second.kkt
    s1, s2 = first.status, second.status
    if s1 == s2 == "optimal":
        return (first, second, s1) if k1 <= k2 else (second, first, s2)
    if "optimal" in (s1, s2):
        opt, other = (first, second) if s1 == "optimal" else (second, first)
        if other.status == "unknown" or opt.kkt <= ALMOST_TOL:
            return opt, other, "optimal"
        return other, opt, other.status
    if s1 == s2:
        return first, second, s1
    if "unknown" in (s1, s2):
        verdict, other = (first, second) if s2 == "unknown" else (second, first)
        return verdict, other, verdict.status
    return first, second, "unknown"


def reference_solution(record: ProblemRecord) -> ReferenceSolution:
    """High-accuracy reference of one problem (see the module docstring)."""
    problem = solver_problem(record.problem)  # sparse matrices stay sparse
    if _is_unconstrained(problem):
        return _unconstrained(ProblemRecord(problem, record.name, offset=record.offset))
    candidates = []
    for solver, settings in (("clarabel", CLARABEL_SETTINGS), ("piqp", PIQP_SETTINGS)):
        sol, status = _solve(problem, solver, settings)
        obj = objective(record, sol.x) if status == "optimal" else math.nan
        candidates.append(Candidate(solver, status, sol if status == "optimal" else None, obj))
    return combine(record.name, *candidates)


def combine(name: str | None, first: Candidate, second: Candidate) -> ReferenceSolution:
    """The reference made of two solvers' answers (see :func:`settle`)."""
    agreement = relative_difference(first.objective, second.objective)
    agree = first.status == second.status and (first.status != "optimal" or agreement <= AGREE_RTOL)
    keep, other, status = settle(first, second)
    if not agree:
        log.warning(
            "reference of '%s': %s says %s (f = %.10g, KKT %.3g), %s says %s (f = %.10g, KKT %.3g); "
            "keeping %s's answer (%s)",
            name, first.solver, first.status, first.objective, first.kkt,
            second.solver, second.status, second.objective, second.kkt, keep.solver, status,
        )
    ref = ReferenceSolution(
        status=status,
        objective=keep.objective if status == "optimal" else math.nan,
        solver=keep.solver,
        check_solver=other.solver,
        check_status=other.status,
        check_objective=other.objective,
        agree=agree,
        agreement=agreement,
        kkt=keep.kkt,
        check_kkt=other.kkt,
        name=name,
    )
    if status == "optimal":
        sol = keep.solution
        ref.x = np.asarray(sol.x, dtype=np.float64)
        ref.y = None if sol.y is None else np.asarray(sol.y, dtype=np.float64)
        ref.z = None if sol.z is None else np.asarray(sol.z, dtype=np.float64)
        ref.z_box = None if sol.z_box is None else np.asarray(sol.z_box, dtype=np.float64)
    return ref


# ---------------------------------------------------------------- cache


def cache_path(problem_set: ProblemSet) -> Path | None:
    """Where the references of ``problem_set`` are cached (``None``: not cached)."""
    sha = content_sha256(problem_set)
    if sha is None or problem_set.path is None:
        return None
    path = Path(problem_set.path)
    if path.is_dir():
        return path / f"reference-{sha[:16]}.parquet"
    return path.parent / f"{path.stem}.reference-{sha[:16]}.parquet"


_VEC_KEYS = ("x", "y", "z", "z_box")
_FLOAT_KEYS = ("agreement", "kkt", "check_kkt")


def _to_bytes(refs: list[ReferenceSolution], sha: str) -> bytes:
    import pyarrow as pa

    from .formats import _list_column, table_to_bytes

    cols = {
        "name": pa.array([r.name for r in refs], type=pa.string()),
        "status": pa.array([r.status for r in refs], type=pa.string()),
        **{k: _list_column([getattr(r, k) for r in refs]) for k in _VEC_KEYS},
        "objective": pa.array([r.objective for r in refs], type=pa.float64()),
        "solver": pa.array([r.solver for r in refs], type=pa.string()),
        "check_solver": pa.array([r.check_solver for r in refs], type=pa.string()),
        "check_status": pa.array([r.check_status for r in refs], type=pa.string()),
        "check_objective": pa.array([r.check_objective for r in refs], type=pa.float64()),
        "agree": pa.array([r.agree for r in refs], type=pa.bool_()),
        **{k: pa.array([getattr(r, k) for r in refs], type=pa.float64()) for k in _FLOAT_KEYS},
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
    except Exception as exc:  # corrupt cache: recompute
        log.warning("%s: unreadable reference cache, recomputing (%s)", path, exc)
        return None
    out = []
    for r in rows:
        vec = {k: None if r[k] is None else np.array(r[k], dtype=np.float64) for k in _VEC_KEYS}
        out.append(
            ReferenceSolution(
                status=r["status"],
                objective=math.nan if r["objective"] is None else r["objective"],
                solver=r["solver"],
                check_solver=r["check_solver"],
                check_status=r["check_status"],
                check_objective=math.nan if r["check_objective"] is None else r["check_objective"],
                agree=r["agree"],
                name=r["name"],
                **{k: math.nan if r[k] is None else r[k] for k in _FLOAT_KEYS},
                **vec,
            )
        )
    return out


def _writable(folder: Path) -> bool:
    """Whether to write into ``folder``: it must be writable and not marked read-only
    (no write bit at all; this holds even for root, who may write anywhere)."""
    try:
        return os.access(folder, os.W_OK) and bool(folder.stat().st_mode & 0o222)
    except OSError:
        return False


def reference_solutions(problem_set: ProblemSet, cache: bool = True, progress=None) -> list[ReferenceSolution]:
    """References of every problem of a set, in order, read from or written to the cache.

    Args:
        problem_set: The set (from :func:`qpbench.formats.load_problems`).
        cache: Use the cache beside the set.
        progress: Optional callable wrapping an iterable (e.g. ``tqdm.tqdm``).
    """
    path = cache_path(problem_set) if cache else None
    sha = content_sha256(problem_set)
    names = [r.name for r in problem_set.records]
    known: dict[str, ReferenceSolution] = {}
    if path is not None and path.exists():
        # a subset of a set (``--problems``, ``--every``, ``--limit``) reads the set's cache and
        # adds what it lacks; it never replaces the cache with fewer problems
        known = {ref.name: ref for ref in (_read_cache(path, sha) or [])}
        if all(n in known for n in names):
            return [known[n] for n in names]
    todo = [r for r in problem_set.records if r.name not in known]
    records = todo if progress is None else progress(todo)
    for r in records:
        known[r.name] = reference_solution(r)
    refs = [known[n] for n in names]
    if path is not None and _writable(path.parent):
        try:
            write_bytes(path, _to_bytes(list(known.values()), sha))
        except OSError as exc:
            log.debug("%s: reference cache not written (%s)", path, exc)
            return refs
        if problem_set.kind == "set" and Path(problem_set.path).is_dir():
            for stale in Path(problem_set.path).glob("reference-*.parquet"):
                if stale != path:
                    stale.unlink(missing_ok=True)
    return refs
