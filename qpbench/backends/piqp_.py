"""Backend ``piqp``: PIQP (proximal interior point) through its own dense and sparse APIs.

``piqp.DenseSolver`` with ``h_l = -inf``, ``z = z_u - z_l``, ``z_box = z_bu - z_bl``; a problem
:func:`~qpbench.backends._common.dense_route` sends to the sparse API goes to
``piqp.SparseSolver`` (``P``'s upper triangle). The solver is ``setup`` once per shape (per
structure when sparse), then ``update``-d; a status other than optimal drops it.
``warm_start`` is ignored.
"""

from __future__ import annotations

from functools import cache, partial

from . import register
from ._common import (
    EMPTY,
    GENERIC_KEYS,
    check_shapes,
    dense_route,
    own_settings,
    refuse_unknown,
    shapes,
    solver_module,
    solver_options,
    sparse_parts,
    structure_key,
)
from .base import BackendSolution, PersistentBackend, new_solution

#: PIQP's status name -> our status (also read by ``qpsolvers:piqp``).
PIQP_STATUSES = {
    "PIQP_SOLVED": "optimal",
    "PIQP_PRIMAL_INFEASIBLE": "primal_infeasible",
    "PIQP_DUAL_INFEASIBLE": "dual_infeasible",
    "PIQP_MAX_ITER_REACHED": "max_iter",
    "PIQP_NUMERICS": "error",
    "PIQP_INVALID_SETTINGS": "error",
}

_piqp = partial(solver_module, "piqp")


@cache
def _solved() -> int:
    """``piqp.PIQP_SOLVED.value``: an int compares faster than the enum, whose ``name`` is slower."""
    return _piqp().PIQP_SOLVED.value


@register
class PiqpBackend(PersistentBackend):
    """PIQP dense with a persistent ``DenseSolver``, updated per tick."""

    name = "piqp"
    errors = (ValueError, TypeError, RuntimeError)
    family = "proximal interior point"
    package = "piqp"
    module = "piqp"
    sparse = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings and PIQP's own (dense and sparse solvers' settings)."""
        piqp = _piqp()
        own = own_settings(piqp.DenseSolver().settings) | own_settings(piqp.SparseSolver().settings)
        return frozenset(own | set(GENERIC_KEYS))

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        options = solver_options(self, "piqp")
        allowed = sorted(a for a in dir(_piqp().DenseSolver().settings) if not a.startswith("_"))
        refuse_unknown("piqp", options, allowed, "PIQP's own")
        self._settings_dict = {"verbose": False, "compute_timings": True, **options}

    def reset(self) -> None:
        self._solver = self._key = self._info = None
        self._views = None  # (x, y, z_l, z_u, z_bl, z_bu): numpy views of the live result

    def _attempt(self, problem, warm_start):
        parts = dense_route(problem)
        if parts is None:
            return self._solve_sparse(problem)
        P, q, A, b, G, h, lb, ub = parts
        # PIQP keeps its old data on an update of another shape: updated only on the same shapes
        return self._run(problem, None, shapes(P, q, A, b, G, h, lb, ub), P, q, A, b, G, h, lb, ub)

    def _solve_sparse(self, problem):
        """The sparse route: ``piqp.SparseSolver`` kept per structure (upper triangle of ``P``)."""
        P, q, A, b, G, h, lb, ub = sparse_parts(problem, upper=True)
        # every shape: the kept solver's were checked at its set-up
        key = ("sparse", shapes(P, q, A, b, G, h, lb, ub), structure_key(P, A, G))
        return self._run(problem, _piqp().SparseSolver, key, P, q, A, b, G, h, lb, ub)

    def _run(self, problem, cls, key, P, q, A, b, G, h, lb, ub) -> BackendSolution:
        """Update the kept solver set up for ``key``, else set up a new ``cls`` (``None``:
        ``DenseSolver``) after checking the shapes; solve."""
        solver = self._solver
        if solver is not None and key == self._key:
            solver.update(P, q, A, b, G, None, h, lb, ub)
        else:
            check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            self.reset()
            solver = (cls or _piqp().DenseSolver)()
            for name, value in self._settings_dict.items():
                setattr(solver.settings, name, value)
            solver.setup(P, q, A, b, G, None, h, lb, ub)
            self._solver, self._key = solver, key
            res = solver.result
            self._info = res.info
            # update() and solve() overwrite the vectors these views show (each read builds one)
            self._views = (res.x, res.y, res.z_l, res.z_u, res.z_bl, res.z_bu)
        raw_status = solver.solve()  # what ``result.info.status`` holds, without reading it
        raw = "PIQP_SOLVED" if raw_status.value == _solved() else raw_status.name
        status = PIQP_STATUSES.get(raw, "not_solved")
        sol = new_solution(problem, status, {"raw_status": raw})
        info = self._info
        sol.iterations = info.iter
        sol.solver_time_s = info.run_time
        if status == "optimal":  # the objective is computed from x when read
            x, y, z_l, z_u, z_bl, z_bu = self._views
            sol.x = x.copy()
            sol.y = EMPTY if A is None else y.copy()
            sol.z = EMPTY if G is None else z_u - z_l
            sol.z_box = EMPTY if lb is None and ub is None else z_bu - z_bl
            return sol
        self.reset()
        if status == "error":
            sol.error = f"PIQP: {raw}"
        return sol
