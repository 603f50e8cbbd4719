"""Backend ``piqp``: PIQP (proximal interior point) through its own dense and sparse APIs.

``piqp.DenseSolver`` with ``h_l = -inf``, ``z = z_u - z_l``, ``z_box = z_bu - z_bl``; a problem
:func:`~qpbench.backends._common.dense_route` sends to the sparse API goes to
``piqp.SparseSolver`` (``P``'s upper triangle). The solver is ``setup`` once per shape (per
structure when sparse), then ``update``-d; a status other than optimal drops it.
``warm_start`` is ignored.
"""

from __future__ import annotations

from . import register
from ._common import (
    EMPTY,
    GENERIC_KEYS,
    check_shapes,
    dense_route,
    own_settings,
    refuse_unknown,
    solver_options,
    sparse_parts,
    structure_key,
)
from .base import BackendSolution, PersistentBackend, new_solution

_MODULE: list = []
_SOLVED: list = []  # piqp.PIQP_SOLVED.value (an int compares faster than the enum, which hashes slower still)

#: PIQP's status name -> our status (also read by ``qpsolvers:piqp``).
PIQP_STATUSES = {
    "PIQP_SOLVED": "optimal",
    "PIQP_PRIMAL_INFEASIBLE": "primal_infeasible",
    "PIQP_DUAL_INFEASIBLE": "dual_infeasible",
    "PIQP_MAX_ITER_REACHED": "max_iter",
    "PIQP_NUMERICS": "error",
    "PIQP_INVALID_SETTINGS": "error",
}


def _piqp():
    if not _MODULE:
        import piqp

        _MODULE.append(piqp)
        _SOLVED.append(piqp.PIQP_SOLVED.value)
    return _MODULE[0]


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
        self._solver = self._shapes = self._info = None
        self._views = None  # (x, y, z_l, z_u, z_bl, z_bu): numpy views of the live result

    def _setup(self, cls, shapes, data):
        """A new ``cls`` solver (``DenseSolver`` or ``SparseSolver``) set up with ``data``; kept."""
        self.reset()
        solver = cls()
        s = solver.settings
        for name, value in self._settings_dict.items():
            setattr(s, name, value)
        solver.setup(*data)
        self._solver, self._shapes = solver, shapes
        res = solver.result
        self._info = res.info
        # update() and solve() overwrite the vectors these views show (each read builds one)
        self._views = (res.x, res.y, res.z_l, res.z_u, res.z_bl, res.z_bu)
        return solver

    def _attempt(self, problem, warm_start):
        parts = dense_route(problem)
        if parts is None:
            return self._solve_sparse(problem)
        P, q, A, b, G, h, lb, ub = parts
        # PIQP keeps its old data on an update of another shape: updated only on the same shapes
        shapes = (
            P.shape,
            q.shape,
            None if A is None else A.shape,
            None if b is None else b.shape,
            None if G is None else G.shape,
            None if h is None else h.shape,
            None if lb is None else lb.shape,
            None if ub is None else ub.shape,
        )
        return self._run(problem, None, shapes, P, q, A, b, G, h, lb, ub)

    def _solve_sparse(self, problem):
        """The sparse route: ``piqp.SparseSolver`` kept per structure (upper triangle of ``P``)."""
        P, q, A, b, G, h, lb, ub = sparse_parts(problem, upper=True)
        shapes = (  # every shape: the kept solver's were checked at its set-up
            "sparse",
            q.shape,
            None if b is None else b.shape,
            None if h is None else h.shape,
            None if lb is None else lb.shape,
            None if ub is None else ub.shape,
            structure_key(P, A, G),
        )
        return self._run(problem, _piqp().SparseSolver, shapes, P, q, A, b, G, h, lb, ub)

    def _run(self, problem, cls, shapes, P, q, A, b, G, h, lb, ub) -> BackendSolution:
        """Update the kept solver set up for ``shapes``, else set up a new ``cls`` (``None``:
        ``DenseSolver``) after checking the shapes; solve."""
        solver = self._solver
        if solver is not None and shapes == self._shapes:
            solver.update(P, q, A, b, G, None, h, lb, ub)
        else:
            check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            solver = self._setup(
                cls or _piqp().DenseSolver, shapes, (P, q, A, b, G, None, h, lb, ub)
            )
        raw_status = solver.solve()  # what ``result.info.status`` holds, without reading it
        info = self._info
        if raw_status.value == _SOLVED[0]:  # the objective is computed from x when read
            sol = new_solution(problem, "optimal", {"raw_status": "PIQP_SOLVED"})
            x, y, z_l, z_u, z_bl, z_bu = self._views
            sol.x = x.copy()
            sol.y = EMPTY if A is None else y.copy()
            sol.z = EMPTY if G is None else z_u - z_l
            sol.z_box = EMPTY if lb is None and ub is None else z_bu - z_bl
        else:
            raw = raw_status.name
            status = PIQP_STATUSES.get(raw, "not_solved")
            sol = BackendSolution(problem, status=status, extras={"raw_status": raw})
            self.reset()
            if status == "error":
                sol.error = f"PIQP: {raw}"
        sol.iterations = info.iter
        sol.solver_time_s = info.run_time
        return sol
