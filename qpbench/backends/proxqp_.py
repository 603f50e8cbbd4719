"""Backend ``proxqp``: ProxQP (proximal augmented Lagrangian) through proxsuite's dense and sparse APIs.

``proxqp.dense.QP`` with ``C = G``, ``l = -inf``, ``u = h`` and the bounds as ProxQP's box; the
sparse route (:func:`~qpbench.backends._common.dense_route`) stacks the bounds under ``G``. The
``QP`` object is ``init``-ed once per shape (or structure), then ``update``-d and warm-started;
an infeasibility verdict after a warm start, or on the sparse route, is checked by one cold
solve (``extras["cold_retry"]``; ``retry_cold=False``: not; docs/architecture.md).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import scipy.sparse as spa

from . import register
from ._common import (
    EMPTY,
    GENERIC_KEYS,
    all_finite,
    dense_bounds,
    dense_route,
    own_settings,
    solver_options,
    sparse_parts,
    structure_key,
)
from .base import PersistentBackend, new_solution

#: ProxQP's ``QPSolverOutput`` name -> our status (also read by ``qpsolvers:proxqp``).
PROXQP_STATUSES = {
    "PROXQP_SOLVED": "optimal",
    "PROXQP_PRIMAL_INFEASIBLE": "primal_infeasible",
    "PROXQP_DUAL_INFEASIBLE": "dual_infeasible",
    "PROXQP_MAX_ITER_REACHED": "max_iter",
}


@cache
def _proxqp():
    """``proxsuite.proxqp`` (cached: proxsuite's module ``__getattr__`` is Python code)."""
    import proxsuite

    return proxsuite.proxqp


@cache
def _solved():
    """``QPSolverOutput.PROXQP_SOLVED``, compared by identity (the enum hashes in Python)."""
    return _proxqp().QPSolverOutput.PROXQP_SOLVED


def _status(value) -> tuple[str, str]:
    """Our status and ProxQP's name of a ``QPSolverOutput``."""
    return PROXQP_STATUSES.get(value.name, "not_solved"), value.name


@register
class ProxqpBackend(PersistentBackend):
    """ProxQP dense with a persistent ``QP`` object, updated per problem."""

    name = "proxqp"
    errors = (ValueError, RuntimeError)
    family = "augmented Lagrangian"
    package = "proxsuite"
    module = "proxsuite"
    sparse = True
    #: ProxQP 0.8 was seen to hang in native code on a warm-started robot tick.
    risky = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings, ``retry_cold`` and ProxQP's own (dense and sparse ``QP.settings``)."""
        proxqp = _proxqp()
        own = own_settings(proxqp.dense.QP(1, 0, 0).settings)
        own |= own_settings(proxqp.sparse.QP(1, 0, 0).settings)
        return frozenset(own | {"retry_cold"} | set(GENERIC_KEYS))

    def reset(self) -> None:
        self._qp = self._key = self._l = None  # _l: ``l = -inf``, kept
        self._info = None  # ``qp.results.info`` of ``_qp``
        self._views = None  # ``(results.x, results.y, results.z)`` of ``_qp`` (numpy views)

    def _apply_settings(self, qp, proxqp) -> bool:
        s = qp.settings
        s.verbose = False
        s.compute_timings = True
        s.initial_guess = proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        native = solver_options(self, "proxqp")
        update_preconditioner = bool(native.pop("update_preconditioner", False))
        self._retry_cold = bool(native.pop("retry_cold", True))
        for key, value in native.items():
            setattr(s, key, value)
        return update_preconditioner

    def _build(self, proxqp, key, data):
        """A new ``QP`` object (sparse for a ``key`` with a structure) initialised with ``data``."""
        self._qp = self._info = self._views = None
        n, n_eq, n_in, with_box = key[:4]
        if len(key) > 4:
            qp = proxqp.sparse.QP(n, n_eq, n_in)
        else:
            qp = proxqp.dense.QP(n, n_eq, n_in, box_constraints=with_box)
        self._update_preconditioner = self._apply_settings(qp, proxqp)
        qp.init(*data)
        self._qp, self._key = qp, key
        self._info = qp.results.info  # a member of the object: the wrapper stays valid
        return qp

    def _lower(self, n_in: int) -> np.ndarray:
        """``l = -inf`` of ``n_in`` rows, cached (ProxQP copies its inputs)."""
        l = self._l
        if l is None or l.shape[0] != n_in:
            l = self._l = np.full(n_in, -np.inf)
        return l

    def _attempt(self, problem, warm_start):
        parts = dense_route(problem)
        if parts is None:
            return self._solve_sparse(problem, warm_start)
        H, q, A, b, C, u, lb, ub = parts
        n = q.shape[0]
        if (lb is None) is not (ub is None):  # ProxQP's box takes both
            lb, ub = dense_bounds(problem, n)
        n_eq = 0 if A is None else A.shape[0]
        n_in = 0 if C is None else C.shape[0]
        l = None if C is None else self._lower(n_in)
        with_box = lb is not None
        key = (n, n_eq, n_in, with_box)
        data = (H, q, A, b, C, l, u, lb, ub) if with_box else (H, q, A, b, C, l, u)
        return self._run(problem, key, data, n, n_in, with_box, warm_start)

    def _solve_sparse(self, problem, warm_start):
        """The sparse route: ``proxqp.sparse.QP``, bounds stacked under ``G`` as qpsolvers does."""
        H, q, A, b, G, h, lb, ub = sparse_parts(problem)
        n = q.shape[0]
        n_g = 0 if G is None else G.shape[0]
        C, u = G, h
        l = None if G is None else self._lower(n_g)
        lb, ub = dense_bounds(problem, n)
        with_box = lb is not None
        if with_box:
            eye = spa.identity(n, format="csc")
            C = eye if G is None else spa.vstack([G, eye], format="csc")
            l = lb if G is None else np.concatenate([l, lb])
            u = ub if G is None else np.concatenate([h, ub])
        n_eq = 0 if A is None else A.shape[0]
        n_in = 0 if C is None else C.shape[0]
        key = (n, n_eq, n_in, False, structure_key(H, A, C))
        return self._run(problem, key, (H, q, A, b, C, l, u), n, n_g, with_box, warm_start)

    def _run(self, problem, key, data, n, n_in, with_box, warm_start):
        """Update (same ``key``) or build the ``QP`` object with ``data``, solve, read the result
        (``z``: ``n_in`` rows of ``G``, then ``n`` of ``z_box``)."""
        warm = self._qp is not None and key == self._key
        if warm:
            qp = self._qp
            qp.update(*data, update_preconditioner=self._update_preconditioner)
        else:
            qp = self._build(_proxqp(), key, data)
        if warm_start is not None:
            # results.x becomes a copy of the guess: the kept views are read again
            qp.solve(np.asarray(warm_start, dtype=float), None, None)
            self._views = None
        else:
            qp.solve()
        info = self._info
        raw_status = info.status
        solved = raw_status is _solved()
        status, raw = ("optimal", "PROXQP_SOLVED") if solved else _status(raw_status)
        retried = False
        sparse = len(key) > 4
        if sparse:  # the kept views' split of z depends on n_in, which the key does not pin
            self._views = None
        if (
            self._retry_cold
            and (warm or warm_start is not None or sparse)
            and status in ("primal_infeasible", "dual_infeasible")
        ):
            first_time = info.solve_time
            first_iter = info.iter
            qp = self._build(_proxqp(), key, data)
            if sparse:  # bounds as rows: the verdict checked at the profile's tolerance
                eps = qp.settings.eps_abs
                qp.settings.eps_primal_inf = min(qp.settings.eps_primal_inf, eps)
                qp.settings.eps_dual_inf = min(qp.settings.eps_dual_inf, eps)
            qp.solve()
            info = self._info
            status, raw = _status(info.status)
            retried = True
        if not warm or retried:  # built cold (equality-constrained guess); warm from now on
            qp.settings.initial_guess = _proxqp().InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        sol = new_solution(problem, status, {"raw_status": raw, "cold_retry": retried})
        sol.iterations = info.iter  # a Python int (and solve_time a float) from the binding
        sol.solver_time_s = info.solve_time * 1e-6  # ProxQP reports [us]
        if retried:
            sol.iterations += int(first_iter)
            sol.solver_time_s += float(first_time) * 1e-6
        if status == "primal_infeasible" or status == "dual_infeasible":
            self.reset()  # no warm start from an infeasibility exit
            return sol
        views = self._views
        if views is None:  # update and solve write into the buffers these views show
            res = qp.results
            views = self._views = (res.x, res.y, res.z, slice(0, n_in), slice(n_in, n_in + n))
        x_view, y_view, z_view, part_z, part_box = views
        x = x_view.copy()
        if all_finite(x):
            sol.x = x
            sol.y = y_view.copy() if key[1] else EMPTY
            z = z_view.copy()  # [z; z_box] with a box
            sol.z, sol.z_box = (z[part_z], z[part_box]) if with_box else (z, EMPTY)
        if status == "optimal":
            sol._obj = info.objValue  # a Python float from the binding
        return sol
