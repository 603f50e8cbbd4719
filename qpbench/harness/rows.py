"""One bench CSV row from a record, a backend's outcome and the record's reference."""

from __future__ import annotations

import statistics

import numpy as np

from ..profiles import Profile
from ..statuses import FAILURE_STATUSES
from .bench_summary import _float


def _n_box(problem) -> int:
    n = 0
    if problem.lb is not None:
        n += int(np.isfinite(np.asarray(problem.lb, dtype=float)).sum())
    if problem.ub is not None:
        n += int(np.isfinite(np.asarray(problem.ub, dtype=float)).sum())
    return n


class _RowMaker:
    """Builds a row from a record, a backend outcome and the record's reference."""

    def __init__(self, problem_set, profile: Profile, mode: str, sha: str | None, versions: dict):
        from ..formats import problem_sizes

        self.problem_sizes = problem_sizes
        self.profile = profile
        self.mode = mode
        self.sha = sha or ""
        self.versions = versions

    def __call__(
        self,
        record,
        backend: str,
        outcome,
        reference,
        position: int | None = None,
        seed: int | None = None,
    ) -> dict:
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
            "solver_time_s": _float(getattr(sol, "solver_time_s", None))
            if outcome.solution is not None
            else None,
            "iterations": getattr(outcome.solution, "iterations", None)
            if outcome.solution is not None
            else None,
            "error": error,
            "state_reset": outcome.state_reset,
            "isolated": outcome.isolated,
            "position": position,
            "order_seed": seed,
            "repeat": len(times),
            "repeat_exact": outcome.repeat_exact,
            "repeat_note": outcome.repeat_note or None,
            "n": n,
            "m_eq": m_eq,
            "m_ineq": m_ineq,
            "n_box": _n_box(record.problem),
            "problem_set_sha256": self.sha,
            "backend_version": self.versions.get(backend),
        }
