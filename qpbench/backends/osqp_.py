"""Backend ``osqp``: OSQP (ADMM) through its own Python API.

``min 1/2 x'Px + q'x  s.t.  l <= C x <= u``, ``C = [G; A; I]`` (``I`` only with bounds), ``l =
[-inf; b; lb]``, ``u = [h; b; ub]``; set up once, ``update``-d while shape and pattern hold.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from . import register
from ._common import (
    EMPTY,
    GENERIC_KEYS,
    StackedCsc,
    all_dense,
    all_finite,
    dense_bounds,
    solver_module,
    solver_options,
)
from .base import PersistentBackend, new_solution

if TYPE_CHECKING:
    import qpsolvers


class StackedLayout(StackedCsc):
    """The pattern of ``P`` and ``C = [G; A; I]`` of one problem shape (``I`` with ``with_box``)."""

    def __init__(self, problem, with_box: bool):
        G, A = problem.G, problem.A
        n = problem.q.shape[0]
        self.m = 0 if G is None else G.shape[0]
        self.meq = 0 if A is None else A.shape[0]
        self.with_box = with_box
        super().__init__(problem.P, _blocks(problem), [(1.0, np.arange(n))] if with_box else [], n)
        k = self.m + self.meq
        #: Where ``y``, ``z`` and ``z_box`` lie in OSQP's multiplier of ``[G; A; I]``.
        self.parts = (slice(self.m, k), slice(0, self.m), slice(k, None))
        self.key = (self.dense, n, self.m, self.meq, with_box, self.structure)
        #: (P, G, A) shapes of a problem :meth:`tick_data` takes: dense, every block there.
        self.tick_shapes = None
        if self.dense and self.m and self.meq and with_box:
            self.tick_shapes = ((n, n), (self.m, n), (self.meq, n))
            rows, cols = self.P_index
            self._P_flat = rows * n + cols
            self._CT = np.empty((n, k + 1))  # C' in C order: its ravel is C's data
            self._CT[:, k] = 1.0
            self._l = np.empty(self.rows)
            self._l[: self.m] = -np.inf

    def tick_data(self, P, G, h, A, b, lb, ub) -> tuple[np.ndarray, ...]:
        """``(l, u, Px, Ax)`` of ``OSQP.update`` for a problem of :attr:`tick_shapes`, ``C``'s
        data and ``l`` written into buffers kept here (OSQP copies what ``update`` is given)."""
        m, k = self.m, self.m + self.meq
        CT, l = self._CT, self._l
        CT[:, :m] = G.T
        CT[:, m:k] = A.T
        l[m:k] = b
        l[k:] = lb
        return l, np.concatenate((h, b, ub)), P.take(self._P_flat), CT.ravel()

    def vectors(self, problem: qpsolvers.Problem) -> tuple[np.ndarray, np.ndarray]:
        """``(l, u)`` of the stacked rows ``[G; A; I]``."""
        h, b = (None if v is None else np.asarray(v, dtype=float) for v in (problem.h, problem.b))
        lb = ub = None
        if self.with_box:
            lb, ub = dense_bounds(problem, self.n)
            if lb is None:  # free rows of an unconstrained problem
                lb, ub = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        lower = None if problem.G is None else np.full(self.m, -np.inf)
        return _stack(lower, b, lb), _stack(h, b, ub)

    def split_duals(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(y, z, z_box)`` of the stacked multiplier ``w`` (views into ``w``)."""
        part_y, part_z, part_box = self.parts
        return w[part_y], w[part_z], w[part_box] if self.with_box else EMPTY


def _blocks(problem) -> list:
    return [M for M in (problem.G, problem.A) if M is not None]


def _stack(*vectors) -> np.ndarray:
    vectors = [v for v in vectors if v is not None]
    return np.concatenate(vectors) if vectors else EMPTY


#: OSQP's status name -> our status (also read by ``qpsolvers:osqp``).
OSQP_STATUSES = {
    "OSQP_SOLVED": "optimal",
    "OSQP_PRIMAL_INFEASIBLE": "primal_infeasible",
    "OSQP_DUAL_INFEASIBLE": "dual_infeasible",
    "OSQP_MAX_ITER_REACHED": "max_iter",
    "OSQP_TIME_LIMIT_REACHED": "time_limit",
    "OSQP_NON_CVX": "error",
}


def status_name(status_val: int) -> str:
    """OSQP's name of a ``status_val``."""
    return _osqp().SolverStatus(status_val).name


def _has_box(problem) -> bool:
    """Whether ``C`` has the identity rows: with bounds, or with no other rows (OSQP needs a
    row per column: an unconstrained problem gets free rows ``-inf <= x <= inf``)."""
    if problem.lb is not None or problem.ub is not None:
        return True
    no_G = problem.G is None or problem.G.shape[0] == 0
    no_A = problem.A is None or problem.A.shape[0] == 0
    return no_G and no_A


@register
class OsqpBackend(PersistentBackend):
    """OSQP through ``osqp.OSQP`` with a persistent, updated solver object."""

    name = "osqp"
    sparse = True
    error_names = frozenset({"OSQPException"})
    family = "ADMM"
    package = "osqp"
    module = "osqp"

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings, OSQP's ``OSQPSettings`` fields and the names it translates."""
        import osqp

        own = {k for k in type(osqp.OSQP().ext.OSQPSettings()).__dict__ if not k.startswith("_")}
        return frozenset(
            own | {"polish", "warm_start", "solver_type", "cg_preconditioner"} | set(GENERIC_KEYS)
        )

    def _settings(self) -> dict:
        return {"verbose": False, **solver_options(self, "osqp")}

    def _attempt(self, problem, warm_start):
        P, G, A, lb, ub = problem.P, problem.G, problem.A, problem.lb, problem.ub
        layout = self._layout
        if (
            layout is not None
            and layout.tick_shapes is not None
            and type(P) is _ndarray
            and type(G) is _ndarray
            and type(A) is _ndarray
            and lb is not None
            and ub is not None
            and (P.shape, G.shape, A.shape) == layout.tick_shapes
        ):  # a robot tick: every block dense, of the kept shape
            l, u, Px, Ax = layout.tick_data(P, G, problem.h, A, problem.b, lb, ub)
            self._solver.update(q=problem.q, l=l, u=u, Px=Px, Ax=Ax)
        else:
            layout = self._update_or_setup(problem)
        if warm_start is not None:
            self._solver.warm_start(x=np.asarray(warm_start, dtype=float))
        res = self._solver.solve(raise_error=False)
        info = res.info
        status = OSQP_STATUSES.get(status_name(info.status_val), "not_solved")
        sol = new_solution(problem, status, {"raw_status": info.status, "info": info})
        sol.iterations = info.iter
        sol.solver_time_s = info.run_time
        if status == "error":
            sol.error = f"OSQP: {info.status}"
        if status in ("primal_infeasible", "dual_infeasible"):
            sol.extras["prim_inf_cert"] = np.array(res.prim_inf_cert)
            sol.extras["dual_inf_cert"] = np.array(res.dual_inf_cert)
            return sol
        x = res.x
        if x is not None and all_finite(x):  # OSQP 1.x hands back fresh arrays: no copy
            sol.x = x
            sol.y, sol.z, sol.z_box = layout.split_duals(res.y)
        if status == "optimal":
            sol._obj = info.obj_val
        return sol

    def _update_or_setup(self, problem) -> StackedLayout:
        """Update the kept solver when shape and pattern fit, else set up a new one; the layout."""
        with_box = _has_box(problem)
        layout = self._layout
        reuse = False
        if self._solver is not None and layout is not None and layout.with_box == with_box:
            if layout.dense:
                reuse = all_dense(problem.P, problem.G, problem.A) and (
                    layout.n == problem.q.shape[0]
                    and layout.m == (0 if problem.G is None else problem.G.shape[0])
                    and layout.meq == (0 if problem.A is None else problem.A.shape[0])
                )
            else:
                reuse = StackedLayout(problem, with_box).key == layout.key
        if reuse:
            P_data, C_data = layout.data(problem.P, _blocks(problem))
            l, u = layout.vectors(problem)
            self._solver.update(q=problem.q, l=l, u=u, Px=P_data, Ax=C_data)
            return layout
        self._solver = None
        layout = StackedLayout(problem, with_box)
        P, C = layout.matrices(problem.P, _blocks(problem))
        l, u = layout.vectors(problem)
        solver = _osqp().OSQP()
        solver.setup(P=P, q=np.asarray(problem.q, dtype=float), A=C, l=l, u=u, **self._settings())
        self._solver, self._layout = solver, layout
        return layout


_ndarray = np.ndarray
_osqp = partial(solver_module, "osqp")
