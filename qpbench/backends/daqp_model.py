"""Backend ``daqp``: DAQP (dual active set) through a persistent ``daqp.Model``, warm-started by its working set.

Formulation and duals as the stateless route (:mod:`qpbench.backends.daqp_`,
registered as ``daqp-stateless``)::

    H = P,  f = q,  A = [A_eq; G],
    bupper = [ub; b; h],  blower = [lb; b; -inf],  sense = [0 (n); 5 (me); 0 (mi)]

with the simple bounds native, equalities by sense flag 5, and DAQP's ``lam``
already in qpsolvers' sign convention (``z_box = lam[:n]``,
``y = lam[n:n+me]``, ``z = lam[n+me:]``).

Persistence. One ``daqp.Model`` per shape ``(n, me, mi, with box)``:
``setup`` on the first tick of a shape, then ``update`` of what changed and
``solve``. ``H`` and ``f`` are passed to ``update`` only when they differ
(bytewise) from the previous tick's: in the paper's formulation ``P = I`` and
``q = 0`` never change, so DAQP keeps its factorisation of ``H`` and only
re-forms its constraint data from the new ``A = [J; G]`` and bounds. ``sense``
is not passed to ``update``: DAQP then starts from the working set of its
previous solve (its own warm start); ``warm_start`` is ignored. Every array is
checked against the model's shape before ``update``
(:func:`~qpbench.backends._shapes.check_shapes`): DAQP ignores an update of
another shape without an error and would solve the previous problem again. A
failed ``setup``/``update`` (negative flag) or a solve that is not optimal
drops the model, so the next tick sets up afresh. :meth:`reset` drops it too.

Repeats. A ``daqp.Model`` cannot be copied; ``--repeat`` times each repeat on
another instance of the backend fed the same ticks (:mod:`qpbench.harness.timing`),
so every repeat starts from the working set the kept solve starts from
(``tests/test_contract.py``).

Settings, statuses. As ``daqp-stateless``: ``primal_tol = dual_tol = eps_abs``,
``iter_limit = max_iter``, ``time_limit`` [s], DAQP's own settings verbatim
(set on ``Model.settings``); exit flags mapped by
:data:`qpbench.backends.daqp_.EXITFLAGS`; only an optimal solve carries ``x``.

Time. ``solver_time_s`` is DAQP's ``setup_time + solve_time`` of the call
(``setup_time`` of ``Model.setup``/``update`` as DAQP reports it: 0 after an
``update``, so the time DAQP spends re-forming its data in ``update`` is not
in it; the wall time is).
"""

from __future__ import annotations

from . import register
from ._shapes import check_shapes
from .base import BackendSolution
from .daqp_ import (
    _UNKNOWN,
    EXITFLAGS,
    DaqpBackend,
    _Buffers,
    _daqp,
    _dense,
    _f64,
    _ndarray,
    read_result,
)


@register
class DaqpModelBackend(DaqpBackend):
    """DAQP through a persistent ``daqp.Model`` (setup once per shape, update + solve per tick)."""

    name = "daqp"

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._model = None
        self._key = None
        self._buf: _Buffers | None = None
        self._H = None  # the H and f the model holds (copies)
        self._f = None

    def reset(self) -> None:
        self._model = None
        self._key = None
        self._buf = None
        self._H = self._f = None

    def __deepcopy__(self, memo):
        if self._model is not None:
            raise TypeError("a daqp.Model cannot be copied")
        other = type(self)(self.profile, **self.settings)
        return other

    def _solve(self, problem, warm_start):
        P, q, A, b = problem.P, problem.q, problem.A, problem.b
        G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
        # Inline, not _common.dense_f64_parts: b, h, lb, ub are copied into this backend's
        # float64 buffers, so their types suffice, and the tick pays no extra call.
        if not (
            type(P) is _ndarray
            and type(q) is _ndarray
            and P.dtype == _f64
            and q.dtype == _f64
            and q.ndim == 1
            and (A is None or (type(A) is _ndarray and type(b) is _ndarray))
            and (G is None or (type(G) is _ndarray and type(h) is _ndarray))
            and (lb is None or type(lb) is _ndarray)
            and (ub is None or type(ub) is _ndarray)
        ):
            P, q, A, b, G, h, lb, ub = _dense(problem)
        n = q.shape[0]
        me, mi = check_shapes(self.name, n, P, A, b, G, h, lb, ub)
        box = lb is not None or ub is not None
        key = (n, me, mi, box)
        buf = self._buf
        if key != self._key:
            self.reset()
            buf = self._buf = _Buffers(n, me, mi, box)
            self._key = key
        buf.fill(A, b, G, h, lb, ub)
        model = self._model
        try:
            if model is None:
                daqp = _daqp()
                model = daqp.Model()
                model.settings = dict(model.settings, **self.options())
                flag, setup_time = model.setup(P, q, buf.A, buf.bu, buf.bl, buf.sense)
                if flag < 0:
                    return self._failed(problem, flag)
                self._model = model
                self._H, self._f = P.copy(), q.copy()
            else:
                H = f = None
                if P.tobytes() != self._H.tobytes():
                    H = self._H = P.copy()
                if q.tobytes() != self._f.tobytes():
                    f = self._f = q.copy()
                flag = model.update(H, f, buf.A, buf.bu, buf.bl)
                if flag < 0:
                    return self._failed(problem, flag)
            x, fval, flag, info = model.solve()
        except (ValueError, TypeError) as exc:
            self._model = None
            return BackendSolution(problem, status="error", error=f"{type(exc).__name__}: {exc}")
        sol = read_result(problem, x, fval, flag, info, buf.nb, box, me)
        if sol.status != "optimal":
            self._model = None  # set up afresh on the next tick
        return sol

    def _failed(self, problem, flag):
        """Solution of a ``setup``/``update`` that DAQP refused (the model is dropped)."""
        self._model = None
        status, raw = EXITFLAGS.get(flag, _UNKNOWN)
        sol = BackendSolution(problem, status=status)
        sol.extras["raw_status"] = raw
        if status == "error":
            sol.error = f"DAQP setup/update exit flag {flag} ({raw})"
        return sol
