"""Backend ``piqp``: PIQP (proximal interior point) through its own dense and sparse APIs, with a persistent solver.

Formulation. ``piqp.DenseSolver`` solves
``min 1/2 x'Px + c'x  s.t.  A x = b,  h_l <= G x <= h_u,  x_l <= x <= x_u``
with ``c = q``, ``h_l = -inf`` (left out), ``h_u = h``, ``x_l = lb``,
``x_u = ub`` (bounds native, no stacking; infinite entries are PIQP's
business, it leaves them out). PIQP's multipliers are non-negative per side
(``z_l, z_u`` of the rows of ``G``, ``z_bl, z_bu`` of the bounds) and ``y`` has
qpsolvers' sign, so ``y = y``, ``z = z_u - z_l``, ``z_box = z_bu - z_bl``.

Sparse route. A problem with a scipy.sparse matrix, or one that made dense
would exceed :data:`qpbench.memory.DENSE_MAX_ENTRIES` entries
(:func:`~qpbench.backends._sparse.wants_sparse`), goes to ``piqp.SparseSolver``
with the same formulation, ``P`` as its upper triangle and ``A``, ``G`` as
CSC; the dense arrays of the robot's ticks keep ``DenseSolver``. The sparse
solver is kept per structure (shapes and sparsity patterns) and ``update``-d
like the dense one; same settings, statuses and multipliers.

Persistence. The solver is ``setup`` once per shape ``(n, me, mi, with box)``
and then ``update``-d with the tick's ``P, c, A, b, G, h_u, x_l, x_u`` (the
dense solver has no pattern to keep). PIQP is an interior-point method and
starts every solve from its own initial point (it has no warm start):
``warm_start`` is ignored and the saving is the skipped set-up (allocation,
preconditioner, which ``update`` reuses: PIQP's
``preconditioner_reuse_on_update`` default). A status other than optimal
drops the solver, so the next tick sets up afresh. :meth:`PiqpBackend.reset`
drops it too. Every array is checked against the shape before it is handed to
PIQP (:func:`~qpbench.backends._shapes.check_shapes`).

Settings. As ``qpsolvers:piqp`` (:func:`qpbench.backends.qpsolvers_.native_settings`):
``eps_abs``, ``eps_rel``, ``eps_duality_gap_abs/rel``, ``max_iter``, and
``check_duality_gap=True`` at ``eps_abs <= 1e-7``; PIQP has no time limit.
Under a ``qpbenchmark:<settings>`` profile, qpbenchmark's arguments for PIQP
and nothing else, as that route gets them
(:func:`~qpbench.backends._common.qpbenchmark_options`).
``compute_timings`` is on, ``verbose`` off. Other settings are set on
``DenseSolver.settings`` verbatim; an unknown name is a
:class:`~qpbench.exceptions.ParamError`.

Time. ``solver_time_s`` is PIQP's ``info.run_time``: set-up plus solve on the
first tick of a shape, update plus solve after. The objective is computed
from ``x`` when it is read (:class:`~qpbench.backends.base.BackendSolution`),
not read from ``info.primal_obj``: a property read of the binding per tick.

Statuses. ``PIQP_SOLVED`` -> optimal, ``PIQP_PRIMAL_INFEASIBLE`` /
``PIQP_DUAL_INFEASIBLE`` -> primal_infeasible / dual_infeasible,
``PIQP_MAX_ITER_REACHED`` -> max_iter, ``PIQP_NUMERICS`` and
``PIQP_INVALID_SETTINGS`` -> error, ``PIQP_UNSOLVED`` -> not_solved
(raw name in ``extras["raw_status"]``). ``ValueError``/``TypeError``/
``RuntimeError`` raised by the binding become status ``error``.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import ParamError
from . import register
from ._common import dense_f64_parts, dense_parts, generic_settings, qpbenchmark_options
from ._shapes import check_shapes
from ._sparse import sparse_parts, structure_key, wants_sparse
from .base import Backend, BackendSolution, _perf_ns

_STATUS_MAP: dict = {}
_MODULE: list = []
_SOLVED: list = []  # piqp.PIQP_SOLVED.value (an int compares faster than the enum, which hashes slower still)


def _piqp():
    if not _MODULE:
        import piqp

        _MODULE.append(piqp)
        _SOLVED.append(piqp.PIQP_SOLVED.value)
        S = piqp
        ours = {
            S.PIQP_SOLVED: "optimal",
            S.PIQP_PRIMAL_INFEASIBLE: "primal_infeasible",
            S.PIQP_DUAL_INFEASIBLE: "dual_infeasible",
            S.PIQP_MAX_ITER_REACHED: "max_iter",
            S.PIQP_NUMERICS: "error",
            S.PIQP_INVALID_SETTINGS: "error",
            S.PIQP_UNSOLVED: "not_solved",
        }
        for value, status in ours.items():
            _STATUS_MAP[value] = (status, str(value).split(".")[-1])
    return _MODULE[0]


@register
class PiqpBackend(Backend):
    """PIQP dense with a persistent ``DenseSolver``, updated per tick."""

    name = "piqp"
    certifies_infeasibility = True
    family = "proximal interior point"
    package = "piqp"
    module = "piqp"
    #: scipy.sparse input (or a problem too large made dense) goes to ``piqp.SparseSolver``.
    sparse = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings and PIQP's own: the attributes of the installed package's
        ``DenseSolver().settings`` and ``SparseSolver().settings``."""
        from ._common import GENERIC_KEYS

        piqp = _piqp()
        own = set()
        for settings in (piqp.DenseSolver().settings, piqp.SparseSolver().settings):
            own |= {
                a
                for a in dir(settings)
                if not a.startswith("_") and not callable(getattr(settings, a))
            }
        return frozenset(own | set(GENERIC_KEYS))

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._solver = None
        self._shapes = None
        self._result = None
        self._info = None
        self._views = None  # (x, y, z_l, z_u, z_bl, z_bu): numpy views of the live result
        self._settings_dict = self._make_settings()

    def _make_settings(self) -> dict:
        from .qpsolvers_ import native_settings

        given = qpbenchmark_options(
            self, "piqp", lambda g: {k: g[k] for k in g if k != "time_limit"}
        )
        if given is not None:  # as the qpsolvers:piqp route under a qpbenchmark profile
            settings, native = {"verbose": False, "compute_timings": True}, given
        else:
            generic, native = generic_settings(self)
            settings = native_settings("piqp", **generic)
            settings.update(verbose=False, compute_timings=True)
        allowed = {a for a in dir(_piqp().DenseSolver().settings) if not a.startswith("_")}
        for key in native:
            if key not in allowed:
                raise ParamError(
                    f"unknown setting '{key}' for backend 'piqp' (PIQP's own: {', '.join(sorted(allowed))}; "
                    "generic: eps_abs, eps_rel, max_iter, time_limit)",
                    key=key,
                )
        settings.update(native)
        return settings

    def reset(self) -> None:
        self._solver = None
        self._shapes = None
        self._result = None
        self._info = None
        self._views = None

    def _setup(self, cls, shapes, data):
        """A new ``cls`` solver (``DenseSolver`` or ``SparseSolver``) set up with ``data``; kept."""
        self.reset()
        solver = cls()
        s = solver.settings
        for name, value in self._settings_dict.items():
            setattr(s, name, value)
        solver.setup(*data)
        self._solver, self._shapes = solver, shapes
        res = self._result = solver.result
        self._info = res.info
        # Each attribute read of the result builds a new view; these views follow
        # the live vectors, which update() and solve() overwrite in place (same shape).
        self._views = (res.x, res.y, res.z_l, res.z_u, res.z_bl, res.z_bu)
        return solver

    def solve(self, problem, warm_start=None) -> BackendSolution:
        """One solve; see :meth:`Backend.solve` (same fields). Timed here rather than around
        a ``_solve``: one Python call less per tick."""
        start = _perf_ns()
        parts = dense_f64_parts(problem)
        if parts is None or parts[1].shape[0] > _SMALL_N:
            parts = None if wants_sparse(problem) else _dense(problem)
        if parts is None:
            sol = self._solve_sparse(problem)
        else:
            P, q, A, b, G, h, lb, ub = parts
            # The shapes, not a helper's key: written out, they cost no call per tick. PIQP
            # prints "... has wrong dimensions" and keeps its old data on a wrong shape, so an
            # update needs the shapes the solver was set up with (checked then, in _run).
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
            sol = self._run(problem, None, shapes, P, q, A, b, G, h, lb, ub)
        sol.found = sol.status == "optimal"
        sol.backend = self.name
        sol.wall_time_s = (_perf_ns() - start) * 1e-9
        return sol

    def _solve_sparse(self, problem):
        """The sparse route: ``piqp.SparseSolver`` kept per structure (upper triangle of ``P``)."""
        P, q, A, b, G, h, lb, ub = sparse_parts(problem, upper=True)
        check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
        shapes = (
            "sparse",
            q.shape,
            None if b is None else b.shape,
            None if h is None else h.shape,
            lb is None,
            ub is None,
            structure_key(P, A, G),
        )
        return self._run(problem, _piqp().SparseSolver, shapes, P, q, A, b, G, h, lb, ub)

    def _run(self, problem, cls, shapes, P, q, A, b, G, h, lb, ub) -> BackendSolution:
        """Update the kept solver when it was set up for ``shapes``, else set up a new ``cls``
        (``None``: ``DenseSolver``) after checking the shapes; solve; the solution in
        qpsolvers' convention."""
        solver = self._solver
        try:
            if solver is not None and shapes == self._shapes:
                solver.update(P, q, A, b, G, None, h, lb, ub)
            else:
                check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
                solver = self._setup(
                    cls or _piqp().DenseSolver, shapes, (P, q, A, b, G, None, h, lb, ub)
                )
            raw_status = solver.solve()  # what ``result.info.status`` holds, without reading it
        except (ValueError, TypeError, RuntimeError) as exc:
            self.reset()
            return BackendSolution(problem, status="error", error=f"{type(exc).__name__}: {exc}")
        info = self._info
        if raw_status.value == _SOLVED[0]:
            # Without __init__ (BackendSolution's defaults are class attributes): a microsecond
            # less per call. No objective read (a property read of the binding): it is
            # computed from x if asked for.
            sol = _new(BackendSolution)
            sol.problem = problem
            sol.status = "optimal"
            sol.extras = {"raw_status": "PIQP_SOLVED"}
            x, y, z_l, z_u, z_bl, z_bu = self._views
            sol.x = x.copy()
            sol.y = _EMPTY if A is None else y.copy()
            sol.z = _EMPTY if G is None else z_u - z_l
            sol.z_box = _EMPTY if lb is None and ub is None else z_bu - z_bl
        else:
            status, raw = _STATUS_MAP.get(raw_status, ("not_solved", str(raw_status)))
            sol = BackendSolution(problem, status=status, extras={"raw_status": raw})
            self.reset()
            if status == "error":
                sol.error = f"PIQP: {raw}"
        sol.iterations = info.iter
        sol.solver_time_s = info.run_time
        return sol


_new = object.__new__
_EMPTY = np.zeros(0)
_EMPTY.flags.writeable = False


_dense = dense_parts
#: Above this many variables the fast path asks :func:`wants_sparse` (exact: ``n (n + m)`` entries).
_SMALL_N = 2_000
