"""Metrics of a solution against its problem and its reference solution.

For a record with problem ``(P, q, G, h, A, b, lb, ub)`` and constant ``r``
(:attr:`~qpbench.formats.ProblemRecord.offset`), :func:`evaluate` returns:

- ``objective``: ``f(x) = 1/2 x'Px + q'x + r`` computed here (``Solution.obj``
  is ``None`` for some solvers and never includes ``r``); NaN without ``x``.
- ``reference_objective``: ``f*`` of an optimal reference, else NaN.
- ``optimality_gap_signed``: ``(f(x) - f*) / max(1, |f*|)`` (dimensionless);
  ``optimality_gap``: its absolute value. NaN when either side is missing.
- ``primal_residual``, ``dual_residual``, ``duality_gap``: qpsolvers'
  :meth:`~qpsolvers.Solution.primal_residual`, ``dual_residual`` and
  ``duality_gap`` on the solution as given (``inf`` when ``found`` is false or
  the duals are missing, as qpsolvers defines them).
- constraint violation of ``x``, whether the backend reported ``found`` or
  not (so a baseline that ignores constraints, a solver stopped at its
  iteration limit or the online network, whose answers are not ``found``, shows
  how far off it is); absolute, in the problem's units, NaN without ``x``
  (:func:`constraint_violation`):

  - ``violation_ineq``: ``max_i max(0, (G x - h)_i)``;
  - ``violation_eq``: ``max_i |(A x - b)_i|``;
  - ``violation_box``: ``max_i max(0, lb_i - x_i, x_i - ub_i)``;
  - ``constraint_violation``: the largest of the three (0 for a problem
    without constraints). It equals qpsolvers' primal residual of a found
    solution.
- ``status``, ``found``: as reported by the backend (``status`` of a
  :class:`~qpbench.backends.base.BackendSolution`, or ``extras["status"]`` when
  it is one of :data:`STATUSES`; for a plain ``qpsolvers.Solution``,
  ``optimal`` if found else ``not_solved``).
- ``success``: the rule below.

Success rule (qpbenchmark's, plus the reference):

- reference ``primal_infeasible`` or ``dual_infeasible``: success iff the
  backend reported that same status (a solution "found" there is wrong);
- otherwise: ``found`` and ``primal_residual <= tol.primal`` and
  ``dual_residual <= tol.dual`` and ``duality_gap <= tol.gap``, and, when the
  reference is ``optimal``, ``optimality_gap <= tol.gap``, i.e.
  ``|f(x) - f*| <= tol.gap * max(1, |f*|)``: absolute for objectives below 1
  in magnitude, relative above. A reference with status ``unknown`` (or no
  reference) adds no condition.
"""

from __future__ import annotations

import math

import numpy as np

INFEASIBLE_STATUSES = ("primal_infeasible", "dual_infeasible")
#: Statuses a backend reports (same list as :data:`qpbench.backends.base.STATUSES`).
STATUSES = (
    "optimal", "primal_infeasible", "dual_infeasible", "max_iter", "time_limit", "error", "not_solved",
)


def objective(record, x: np.ndarray | None) -> float:
    """``1/2 x'Px + q'x + offset`` of ``record`` at ``x`` (NaN when ``x`` is None)."""
    if x is None:
        return math.nan
    x = np.asarray(x, dtype=np.float64)
    P, q = record.problem.P, record.problem.q
    return float(0.5 * x @ (P @ x) + q @ x + record.offset)


def solution_status(solution) -> str | None:
    """The backend's status string, if it reported one."""
    if solution is None:
        return None
    status = getattr(solution, "status", None)
    if status is None:
        status = (solution.extras or {}).get("status")
    if isinstance(status, str) and status in STATUSES:
        return status
    # a plain qpsolvers.Solution: its extras hold the solver's own status type
    return "optimal" if solution.found else "not_solved"


#: Keys of :func:`constraint_violation`'s answer (also bench CSV columns).
VIOLATION_KEYS = ("violation_ineq", "violation_eq", "violation_box", "constraint_violation")


def _dense(M):
    """``M`` as it is when scipy.sparse (``M @ x`` is sparse-times-vector), else a float array."""
    return M if hasattr(M, "toarray") else np.asarray(M, dtype=np.float64)


def constraint_violation(problem, x: np.ndarray | None) -> dict:
    """How far ``x`` is from satisfying ``problem``'s constraints (absolute, problem units).

    Args:
        problem: ``qpsolvers.Problem`` with ``G, h, A, b, lb, ub`` (any may be ``None``).
        x: Primal point of shape (n,), or ``None``.

    Returns:
        ``{"violation_ineq": max(0, max(G x - h)), "violation_eq": max|A x - b|,
        "violation_box": max(0, max(lb - x), max(x - ub)), "constraint_violation":
        the largest of the three}``; a part the problem lacks is 0; all NaN
        when ``x`` is ``None``. A non-finite ``x`` gives ``inf`` or NaN as
        arithmetic does.
    """
    if x is None:
        return dict.fromkeys(VIOLATION_KEYS, math.nan)
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    ineq = eq = box = 0.0
    if problem.G is not None and problem.h is not None and np.size(problem.h):
        ineq = max(0.0, float(np.max(_dense(problem.G) @ x - np.asarray(problem.h, dtype=np.float64))))
    if problem.A is not None and problem.b is not None and np.size(problem.b):
        eq = float(np.max(np.abs(_dense(problem.A) @ x - np.asarray(problem.b, dtype=np.float64))))
    with np.errstate(invalid="ignore"):  # inf - inf of an infinite bound at an infinite x
        if problem.lb is not None and np.size(problem.lb):
            low = np.asarray(problem.lb, dtype=np.float64) - x
            low = low[~np.isnan(low)]
            box = max(box, float(np.max(low, initial=0.0)))
        if problem.ub is not None and np.size(problem.ub):
            high = x - np.asarray(problem.ub, dtype=np.float64)
            high = high[~np.isnan(high)]
            box = max(box, float(np.max(high, initial=0.0)))
    return {
        "violation_ineq": ineq,
        "violation_eq": eq,
        "violation_box": box,
        "constraint_violation": max(ineq, eq, box),
    }


def _qpsolvers_metrics(solution) -> tuple[float, float, float]:
    if solution is None:
        return math.inf, math.inf, math.inf
    primal = float(solution.primal_residual())
    dual = float(solution.dual_residual())
    gap = float(solution.duality_gap())
    return primal, dual, gap


def evaluate(record, solution, reference, tolerance) -> dict:
    """Score ``solution`` of ``record`` against ``reference`` under ``tolerance``.

    Args:
        record: :class:`~qpbench.formats.ProblemRecord` that was solved.
        solution: ``qpsolvers.Solution`` (or a subclass) whose ``problem`` is the
            record's problem; ``None`` when the backend returned nothing.
        reference: :class:`~qpbench.reference.ReferenceSolution` or ``None``.
        tolerance: :class:`~qpbench.profiles.Tolerance` (``primal``, ``dual``, ``gap``).

    Returns:
        A dict with the keys listed in the module docstring.
    """
    primal, dual, gap = _qpsolvers_metrics(solution)
    x = None if solution is None else solution.x
    violation = constraint_violation(record.problem, x)
    obj = objective(record, x)
    found = bool(solution is not None and solution.found)
    status = solution_status(solution)
    ref_status = None if reference is None else reference.status
    ref_obj = reference.objective if ref_status == "optimal" else math.nan
    if math.isnan(obj) or ref_obj is None or math.isnan(ref_obj):
        signed = math.nan
    else:
        signed = (obj - ref_obj) / max(1.0, abs(ref_obj))
    if ref_status in INFEASIBLE_STATUSES:
        success = status == ref_status
    else:
        success = (
            found
            and primal <= tolerance.primal
            and dual <= tolerance.dual
            and gap <= tolerance.gap
        )
        if success and ref_status == "optimal":
            success = abs(signed) <= tolerance.gap
    return {
        "status": status,
        "found": found,
        "objective": obj,
        "reference_objective": float(ref_obj) if ref_obj is not None else math.nan,
        "reference_status": ref_status,
        "optimality_gap": abs(signed),
        "optimality_gap_signed": signed,
        "primal_residual": primal,
        "dual_residual": dual,
        "duality_gap": gap,
        **violation,
        "success": bool(success),
    }
