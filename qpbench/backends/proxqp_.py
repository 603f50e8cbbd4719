"""Backend ``proxqp``: ProxQP (proximal augmented Lagrangian) through proxsuite's own dense and sparse APIs.

Formulation. ``proxsuite.proxqp.dense.QP(n, n_eq, n_in, box_constraints=True)``
solves ``min 1/2 x'Hx + g'x  s.t.  A x = b,  l <= C x <= u,  l_box <= x <= u_box``
with ``H = P, g = q, C = G, l = -inf, u = h`` and the bounds as ProxQP's own box
(no stacking). ProxQP's multipliers satisfy ``H x + g + A'y + C'z + z_box = 0``
with the same signs as qpsolvers, so ``y``, ``z`` and the last ``n`` entries of
ProxQP's ``z`` (``z_box``) are used as they are.

Sparse route. A problem with a scipy.sparse matrix, or one that made dense
would exceed :data:`qpbench.memory.DENSE_MAX_ENTRIES` entries
(:func:`~qpbench.backends._sparse.wants_sparse`), goes to
``proxsuite.proxqp.sparse.QP(n, n_eq, n_in)``, which has no box of its own:
the bounds are stacked under ``G`` as qpsolvers does (``C = [G; I]``,
``l = [-inf; lb]``, ``u = [h; ub]``), and ProxQP's ``z`` is again
``[z; z_box]``. The object is kept per structure (shapes and sparsity patterns
of ``H``, ``A``, ``C``) and ``update``-d as the dense one, with the same
warm start, cold retry, settings and statuses. The dense arrays of the robot's
ticks keep ``proxqp.dense.QP``.

Persistence. The ``QP`` object is built and ``init``-ed once per shape
``(n, n_eq, n_in, with bounds)`` and then ``update``-d with the new data
(the dense backend has no sparsity pattern to keep). A new object's first
solve starts from ``EQUALITY_CONSTRAINED_INITIAL_GUESS``, as
``proxqp.dense.solve`` / ``proxqp.sparse.solve`` do on the
``qpsolvers:proxqp`` route (so a cold solve takes the same iterations on
both routes); from then on the initial guess is
``WARM_START_WITH_PREVIOUS_RESULT``, the one change made after ``init``
(ProxQP 0.8 was seen to loop forever in ``solve`` after other changes of
``initial_guess``, so a cold re-solve builds a new object). An explicit ``warm_start``
is passed to ``QP.solve(x, None, None)``, which starts from that ``x`` for
the call. The preconditioner is computed
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
it happened. On the sparse route (bounds stacked as rows) ProxQP 0.8's
default ``eps_primal_inf = 1e-4`` also fires on cold solves of feasible
problems (HS118 of Maros-Meszaros, which the dense box API solves): there an
infeasibility verdict is checked by one fresh solve with ``eps_primal_inf`` and
``eps_dual_inf`` at the profile's ``eps_abs``, whose status is kept (a truly
infeasible problem stays infeasible). ``retry_cold=False`` in the settings
turns both checks off. After an infeasibility verdict the object is dropped
and the next tick builds a new one (a cold start): warm-started from the
iterate of an infeasibility exit, ProxQP 0.8 does not give the same answer
twice for the same sequence of ticks (iterations and ``x`` vary between two
objects fed the same ticks in one process), so neither a controller's
behaviour nor ``--repeat``'s timings would be reproducible.
:meth:`ProxqpBackend.reset` drops the object.

Per-call cost. Dense float64 inputs are passed as they are (other inputs
are converted), ``l = -inf`` is cached, and ``qp.results.info`` and numpy
views of ``results.x, y, z`` are kept per ``QP`` object (re-read after a
solve with an explicit guess), each copied once into the solution (``z`` and
``z_box`` are views of one copy of ProxQP's ``z``, through slice objects kept
with the views). A solved status is recognised by identity (the status enum
hashes in Python), and the solution is filled without its ``__init__``. What
is left against ``update`` + ``solve`` + reading the status, the solve time
and copies of ``x``, ``y``, ``z``: ``bench/backend_overhead.py``.

Settings. ``eps_abs``, ``eps_rel``, ``max_iter`` from the profile, and at
``eps_abs <= 1e-7`` also ``check_duality_gap=True`` with
``eps_duality_gap_abs = eps_abs`` (as qpbenchmark does at high accuracy);
ProxQP has no time limit. Under a ``qpbenchmark:<settings>`` profile,
qpbenchmark's arguments for ProxQP and nothing else, as the
``qpsolvers:proxqp`` route gets them
(:func:`~qpbench.backends._common.qpbenchmark_options`; under
``qpbenchmark:default`` ProxQP's own ``eps_abs = 1e-5`` and iteration limit).
The infeasibility checks above stay on (``retry_cold=False`` turns them off):
where ProxQP's verdict is overturned the two routes differ by design. ``compute_timings`` is on so that the solver's own
solve time is reported. Other settings are set on ``QP.settings`` verbatim
(``update_preconditioner`` is passed to ``update``).

Statuses. ``PROXQP_SOLVED`` -> optimal, ``PROXQP_PRIMAL_INFEASIBLE`` /
``PROXQP_DUAL_INFEASIBLE`` -> primal_infeasible / dual_infeasible,
``PROXQP_MAX_ITER_REACHED`` -> max_iter, anything else
(``SOLVED_CLOSEST_PRIMAL_FEASIBLE``, ``NOT_RUN``) -> not_solved.
``ValueError`` and ``RuntimeError`` raised by proxsuite become status ``error``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as spa

from . import register
from ._common import (
    as_dense,
    dense_bounds,
    dense_f64_parts,
    generic_settings,
    qpbenchmark_options,
)
from ._sparse import sparse_parts, structure_key, wants_sparse
from .base import Backend, BackendSolution

if TYPE_CHECKING:
    import qpsolvers

_STATUS_MAP: dict = {}
_MODULE: list = []
_SOLVED: list = []  # QPSolverOutput.PROXQP_SOLVED: compared by identity (the enum hashes in Python)
_new = object.__new__


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
        _SOLVED.append(O.PROXQP_SOLVED)
        ours = {
            O.PROXQP_SOLVED: "optimal",
            O.PROXQP_PRIMAL_INFEASIBLE: "primal_infeasible",
            O.PROXQP_DUAL_INFEASIBLE: "dual_infeasible",
            O.PROXQP_MAX_ITER_REACHED: "max_iter",
        }
        for value in O.__members__.values():
            _STATUS_MAP[value] = (ours.get(value, "not_solved"), str(value).split(".")[-1])
    return _STATUS_MAP


def _native_names(generic: dict) -> dict:
    """ProxQP's settings for the generic ones given (it has no time limit: that one is dropped)."""
    return {k: v for k, v in generic.items() if k != "time_limit"}


@register
class ProxqpBackend(Backend):
    """ProxQP dense with a persistent ``QP`` object, updated per problem."""

    name = "proxqp"
    certifies_infeasibility = True
    family = "augmented Lagrangian"
    package = "proxsuite"
    module = "proxsuite"
    #: scipy.sparse input (or a problem too large made dense) goes to ``proxqp.sparse.QP``.
    sparse = True
    #: Solved in a worker process with a deadline under ``--isolate auto``:
    #: ProxQP 0.8 was seen once to hang in native code (633 s) on a warm-started
    #: robot tick, which an in-process time limit cannot interrupt.
    risky = True

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings, ``retry_cold`` and ProxQP's own: the attributes of the installed
        package's ``proxqp.dense.QP(...).settings`` and ``proxqp.sparse.QP(...).settings``."""
        from ._common import GENERIC_KEYS

        proxqp = _proxqp()
        own = set()
        for qp in (proxqp.dense.QP(1, 0, 0), proxqp.sparse.QP(1, 0, 0)):
            s = qp.settings
            own |= {a for a in dir(s) if not a.startswith("_") and not callable(getattr(s, a))}
        return frozenset(own | {"retry_cold"} | set(GENERIC_KEYS))

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._qp = None
        self._key = None
        self._info = None  # ``qp.results.info`` of ``_qp``
        self._views = None  # ``(results.x, results.y, results.z)`` of ``_qp`` (numpy views)
        self._l = None  # cached ``l = -inf``

    def reset(self) -> None:
        self._qp = None
        self._key = None
        self._info = None
        self._views = None

    def _apply_settings(self, qp, proxqp) -> bool:
        s = qp.settings
        s.verbose = False
        s.compute_timings = True
        s.initial_guess = proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        native = qpbenchmark_options(self, "proxqp", _native_names)
        if native is None:
            generic, native = generic_settings(self)
            s.eps_abs = float(generic["eps_abs"])
            s.eps_rel = float(generic["eps_rel"])
            s.max_iter = int(generic["max_iter"])
            if generic["eps_abs"] <= 1e-7:
                s.check_duality_gap = True
                s.eps_duality_gap_abs = float(generic["eps_abs"])
                s.eps_duality_gap_rel = float(generic["eps_rel"])
        update_preconditioner = bool(native.pop("update_preconditioner", False))
        self._retry_cold = bool(native.pop("retry_cold", True))
        for key, value in native.items():
            setattr(s, key, value)
        return update_preconditioner

    def _build(self, proxqp, key, data):
        """A new ``QP`` object, initialised with ``data``; it becomes the persistent one.

        ``key`` is ``(n, n_eq, n_in, with_box)`` for ``proxqp.dense.QP`` and
        ``(n, n_eq, n_in, False, structure)`` for ``proxqp.sparse.QP`` (bounds stacked in ``C``).
        """
        self._qp = self._info = self._views = None
        n, n_eq, n_in, with_box = key[:4]
        if len(key) > 4:
            qp = proxqp.sparse.QP(n, n_eq, n_in)
        else:
            qp = proxqp.dense.QP(n, n_eq, n_in, box_constraints=with_box)
        self._update_preconditioner = self._apply_settings(qp, proxqp)
        qp.init(*data)
        self._qp, self._key = qp, key
        # ``qp.results.info`` is a member of the object: its wrapper stays valid.
        self._info = qp.results.info
        return qp

    def _lower(self, n_in: int) -> np.ndarray:
        """``l = -inf`` of ``n_in`` rows, cached (ProxQP copies its inputs)."""
        l = self._l
        if l is None or l.shape[0] != n_in:
            l = self._l = np.full(n_in, -np.inf)
        return l

    def _solve(self, problem, warm_start):
        parts = dense_f64_parts(problem)
        if (
            parts is None
            or parts[1].shape[0] > _SMALL_N
            or (parts[6] is None) is not (parts[7] is None)  # one bound given: the other is filled
        ):
            if wants_sparse(problem):
                return self._solve_sparse(problem, warm_start)
            parts = _converted(problem)
        H, q, A, b, C, u, lb, ub = parts
        n = q.shape[0]
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
        with_box = lb is not None or ub is not None
        if with_box:
            lb = np.full(n, -np.inf) if lb is None else lb
            ub = np.full(n, np.inf) if ub is None else ub
            eye = spa.identity(n, format="csc")
            C = eye if G is None else spa.vstack([G, eye], format="csc")
            l = lb if G is None else np.concatenate([l, lb])
            u = ub if G is None else np.concatenate([h, ub])
        n_eq = 0 if A is None else A.shape[0]
        n_in = 0 if C is None else C.shape[0]
        key = (n, n_eq, n_in, False, structure_key(H, A, C))
        return self._run(problem, key, (H, q, A, b, C, l, u), n, n_g, with_box, warm_start)

    def _run(self, problem, key, data, n, n_in, with_box, warm_start):
        """Update (same ``key``) or build the ``QP`` object with ``data``, solve, read the result.

        ``n_in`` rows of ``G`` lead ProxQP's ``z``; with ``with_box`` the next ``n`` are ``z_box``.
        """
        n_eq = key[1]
        try:
            warm = self._qp is not None and key == self._key
            if warm:
                qp = self._qp
                # ``update_preconditioner`` as a keyword: nanobind dispatches
                # this faster than the same call all positional.
                qp.update(*data, update_preconditioner=self._update_preconditioner)
            else:
                qp = self._build(_MODULE[0] if _MODULE else _proxqp(), key, data)
            if warm_start is not None:
                # Passing x makes ProxQP start from it (y, z from zero) for this call.
                qp.solve(np.asarray(warm_start, dtype=float), None, None)
                # ProxQP assigns ``results.x`` from an evaluated copy of the
                # guess (``results.x = x_wm.value().eval()``): 0.8.0 keeps the
                # buffer, but the cached views are re-read rather than rely on it.
                self._views = None
            else:
                qp.solve()
            info = self._info
            raw_status = info.status
            if _SOLVED and raw_status is _SOLVED[0]:
                status, raw = "optimal", "PROXQP_SOLVED"
            else:
                status, raw = (_STATUS_MAP or _status_map(_proxqp()))[raw_status]
            retried = False
            sparse = len(key) > 4
            if (
                sparse
            ):  # the kept views' split of z depends on n_in, which the key does not pin here
                self._views = None
            if (
                self._retry_cold
                and (warm or warm_start is not None or sparse)
                and status in ("primal_infeasible", "dual_infeasible")
            ):
                first_time = info.solve_time
                first_iter = info.iter
                # A fresh object: changing ``initial_guess`` after ``init`` makes
                # ProxQP 0.8 loop forever in ``solve``.
                qp = self._build(_proxqp(), key, data)
                if sparse:  # bounds as rows: the verdict is checked at the profile's tolerance
                    eps = qp.settings.eps_abs
                    qp.settings.eps_primal_inf = min(qp.settings.eps_primal_inf, eps)
                    qp.settings.eps_dual_inf = min(qp.settings.eps_dual_inf, eps)
                qp.solve()
                info = self._info
                status, raw = _STATUS_MAP[info.status]
                retried = True
            if not warm or retried:  # built cold (equality-constrained guess); warm from now on
                qp.settings.initial_guess = _proxqp().InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        except (ValueError, RuntimeError) as exc:
            self.reset()
            return BackendSolution(problem, status="error", error=f"{type(exc).__name__}: {exc}")

        # Without __init__ (BackendSolution's defaults are class attributes): a microsecond less per call.
        sol = _new(BackendSolution)
        sol.problem = problem
        sol.status = status
        sol.extras = {"raw_status": raw, "cold_retry": retried}
        sol.iterations = info.iter  # a Python int (and solve_time a float) from the binding
        sol.solver_time_s = info.solve_time * 1e-6  # ProxQP reports [us]
        if retried:
            sol.iterations += int(first_iter)
            sol.solver_time_s += float(first_time) * 1e-6
        if status == "primal_infeasible" or status == "dual_infeasible":
            self.reset()  # no warm start from an infeasibility exit (see the module docstring)
            return sol
        return self._read_solution(qp, sol, info, n, n_eq, n_in, with_box)

    def _read_solution(self, qp, sol, info, n: int, n_eq: int, n_in: int, with_box: bool):
        """Copy x, y, z (and z_box: the ``n`` rows after ``n_in``) out of ProxQP's results into ``sol``."""
        status = sol.status
        views = self._views
        if views is None:
            # Views of ``qp.results.x, y, z`` (each attribute access builds a
            # new one), kept per ``QP`` object: ``update`` and
            # ``solve`` write into the same buffers (same dimensions); with
            # them, where ``z`` and ``z_box`` lie in a copy of ProxQP's ``z``.
            res = qp.results
            views = self._views = (res.x, res.y, res.z, slice(0, n_in), slice(n_in, n_in + n))
        x_view, y_view, z_view, part_z, part_box = views
        x = x_view.copy()
        if n <= 32:
            finite = all(map(_isfinite, x.tolist()))
        else:
            finite = bool(np.isfinite(x).all())
        if finite:
            sol.x = x
            sol.y = y_view.copy() if n_eq else np.zeros(0)
            # One copy of ProxQP's z, then views: [z; z_box] with a box.
            z = z_view.copy()
            if with_box:
                sol.z = z[part_z]
                sol.z_box = z[part_box]
            else:
                sol.z = z
                sol.z_box = np.zeros(0)
        if status == "optimal":
            sol._obj = info.objValue  # a Python float from the binding
        return sol


def _converted(problem: qpsolvers.Problem) -> tuple[np.ndarray | None, ...]:
    """``P, q, A, b, G, h, lb, ub`` as float arrays, both bounds or neither (proxqp's dense API)."""
    q = np.asarray(problem.q, dtype=float)
    A, b, G, h = problem.A, problem.b, problem.G, problem.h
    lb, ub = dense_bounds(problem, q.shape[0])
    return (
        as_dense(problem.P),
        q,
        None if A is None else as_dense(A),
        None if b is None else np.asarray(b, dtype=float),
        None if G is None else as_dense(G),
        None if h is None else np.asarray(h, dtype=float),
        lb,
        ub,
    )


_isfinite = math.isfinite
#: Above this many variables the fast path asks :func:`wants_sparse` (exact: ``n (n + m)`` entries).
_SMALL_N = 2_000
