"""Backend ``cvxpy``: the modelling-layer route, a parametrised cvxpy model re-solved with new values.

Model, built once per shape, the rows and bounds with an infinite right-hand side left out::

    minimize    1/2 ||L' x||^2 + q' x          P = L L'
    subject to  A x == b,  G_f x <= h_f,  x[i_l] >= lb_f,  x[i_u] <= ub_f

(``quad_form(x, P)`` with a parameter ``P`` is not DPP). Solver: OSQP (Clarabel when OSQP is
missing) with :func:`~qpbench.backends._common.native_settings`, ``warm_start=True``.
"""

from __future__ import annotations

import warnings

import numpy as np

from . import register
from ._common import FiniteRows, as_dense, dense_bounds, generic_settings, native_settings
from .base import Backend, BackendSolution, error_solution


def cost_factor(P: np.ndarray) -> np.ndarray:
    """``L`` with ``L L' = P`` for a symmetric positive semidefinite ``P``."""
    try:
        return np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(0.5 * (P + P.T))
        return V * np.sqrt(np.maximum(w, 0.0))


class _Model:
    """The parametrised cvxpy problem of one shape and one set of finite rows."""

    def __init__(self, cp, n: int, meq: int, rows: FiniteRows):
        self.x = x = cp.Variable(n)
        self.L = cp.Parameter((n, n))
        self.q = cp.Parameter(n)
        self.eq = self.ineq = self.lower = self.upper = None
        if meq:
            self.A, self.b = cp.Parameter((meq, n)), cp.Parameter(meq)
            self.eq = self.A @ x == self.b
        g_idx, lb_idx, ub_idx = rows.g_idx, rows.lb_idx, rows.ub_idx
        if g_idx.size:
            self.G, self.h = cp.Parameter((g_idx.size, n)), cp.Parameter(g_idx.size)
            self.ineq = self.G @ x <= self.h
        if lb_idx.size:
            self.lb = cp.Parameter(lb_idx.size)
            self.lower = x[lb_idx] >= self.lb
        if ub_idx.size:
            self.ub = cp.Parameter(ub_idx.size)
            self.upper = x[ub_idx] <= self.ub
        constraints = [c for c in (self.eq, self.ineq, self.lower, self.upper) if c is not None]
        objective = cp.Minimize(0.5 * cp.sum_squares(self.L.T @ x) + self.q @ x)
        self.problem = cp.Problem(objective, constraints)

    def set_values(self, problem, rows: FiniteRows, lb, ub) -> None:
        self.L.value = cost_factor(as_dense(problem.P))
        self.q.value = np.asarray(problem.q, dtype=float)
        if self.eq is not None:
            self.A.value = as_dense(problem.A)
            self.b.value = np.asarray(problem.b, dtype=float)
        if self.ineq is not None:
            self.G.value = as_dense(problem.G)[rows.g_idx]
            self.h.value = np.asarray(problem.h, dtype=float)[rows.g_idx]
        if self.lower is not None:
            self.lb.value = lb[rows.lb_idx]
        if self.upper is not None:
            self.ub.value = ub[rows.ub_idx]

    def duals(self, rows: FiniteRows):
        def value(c):
            return (
                np.zeros(0)
                if c is None or c.dual_value is None
                else np.atleast_1d(np.asarray(c.dual_value, float))
            )

        return (value(self.eq), *rows.scatter(*map(value, (self.ineq, self.lower, self.upper))))


@register
class CvxpyBackend(Backend):
    """A cached, parametrised cvxpy model per problem shape, on cvxpy's default QP solver."""

    name = "cvxpy"
    certifies_infeasibility = True
    family = "modelling layer (OSQP: ADMM)"
    package = "cvxpy"
    module = "cvxpy"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._models: dict[tuple, _Model] = {}
        self._options: tuple[str, dict] | None = None

    def reset(self) -> None:
        self._models = {}

    def _solver_options(self, cp) -> tuple[str, dict]:
        generic, native = generic_settings(self)
        if "OSQP" in cp.installed_solvers():
            options = native_settings("osqp", **generic)
            options["polish"] = options.pop("polishing", False)  # cvxpy's name
            return "OSQP", {**options, **native}
        return "CLARABEL", {**native_settings("clarabel", **generic), **native}

    def _solve(self, problem, warm_start):
        import cvxpy as cp

        sol = BackendSolution(problem)
        n = np.shape(problem.q)[0]
        meq = 0 if problem.A is None else problem.A.shape[0]
        rows = FiniteRows(problem, n)
        key = (n, meq, rows.kept)
        model = self._models.get(key)
        if model is None:
            model = self._models[key] = _Model(cp, n, meq, rows)
        model.set_values(problem, rows, *dense_bounds(problem, n))
        if warm_start is not None:
            model.x.value = np.asarray(warm_start, dtype=float)
        if self._options is None:  # cp.installed_solvers() takes milliseconds
            self._options = self._solver_options(cp)
        solver, options = self._options
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "Solution may be inaccurate": the status says it
                model.problem.solve(solver=solver, warm_start=True, verbose=False, **options)
        except cp.error.SolverError as exc:
            return error_solution(problem, exc)
        raw = model.problem.status
        status = {
            cp.OPTIMAL: "optimal",
            cp.INFEASIBLE: "primal_infeasible",
            cp.UNBOUNDED: "dual_infeasible",
            cp.USER_LIMIT: "max_iter",
        }.get(raw, "not_solved")
        stats = model.problem.solver_stats
        if (
            status == "not_solved"
            and stats.num_iters is not None
            and stats.num_iters >= options.get("max_iter", np.inf)
        ):
            status = "max_iter"  # cvxpy reports OSQP's iteration limit as "optimal_inaccurate"
        sol.status = status
        sol.extras = {"raw_status": raw, "solver": stats.solver_name}
        sol.iterations = None if stats.num_iters is None else int(stats.num_iters)
        sol.solver_time_s = stats.solve_time
        if status in ("primal_infeasible", "dual_infeasible"):
            return sol
        if model.x.value is not None and np.all(np.isfinite(model.x.value)):
            sol.x = np.array(model.x.value, dtype=float)
            sol.y, sol.z, sol.z_box = model.duals(rows)
        return sol
