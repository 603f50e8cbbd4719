"""Metrics of a solution against its problem and its reference solution: the per-tick metrics,
functions of one :class:`Tick` registered with :func:`per_tick_metric` in column order, are a
bench CSV's metric columns (meanings: docs/methodology.md); :func:`evaluate` scores a solve.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .published import qpbenchmark_success
from .statuses import CERTIFIED_INFEASIBLE, STATUSES

if TYPE_CHECKING:
    import qpsolvers

    from .formats import ProblemRecord
    from .profiles import Tolerance


def objective(record: ProblemRecord, x: np.ndarray | None) -> float:
    """``1/2 x'Px + q'x + offset`` of ``record`` at ``x`` (NaN when ``x`` is None)."""
    if x is None:
        return math.nan
    x = np.asarray(x, dtype=np.float64)
    P, q = record.problem.P, record.problem.q
    return float(0.5 * x @ (P @ x) + q @ x + record.offset)


#: Keys of :func:`constraint_violation`'s answer (also bench CSV columns).
VIOLATION_KEYS = ("constraint_violation", "violation_ineq", "violation_eq", "violation_box")


def _excess(M, v, x: np.ndarray) -> np.ndarray | None:
    """``M x - v`` (``None`` for rows the problem lacks); scipy.sparse ``M`` kept sparse."""
    if M is None or v is None or not np.size(v):
        return None
    M = M if hasattr(M, "toarray") else np.asarray(M, dtype=np.float64)
    return M @ x - np.asarray(v, dtype=np.float64)


def constraint_violation(problem: qpsolvers.Problem, x: np.ndarray | None) -> dict:
    """How far ``x`` is from satisfying ``problem``'s constraints (absolute, problem units):
    ``violation_ineq = max(0, max(G x - h))``, ``violation_eq = max|A x - b|``,
    ``violation_box = max(0, max(lb - x), max(x - ub))``, ``constraint_violation`` the largest."""
    if x is None:
        return dict.fromkeys(VIOLATION_KEYS, math.nan)
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    ineq, eq = _excess(problem.G, problem.h, x), _excess(problem.A, problem.b, x)
    ineq = 0.0 if ineq is None else max(0.0, float(np.max(ineq)))
    eq = 0.0 if eq is None else float(np.max(np.abs(eq)))
    box = 0.0
    with np.errstate(invalid="ignore"):  # inf - inf of an infinite bound at an infinite x
        for lower, upper in ((problem.lb, x), (x, problem.ub)):
            if lower is not None and upper is not None and np.size(lower) and np.size(upper):
                d = np.asarray(lower, dtype=np.float64) - np.asarray(upper, dtype=np.float64)
                box = max(box, float(np.max(d[~np.isnan(d)], initial=0.0)))
    return dict(zip(VIOLATION_KEYS, (max(ineq, eq, box), ineq, eq, box)))


@dataclass
class Tick:
    """What a per-tick metric reads (``None`` when missing); ``values``: the metrics before it."""

    record: object
    solution: object
    x: np.ndarray | None
    reference: object
    reference_status: str | None
    values: dict = field(default_factory=dict)


#: The per-tick metrics in column order: ``{columns: function}`` (several columns: a dict).
PER_TICK_METRICS: dict[tuple[str, ...], Callable[[Tick], object]] = {}


def per_tick_metric(
    fn: Callable | None = None, *, columns: tuple[str, ...] | None = None
) -> Callable:
    """Register ``fn(tick) -> value`` as a per-tick metric named after its column (or a dict of
    ``columns``); a registered name is replaced in place."""

    def add(f: Callable) -> Callable:
        cols = tuple(columns) if columns else (f.__name__,)
        taken = set(metric_columns()) & set(cols)
        if taken and cols not in PER_TICK_METRICS:
            raise ValueError(f"metric column(s) {', '.join(sorted(taken))} already registered")
        PER_TICK_METRICS[cols] = f
        return f

    return add(fn) if fn is not None else add


def metric_columns() -> tuple[str, ...]:
    """The bench CSV's metric columns, in order."""
    return tuple(c for cols in PER_TICK_METRICS for c in cols)


@per_tick_metric(columns=("objective",))
def _objective(tick: Tick) -> float:
    return objective(tick.record, tick.x)


@per_tick_metric(
    columns=("reference_objective", "reference_status", "reference_agreement", "reference_note")
)
def _reference(tick: Tick) -> dict:
    """The reference's objective (NaN unless optimal), status, agreement and note."""
    ref, status = tick.reference, tick.reference_status
    return {
        "reference_objective": float(ref.objective) if status == "optimal" else math.nan,
        "reference_status": status,
        "reference_agreement": None if ref is None else float(ref.agreement),
        "reference_note": getattr(ref, "note", None),
    }


def _signed_gap(values: dict) -> float:
    obj, ref = values["objective"], values["reference_objective"]
    if math.isnan(obj) or math.isnan(ref):
        return math.nan
    return (obj - ref) / max(1.0, abs(ref))


@per_tick_metric
def optimality_gap(tick: Tick) -> float:
    return abs(_signed_gap(tick.values))


_RESIDUALS = ("primal_residual", "dual_residual", "duality_gap")


@per_tick_metric(columns=_RESIDUALS)
def residuals(tick: Tick) -> dict:
    """qpsolvers' residuals and duality gap (``inf`` without a solution)."""
    sol = tick.solution
    return {k: math.inf if sol is None else float(getattr(sol, k)()) for k in _RESIDUALS}


@per_tick_metric(columns=VIOLATION_KEYS)
def _violation(tick: Tick) -> dict:
    return constraint_violation(tick.record.problem, tick.x)


def evaluate(
    record: ProblemRecord,
    solution: qpsolvers.Solution | None,
    reference: object | None,
    tolerance: Tolerance,
) -> dict:
    """Score ``solution`` (``None``: nothing returned) of ``record`` against ``reference`` under
    ``tolerance``: ``status``, ``found``, every per-tick metric, ``optimality_gap_signed`` and
    ``success``: the reference's infeasibility status if it has one; else ``found``, residuals
    within the tolerance and ``optimality_gap <= tolerance.gap`` against an optimal reference
    (``rule == "qpbenchmark"``: :func:`qpbench.published.qpbenchmark_success`)."""
    x = getattr(solution, "x", None)
    tick = Tick(record, solution, x, reference, getattr(reference, "status", None))
    for columns, fn in PER_TICK_METRICS.items():
        value = fn(tick)
        tick.values.update(
            {c: value[c] for c in columns} if len(columns) > 1 else {columns[0]: value}
        )
    m = tick.values
    found = bool(solution is not None and solution.found)
    status = getattr(solution, "status", None)  # a plain qpsolvers.Solution has none
    if solution is not None and status not in STATUSES:
        status = "optimal" if found else "not_solved"
    signed = _signed_gap(m)
    res = tuple(m[k] for k in _RESIDUALS)
    if tolerance.rule == "qpbenchmark":
        success = qpbenchmark_success(found, *res, tolerance)
    elif tick.reference_status in CERTIFIED_INFEASIBLE:
        success = status == tick.reference_status
    else:
        limits = (tolerance.primal, tolerance.dual, tolerance.gap)
        success = found and all(v <= t for v, t in zip(res, limits))
        if success and tick.reference_status == "optimal":
            success = abs(signed) <= tolerance.gap
    return {
        "status": status,
        "found": found,
        **m,
        "optimality_gap_signed": signed,
        "success": bool(success),
    }
