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
- ``constraint_violation``: qpsolvers' primal residual of ``x`` even when the
  backend did not report ``found`` (so a baseline that ignores constraints, or a
  solver stopped at its iteration limit, shows how far off it is); ``inf``
  without ``x``.
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

import dataclasses
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


def _qpsolvers_metrics(solution) -> tuple[float, float, float, float]:
    if solution is None:
        return math.inf, math.inf, math.inf, math.inf
    primal = float(solution.primal_residual())
    dual = float(solution.dual_residual())
    gap = float(solution.duality_gap())
    if solution.x is None:
        violation = math.inf
    elif solution.found:
        violation = primal
    else:
        violation = float(dataclasses.replace(solution, found=True).primal_residual())
    return primal, dual, gap, violation


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
    primal, dual, gap, violation = _qpsolvers_metrics(solution)
    x = None if solution is None else solution.x
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
        "constraint_violation": violation,
        "success": bool(success),
    }
