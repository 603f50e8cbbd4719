"""The one vocabulary of solve outcomes, and :func:`classify`, which the per-tick guard and the
closed loop both use."""

from __future__ import annotations

import numpy as np

#: Statuses a backend reports.
STATUSES = (
    "optimal",
    "primal_infeasible",
    "dual_infeasible",
    "max_iter",
    "time_limit",
    "error",
    "not_solved",
)

#: Statuses only the harness gives: ``invalid`` (no finite answer) and ``crashed`` (worker died).
GUARD_STATUSES = ("invalid", "crashed")

#: Categories of a closed-loop tick log's ``status`` column (no worker process there).
TICK_STATUSES = STATUSES + ("invalid",)

#: The backend proved the QP has no solution.
CERTIFIED_INFEASIBLE = ("primal_infeasible", "dual_infeasible")

#: A certificate of infeasibility, or ``not_solved`` (a failure the backend cannot classify).
INFEASIBLE_OR_UNCLASSIFIED = CERTIFIED_INFEASIBLE + ("not_solved",)

#: A failure whatever the reference says; the backend is reset after one.
FAILURE_STATUSES = frozenset({"error", "time_limit", "invalid", "crashed"})

#: The controller's QP formulations: ``paper`` (hard task equality, eq. 11) and ``soft``.
FORMULATIONS = ("paper", "soft")


def describe_exception(exc: BaseException) -> str:
    """``"Type: message"`` on one line (``"Type"`` when the message is empty)."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def classify(solution: object, wall_s: float, time_limit: float) -> tuple[str, str | None]:
    """Status and error text of an answer returned in ``wall_s`` [s]: ``invalid`` for a
    non-finite ``x`` or ``optimal`` without one, ``time_limit`` past ``time_limit`` [s], else
    the backend's status."""
    status = getattr(solution, "status", None) or (
        "optimal" if getattr(solution, "found", False) else "not_solved"
    )
    x = getattr(solution, "x", None)
    if x is not None:
        x = np.asarray(x, dtype=float)
        finite = np.isfinite(x)
        if not finite.all():
            return (
                "invalid",
                f"non-finite x ({int((~finite).sum())} of {x.size} entries; backend status {status})",
            )
    elif status == "optimal":
        return "invalid", "status optimal without a primal solution x"
    if wall_s > time_limit:
        return (
            "time_limit",
            f"solve took {wall_s:.3g} s > time limit {time_limit:g} s (backend status {status})",
        )
    return status, getattr(solution, "error", None)
