"""Backend ``clarabel``: Clarabel (interior point) through its own Python API.

``min 1/2 x'Px + q'x  s.t.  C x + s = d,  s in K``, ``C = [A; G; -I; I]``, ``d = [b; h; -lb;
ub]``, ``K = {0}^meq x R+^(rest)``, rows with an infinite bound left out. A ``DefaultSolver``
is built once and ``update``-d while the pattern holds (docs/architecture.md, "Clarabel").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from . import register
from ._common import (
    EMPTY,
    GENERIC_KEYS,
    FiniteRows,
    StackedCsc,
    all_dense,
    all_finite,
    dense_bounds,
    finite_mask,
    own_settings,
    solver_options,
)
from .base import PersistentBackend, new_solution

if TYPE_CHECKING:
    from types import ModuleType

    import qpsolvers


class ConeLayout(FiniteRows, StackedCsc):
    """The pattern of ``P`` and ``C = [A; G_kept; -I_kept; I_kept]`` of one problem."""

    def __init__(self, problem):
        n = problem.q.shape[0]
        FiniteRows.__init__(self, problem, n)
        self.meq = 0 if problem.A is None else problem.A.shape[0]
        self.m = self.g_idx.size
        eyes = [(-1.0, self.lb_idx), (1.0, self.ub_idx)] if self.with_box else []
        StackedCsc.__init__(self, problem.P, self.blocks(problem), eyes, n)
        self.key = (self.dense, n, self.meq, self.m_all, self.with_box, self.kept, self.structure)

    def blocks(self, problem) -> list:
        """``[A; G_kept]``, the rows of ``C`` above the identity blocks."""
        blocks = [] if problem.A is None else [problem.A]
        G = problem.G
        if G is not None and self.m < self.m_all:
            G = (G if type(G) is np.ndarray else spa.csr_matrix(G))[self.g_idx]
        return blocks if G is None else blocks + [G]

    def rhs(self, problem: qpsolvers.Problem) -> np.ndarray:
        """``d = [b; h_kept; -lb_kept; ub_kept]``."""
        lb, ub = dense_bounds(problem, self.n)
        if self.all_kept and self.with_box:
            return np.concatenate([v for v in (problem.b, problem.h) if v is not None] + [-lb, ub])
        parts = [] if problem.A is None else [np.asarray(problem.b, dtype=float)]
        if problem.G is not None:
            parts.append(np.asarray(problem.h, dtype=float)[self.g_idx])
        if self.with_box:
            parts += [-lb[self.lb_idx], ub[self.ub_idx]]
        return np.concatenate(parts) if parts else EMPTY

    def cones(self, clarabel: ModuleType) -> list:
        cones = [clarabel.ZeroConeT(self.meq)] if self.meq else []
        if self.rows > self.meq:
            cones.append(clarabel.NonnegativeConeT(self.rows - self.meq))
        return cones

    def split_duals(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(y, z, z_box)`` of Clarabel's multiplier ``w``."""
        meq, n_lb = self.meq, self.lb_idx.size
        k = meq + self.m
        if self.all_kept:
            z_box = w[k + n_lb :] - w[k : k + n_lb] if self.with_box else EMPTY
            return w[:meq], w[meq:k], z_box
        return (w[:meq], *self.scatter(w[meq:k], w[k : k + n_lb], w[k + n_lb :]))


#: Clarabel status name -> our status (also used by ``qpsolvers:clarabel``).
CLARABEL_STATUSES = {
    "Solved": "optimal",
    "PrimalInfeasible": "primal_infeasible",
    "DualInfeasible": "dual_infeasible",
    "MaxIterations": "max_iter",
    "MaxTime": "time_limit",
    "NumericalError": "error",
}


def status_name(status) -> str:
    """Name of a ``clarabel.SolverStatus`` (``Solved``; older versions' ``str`` is qualified)."""
    return str(status).split(".")[-1]


def quick_key(problem: qpsolvers.Problem) -> tuple | None:
    """The :attr:`ConeLayout.key` of an all-dense problem without building the layout (else None)."""
    P, G, A = problem.P, problem.G, problem.A
    if not all_dense(P, G, A):
        return None
    n = problem.q.shape[0]
    with_box, kept = finite_mask(problem, n)
    m, meq = 0 if G is None else G.shape[0], 0 if A is None else A.shape[0]
    return (True, n, meq, m, with_box, kept.tobytes(), ())


#: Clarabel's settings for the generic ones: name -> (generic key, conversion).
_OWN_NAMES = {
    "tol_feas": ("eps_abs", float),
    "tol_gap_abs": ("eps_abs", float),
    "tol_gap_rel": ("eps_rel", float),
    "max_iter": ("max_iter", lambda k: int(min(k, 2**32 - 1))),  # Clarabel's u32
    "time_limit": ("time_limit", float),
}


@register
class ClarabelBackend(PersistentBackend):
    """Clarabel with a persistent ``DefaultSolver``, updated in place when the pattern holds."""

    name = "clarabel"
    sparse = True
    errors = (ValueError, TypeError)
    error_names = frozenset({"PanicException"})  # Rust panics (pyo3: a BaseException)
    family = "interior point"
    package = "clarabel"
    module = "clarabel"

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings and the attributes of ``clarabel.DefaultSettings()``."""
        import clarabel

        return frozenset(own_settings(clarabel.DefaultSettings()) | set(GENERIC_KEYS))

    def _settings(self, clarabel):
        s = clarabel.DefaultSettings()
        s.verbose = False
        s.presolve_enable = False  # update() needs these two
        s.input_sparse_dropzeros = False
        options = solver_options(self, "clarabel", _OWN_NAMES)
        for key, value in options.items():
            setattr(s, key, value)
        return s

    def _attempt(self, problem, warm_start):
        import clarabel

        layout = self._layout
        same = False
        if self._solver is not None and layout is not None:
            key = quick_key(problem) if layout.dense else None
            if key is None:
                key = ConeLayout(problem).key
            same = key == layout.key
        if same:
            P_data, C_data = layout.data(problem.P, layout.blocks(problem))
            self._solver.update(
                P=P_data, q=np.asarray(problem.q, dtype=float), A=C_data, b=layout.rhs(problem)
            )
        else:
            self._solver = None
            layout = ConeLayout(problem)
            P, C = layout.matrices(problem.P, layout.blocks(problem))
            solver = clarabel.DefaultSolver(
                P,
                np.asarray(problem.q, dtype=float),
                C,
                layout.rhs(problem),
                layout.cones(clarabel),
                self._settings(clarabel),
            )
            if solver.is_data_update_allowed():
                self._solver, self._layout = solver, layout
            else:
                self._layout = None
        res = (self._solver or solver).solve()
        name = status_name(res.status)
        status = CLARABEL_STATUSES.get(name, "not_solved")
        sol = new_solution(problem, status, {"raw_status": name})
        if status == "error":
            sol.error = f"Clarabel: {name}"
        sol.iterations = int(res.iterations)
        sol.solver_time_s = None if same else float(res.solve_time)
        if status in ("primal_infeasible", "dual_infeasible"):
            return sol
        x = np.array(res.x)
        if x.size == layout.n and all_finite(x):
            sol.x = x
            sol.y, sol.z, sol.z_box = layout.split_duals(np.array(res.z))
        if status == "optimal":
            sol.obj = float(res.obj_val)
        return sol
