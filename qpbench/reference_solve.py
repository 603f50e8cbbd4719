"""High-accuracy reference solution of one problem: two solvers, settled by their KKT residuals.

How a reference is computed (:func:`reference_solution`, ``method = "auto"``;
``"clarabel"`` or ``"piqp"`` use that solver alone, without a cross-check):

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

Time limit (:func:`solve_candidate`): Clarabel gets ``time_limit``; PIQP has
none, so a limit that must hold whatever the solver does needs a worker
process (:func:`qpbench.runner.process.run_tasks`). An answer that arrives after the
limit is discarded: that solver's status is ``unknown`` with the reason
(``timed_out``), and :func:`settle` treats it as no verdict.

Every :class:`ReferenceSolution` carries a ``note``: each solver's status,
objective and KKT residual, and which answer was kept and why (or why there
is none). The cache, the orchestration over a set and the other sources of
references (``none``, a file of optimal objectives) are in :mod:`qpbench.reference`.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import qpsolvers

from .formats import ProblemRecord, solver_problem
from .metrics import objective

log = logging.getLogger(__name__)

#: Bumped when the way references are computed changes (invalidates caches).
REFERENCE_VERSION = "3"
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
#: Settings of each reference solver, by name.
SOLVER_SETTINGS = {"clarabel": CLARABEL_SETTINGS, "piqp": PIQP_SETTINGS}
#: Ways of computing a reference: both solvers settled by residuals, or one of them alone.
METHODS = ("auto", "clarabel", "piqp")
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
        note: Each solver's status, objective and KKT residual and which answer
            was kept and why; or why there is no reference.
        time_limit_s: Limit each solve had in [s] (``inf``: none).
        timed_out: A solver gave no answer within the limit.
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
    note: str = ""
    time_limit_s: float = math.inf
    timed_out: bool = False
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
    """``(solution or None, status, error text)`` of one qpsolvers solve; never raises for solver trouble."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = qpsolvers.solve_problem(problem, solver=solver, **settings)
    except Exception as exc:  # a solver crash is an "unknown" reference, not a traceback
        log.debug("reference: %s failed: %s", solver, exc)
        return None, "unknown", f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    status = _clarabel_status(sol) if solver == "clarabel" else _piqp_status(sol)
    return sol, status, ""


def _unconstrained(record: ProblemRecord) -> ReferenceSolution:
    P, q = record.problem.P, record.problem.q
    P = (
        P.toarray() if hasattr(P, "toarray") else P
    )  # no constraint at all: small problems in practice
    x, *_ = np.linalg.lstsq(P, -q, rcond=None)
    res = float(np.max(np.abs(P @ x + q)))
    if res > 1e-9 * max(1.0, float(np.max(np.abs(q)))):
        return ReferenceSolution(
            "dual_infeasible",
            solver="lstsq",
            name=record.name,
            note="no constraints and P x = -q has no solution: unbounded",
        )
    n = q.shape[0]
    return ReferenceSolution(
        "optimal",
        x=x,
        y=np.empty(0),
        z=np.empty(0),
        z_box=np.empty(0)
        if record.problem.lb is None and record.problem.ub is None
        else np.zeros(n),
        objective=objective(record, x),
        solver="lstsq",
        name=record.name,
        note="no constraints: P x = -q solved by least squares",
    )


def _is_unconstrained(p) -> bool:
    no_bounds = all(v is None or np.all(np.isinf(v)) for v in (p.lb, p.ub))
    return p.G is None and p.A is None and no_bounds


def needs_solver(record: ProblemRecord) -> bool:
    """Whether ``record``'s reference takes a solver: ``False`` for a problem without any
    constraint, which :func:`reference_solution` solves by least squares at once."""
    return not _is_unconstrained(_problem_for_reference(record))


def relative_difference(f1: float, f2: float) -> float:
    """``|f1 - f2| / max(1, |f1|, |f2|)`` (NaN when either is NaN)."""
    if math.isnan(f1) or math.isnan(f2):
        return math.nan
    return abs(f1 - f2) / max(1.0, abs(f1), abs(f2))


@dataclass
class Candidate:
    """One reference solver's answer.

    Attributes:
        solver: ``clarabel`` or ``piqp``.
        status: One of :data:`REFERENCE_STATUSES`.
        solution: Its solution (``x, y, z, z_box``) when optimal, else ``None``.
        objective: ``1/2 x'Px + q'x + offset`` (NaN unless optimal).
        reason: Why there is no verdict (time limit, error), else empty.
        timed_out: No answer within the time limit.
        wall_s: Duration of the solve in [s].
        known_kkt: The KKT residual when already computed (a worker's answer).
    """

    solver: str
    status: str
    solution: object | None
    objective: float = math.nan
    reason: str = ""
    timed_out: bool = False
    wall_s: float = math.nan
    known_kkt: float | None = None

    @property
    def kkt(self) -> float:
        """Worst of qpsolvers' primal residual, dual residual and duality gap (``inf`` without x)."""
        if self.known_kkt is not None:
            return self.known_kkt
        if self.solution is None:
            return math.inf
        return float(_worst_residual(self.solution))

    def plain(self) -> Candidate:
        """The same answer without the solver's objects (picklable: a worker sends it back)."""
        sol = self.solution
        plain = (
            None
            if sol is None
            else SimpleNamespace(**{k: getattr(sol, k, None) for k in _VEC_KEYS})
        )
        return Candidate(
            self.solver,
            self.status,
            plain,
            self.objective,
            self.reason,
            self.timed_out,
            self.wall_s,
            self.kkt,
        )

    def describe(self) -> str:
        """``solver status`` with its objective and KKT residual, or the reason for no verdict."""
        text = f"{self.solver} {self.status}"
        if self.status == "optimal":
            text += f" f = {self.objective:.10g} (KKT {self.kkt:.2g})"
        if self.reason:
            text += f" ({self.reason})"
        return text


_VEC_KEYS = ("x", "y", "z", "z_box")


def _problem_for_reference(record: ProblemRecord):
    """The problem as the reference solvers get it (float64; sparse matrices stay sparse)."""
    return solver_problem(record.problem)


def solve_candidate(
    record: ProblemRecord, solver: str, time_limit: float | None = None
) -> Candidate:
    """One reference solver's answer for ``record``; never raises for solver trouble.

    Args:
        record: The problem.
        solver: ``clarabel`` or ``piqp``.
        time_limit: Limit in [s] (``None``: none). Clarabel is given it; an answer of
            either that arrives later is discarded (status ``unknown``, ``timed_out``).
    """
    settings = dict(SOLVER_SETTINGS[solver])
    limited = time_limit is not None and math.isfinite(time_limit)
    if limited and solver == "clarabel":
        settings["time_limit"] = float(time_limit)
    problem = _problem_for_reference(record)
    started = time.perf_counter()
    sol, status, error = _solve(problem, solver, settings)
    wall = time.perf_counter() - started
    if limited and (wall > time_limit or _clarabel_timed_out(solver, sol)):
        return Candidate(
            solver,
            "unknown",
            None,
            reason=f"no answer within the time limit of {time_limit:g} s",
            timed_out=True,
            wall_s=wall,
        )
    if status != "optimal":
        return Candidate(solver, status, None, reason=error, wall_s=wall)
    return Candidate(solver, status, sol, objective(record, sol.x), wall_s=wall)


def solve_task(task: tuple) -> Candidate:
    """:func:`solve_candidate` of ``(record, solver, time_limit)`` in a worker process: a
    plain (picklable) answer, and a bug in one task an ``unknown`` answer, not the others' end."""
    record, solver, time_limit = task
    try:
        return solve_candidate(record, solver, time_limit).plain()
    except Exception as exc:  # noqa: BLE001 - see the docstring
        return Candidate(solver, "unknown", None, reason=f"{type(exc).__name__}: {exc}")


def _clarabel_timed_out(solver: str, sol) -> bool:
    if solver != "clarabel" or sol is None:
        return False
    import clarabel

    return (sol.extras or {}).get("status") == clarabel.SolverStatus.MaxTime


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


def reference_solution(
    record: ProblemRecord,
    method: str = "auto",
    time_limit: float | None = None,
) -> ReferenceSolution:
    """High-accuracy reference of one problem (see the module docstring), solved in this process.

    Args:
        record: The problem.
        method: ``auto`` (both solvers, settled by residuals), ``clarabel`` or ``piqp`` alone.
        time_limit: Limit of each solve in [s] (``None``: none; see :func:`solve_candidate`).
    """
    if method not in METHODS:
        raise ValueError(f"unknown reference method '{method}'")
    if not needs_solver(record):
        return _unconstrained(
            ProblemRecord(_problem_for_reference(record), record.name, offset=record.offset)
        )
    solvers = ("clarabel", "piqp") if method == "auto" else (method,)
    return assemble(
        record.name, [solve_candidate(record, s, time_limit) for s in solvers], time_limit
    )


def assemble(
    name: str | None, candidates: list[Candidate], time_limit: float | None = None
) -> ReferenceSolution:
    """The reference made of one or two solvers' answers (:func:`combine` for two)."""
    if len(candidates) == 2:
        ref = combine(name, *candidates)
    else:
        (only,) = candidates
        ref = _from_candidate(name, only, only.status)
        ref.note = f"{only.describe()}; {only.solver} alone (no cross-check)"
    ref.time_limit_s = math.inf if time_limit is None else float(time_limit)
    ref.timed_out = any(c.timed_out for c in candidates)
    return ref


def _from_candidate(name, keep: Candidate, status: str) -> ReferenceSolution:
    ref = ReferenceSolution(
        status=status,
        solver=keep.solver,
        kkt=keep.kkt,
        name=name,
        objective=keep.objective if status == "optimal" else math.nan,
    )
    if status == "optimal":
        sol = keep.solution
        ref.x = np.asarray(sol.x, dtype=np.float64)
        for k in ("y", "z", "z_box"):
            v = getattr(sol, k, None)
            setattr(ref, k, None if v is None else np.asarray(v, dtype=np.float64))
    return ref


def _why(keep: Candidate, other: Candidate, status: str) -> str:
    if status == "optimal" and other.status == "optimal":
        return f"kept {keep.solver}: smaller KKT residuals"
    if status == "optimal":
        return f"kept {keep.solver}: the only optimal answer"
    if status == "unknown":
        return "no reference: " + (
            "no verdict from either solver"
            if keep.status == other.status
            else "the solvers' verdicts contradict each other"
        )
    return f"kept {keep.solver}'s verdict {status}"


def combine(name: str | None, first: Candidate, second: Candidate) -> ReferenceSolution:
    """The reference made of two solvers' answers (see :func:`settle`)."""
    agreement = relative_difference(first.objective, second.objective)
    agree = first.status == second.status and (first.status != "optimal" or agreement <= AGREE_RTOL)
    keep, other, status = settle(first, second)
    verdict = "agree" if agree else "disagree"
    if first.status == second.status == "optimal":
        verdict += f" (objectives differ by {agreement:.2g} relative)"
    note = f"{first.describe()}; {second.describe()}; {verdict}; {_why(keep, other, status)}"
    if not agree:
        log.warning("reference of '%s': %s", name, note)
    ref = _from_candidate(name, keep, status)
    ref.check_solver = other.solver
    ref.check_status = other.status
    ref.check_objective = other.objective
    ref.agree = agree
    ref.agreement = agreement
    ref.check_kkt = other.kkt
    ref.note = note
    return ref
