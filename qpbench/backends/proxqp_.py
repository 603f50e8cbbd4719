"""Backend ``proxqp``: ProxQP (proximal augmented Lagrangian) through proxsuite's own dense API.

Formulation. ``proxsuite.proxqp.dense.QP(n, n_eq, n_in, box_constraints=True)``
solves ``min 1/2 x'Hx + g'x  s.t.  A x = b,  l <= C x <= u,  l_box <= x <= u_box``
with ``H = P, g = q, C = G, l = -inf, u = h`` and the bounds as ProxQP's own box
(no stacking). ProxQP's multipliers satisfy ``H x + g + A'y + C'z + z_box = 0``
with the same signs as qpsolvers, so ``y``, ``z`` and the last ``n`` entries of
ProxQP's ``z`` (``z_box``) are used as they are. Sparse inputs are densified
(the dense backend is the one made for small problems like the robot's).

Persistence. The ``QP`` object is built and ``init``-ed once per shape
``(n, n_eq, n_in, with bounds)`` and then ``update``-d with the new data
(the dense backend has no sparsity pattern to keep). The initial guess is
``WARM_START_WITH_PREVIOUS_RESULT``; an explicit ``warm_start`` is passed
to ``QP.solve(x, None, None)``, which starts from that ``x`` for the call
(``initial_guess`` itself is never changed after ``init``: ProxQP 0.8 then
loops forever in ``solve``). The preconditioner is computed
at ``init`` and kept at ``update`` (ProxQP's default; set
``update_preconditioner=True`` in the settings to recompute it).

Infeasibility after a warm start. Warm-started from the previous result of
an *unrelated* problem of the same shape (a shuffled problem set, the random
sequences of the tests), ProxQP 0.8 often stops after a few iterations with
a false ``PRIMAL_INFEASIBLE`` (its default ``eps_primal_inf = 1e-4`` test
fires on the dual iterates' jump). On consecutive robot ticks it does not
(3000 ticks of the wall scenario: same statuses as Clarabel, median one
iteration). So an infeasibility report from a warm-started solve is
checked by one cold re-solve (a fresh ``QP`` object) and its status
is kept; iterations and solve time add up, and ``extras["cold_retry"]`` says
it happened. ``retry_cold=False`` in the settings turns this off.
:meth:`ProxqpBackend.reset` drops the object.

Settings. ``eps_abs``, ``eps_rel``, ``max_iter`` from the profile, and at
``eps_abs <= 1e-7`` also ``check_duality_gap=True`` with
``eps_duality_gap_abs = eps_abs`` (as qpbenchmark does at high accuracy);
ProxQP has no time limit. ``compute_timings`` is on so that the solver's own
solve time is reported. Other settings are set on ``QP.settings`` verbatim
(``update_preconditioner`` is passed to ``update``).

Statuses. ``PROXQP_SOLVED`` -> optimal, ``PROXQP_PRIMAL_INFEASIBLE`` /
``PROXQP_DUAL_INFEASIBLE`` -> primal_infeasible / dual_infeasible,
``PROXQP_MAX_ITER_REACHED`` -> max_iter, anything else
(``SOLVED_CLOSEST_PRIMAL_FEASIBLE``, ``NOT_RUN``) -> not_solved.
``ValueError`` and ``RuntimeError`` raised by proxsuite become status ``error``.
"""

from __future__ import annotations

import numpy as np

from . import register
from ._common import as_dense, dense_bounds, generic_settings
from .base import Backend, BackendSolution


_STATUS_MAP: dict = {}
_MODULE: list = []


def _proxqp():
    """``proxsuite.proxqp`` (cached: proxsuite's module ``__getattr__`` is Python code)."""
    if not _MODULE:
        import proxsuite

        _MODULE.append(proxsuite.proxqp)
    return _MODULE[0]



def _status_map(proxqp) -> dict:
    """``QPSolverOutput`` -> (our status, raw name), built once (enum hashing is slow)."""
    if not _STATUS_MAP:
        O = proxqp.QPSolverOutput
        ours = {
            O.PROXQP_SOLVED: "optimal",
            O.PROXQP_PRIMAL_INFEASIBLE: "primal_infeasible",
            O.PROXQP_DUAL_INFEASIBLE: "dual_infeasible",
            O.PROXQP_MAX_ITER_REACHED: "max_iter",
        }
        for value in O.__members__.values():
            _STATUS_MAP[value] = (ours.get(value, "not_solved"), str(value).split(".")[-1])
    return _STATUS_MAP


@register
class ProxqpBackend(Backend):
    """ProxQP dense with a persistent ``QP`` object, updated per problem."""

    name = "proxqp"
    family = "augmented Lagrangian"
    package = "proxsuite"
    #: Solved in a worker process with a deadline under ``--isolate auto``:
    #: ProxQP 0.8 was seen once to hang in native code (633 s) on a warm-started
    #: robot tick, which an in-process time limit cannot interrupt.
    risky = True

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._qp = None
        self._key = None

    @classmethod
    def unavailable_reason(cls):
        try:
            import proxsuite  # noqa: F401
        except ImportError as exc:
            return f"cannot import proxsuite ({exc})"
        return None

    def reset(self) -> None:
        self._qp = None
        self._key = None

    def _apply_settings(self, qp, proxqp) -> bool:
        generic, native = generic_settings(self)
        s = qp.settings
        s.eps_abs = float(generic["eps_abs"])
        s.eps_rel = float(generic["eps_rel"])
        s.max_iter = int(generic["max_iter"])
        s.verbose = False
        s.compute_timings = True
        if generic["eps_abs"] <= 1e-7:
            s.check_duality_gap = True
            s.eps_duality_gap_abs = float(generic["eps_abs"])
            s.eps_duality_gap_rel = float(generic["eps_rel"])
        s.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        update_preconditioner = bool(native.pop("update_preconditioner", False))
        self._retry_cold = bool(native.pop("retry_cold", True))
        for key, value in native.items():
            setattr(s, key, value)
        return update_preconditioner

    def _build(self, proxqp, key, H, q, A, b, C, l, u, lb, ub):
        """A new ``QP`` object, initialised with the data; it becomes the persistent one."""
        self._qp = None
        n, n_eq, n_in, with_box = key
        qp = proxqp.dense.QP(n, n_eq, n_in, box_constraints=with_box)
        self._update_preconditioner = self._apply_settings(qp, proxqp)
        if with_box:
            qp.init(H, q, A, b, C, l, u, lb, ub)
        else:
            qp.init(H, q, A, b, C, l, u)
        self._qp, self._key = qp, key
        return qp

    def _solve(self, problem, warm_start):
        proxqp = _proxqp()
        sol = BackendSolution(problem)
        q = np.asarray(problem.q, dtype=float)
        n = q.shape[0]
        H = as_dense(problem.P)
        A = None if problem.A is None else as_dense(problem.A)
        b = None if problem.b is None else np.asarray(problem.b, dtype=float)
        C = None if problem.G is None else as_dense(problem.G)
        u = None if problem.h is None else np.asarray(problem.h, dtype=float)
        n_eq = 0 if A is None else A.shape[0]
        n_in = 0 if C is None else C.shape[0]
        l = None if C is None else np.full(n_in, -np.inf)
        lb, ub = dense_bounds(problem, n)
        with_box = lb is not None
        key = (n, n_eq, n_in, with_box)
        try:
            warm = self._qp is not None and key == self._key
            if warm:
                qp = self._qp
                if with_box:
                    qp.update(H, q, A, b, C, l, u, lb, ub, self._update_preconditioner)
                else:
                    qp.update(H, q, A, b, C, l, u, self._update_preconditioner)
            else:
                qp = self._build(proxqp, key, H, q, A, b, C, l, u, lb, ub)
            if warm_start is not None:
                # Passing x makes ProxQP start from it (y, z from zero) for this call.
                qp.solve(np.asarray(warm_start, dtype=float), None, None)
            else:
                qp.solve()
            retried = False
            if (
                self._retry_cold
                and (warm or warm_start is not None)
                and _status_map(proxqp)[qp.results.info.status][0] in ("primal_infeasible", "dual_infeasible")
            ):
                first_time = float(qp.results.info.solve_time)
                first_iter = int(qp.results.info.iter)
                # A fresh object: changing ``initial_guess`` after ``init`` makes
                # ProxQP 0.8 loop forever in ``solve``.
                qp = self._build(proxqp, key, H, q, A, b, C, l, u, lb, ub)
                qp.solve()
                retried = True
        except (ValueError, RuntimeError) as exc:
            self.reset()
            sol.status = "error"
            sol.error = f"{type(exc).__name__}: {exc}"
            return sol

        res = qp.results
        info = res.info
        status, raw = _status_map(proxqp)[info.status]
        sol.status = status
        sol.extras = {"raw_status": raw, "cold_retry": retried}
        sol.iterations = int(info.iter)
        sol.solver_time_s = float(info.solve_time) * 1e-6  # ProxQP reports [us]
        if retried:
            sol.iterations += first_iter
            sol.solver_time_s += first_time * 1e-6
        if status in ("primal_infeasible", "dual_infeasible"):
            return sol
        x = np.array(res.x)
        if np.isfinite(x).all():
            sol.x = x
            sol.y = np.array(res.y) if n_eq else np.zeros(0)
            z = np.array(res.z)
            sol.z = z[:n_in].copy()
            sol.z_box = z[n_in : n_in + n].copy() if with_box else np.zeros(0)
        if status == "optimal":
            sol.obj = float(info.objValue)
        return sol
