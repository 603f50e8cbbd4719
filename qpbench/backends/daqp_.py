"""Backend ``daqp``: DAQP (dual active set) through its own Python API, no qpsolvers layer.

Formulation. ``daqp.solve(H, f, A, bupper, blower, sense)`` solves
``min 1/2 x'Hx + f'x  s.t.  blower <= [x_box; A x] <= bupper``, where the first
``len(bupper) - rows(A)`` entries of ``bupper``/``blower`` are simple bounds on
the first variables (DAQP handles those natively, without a row of ``A``).
A qpsolvers problem is passed as::

    H = P,  f = q,  A = [A_eq; G],
    bupper = [ub; b; h],  blower = [lb; b; -inf],  sense = [0 (n); 5 (me); 0 (mi)]

(sense 5: an equality, active and immutable). Without ``lb``/``ub`` the
simple-bound block is left out; a missing side of the box is +-inf. The
stacked arrays are buffers cached per shape ``(n, me, mi, with box)`` and
filled through preallocated views (a few hundred nanoseconds, against about a
microsecond for ``np.concatenate``/``np.vstack``): DAQP copies its input into
its own workspace, so the buffers are free again when ``daqp.solve``
returns. Sparse matrices are densified (DAQP is a dense solver).

Duals. DAQP's multipliers ``lam`` (one per entry of ``bupper``) satisfy
``H x + f + A' lam_rows + lam_box = 0`` with ``lam > 0`` at an active upper
bound and ``< 0`` at an active lower bound: qpsolvers' convention, so
``z_box = lam[:n]``, ``y = lam[n:n+me]``, ``z = lam[n+me:]`` as they are.

Persistence. None: ``daqp.solve`` builds its workspace per call (a deep
copy of the backend rebuilds the buffers' views). DAQP also
offers ``daqp.Model`` (workspace kept, ``update`` + ``solve``, active set of
the previous solve reused): that route is the backend ``daqp``
(:mod:`.daqp_model`); for n = 4 its ``update`` + ``solve`` costs about what
a fresh ``daqp.solve`` does. ``warm_start`` is ignored: passed as DAQP's
``primal_start`` (the previous tick's ``x``) it saves an iteration but costs
more per call than it saves. What the whole call costs per robot tick:
``bench/backend_overhead.py``, ``bench/closed_loop_speed.py``.

Settings. From the profile: ``primal_tol = eps_abs``, ``dual_tol = eps_abs``,
``iter_limit = max_iter`` and ``time_limit`` [s]; under a ``qpbenchmark:<settings>``
profile, qpbenchmark's arguments for DAQP and nothing else, as the
``qpsolvers:daqp`` route gets them
(:func:`~qpbench.backends._common.qpbenchmark_options`). Other settings are DAQP's
own (``eps_prox``, ``zero_tol``, ``pivot_tol``, ...; the names of
``daqp.Model().settings``), passed verbatim; an unknown name is a
:class:`~qpbench.exceptions.ParamError`. DAQP's default ``eps_prox < 0``
regularises a singular ``H`` automatically (proximal iterations), so LPs and
positive semi-definite QPs are solved too.

Statuses from DAQP's exit flag:

===== ===================== =======================================
flag  DAQP name             status
===== ===================== =======================================
1, 2  OPTIMAL, SOFT_OPTIMAL optimal
-1    INFEASIBLE            primal_infeasible
-3    UNBOUNDED             dual_infeasible
-4    ITERLIMIT             max_iter
-2    CYCLE                 max_iter (no progress: cycling)
-7    TIMELIMIT             time_limit
-5    NONCONVEX             error (``H`` could not be factored)
-6    OVERDETERMINED_INITIAL error (inconsistent equalities)
other                       error
===== ===================== =======================================

``extras["raw_status"]`` holds the flag. On a status other than optimal the
solution has no ``x`` (DAQP's iterate and ``lam`` are not meaningful then).
``ValueError`` and ``TypeError`` raised by the binding become status ``error``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ParamError
from . import register
from ._common import dense_parts, generic_settings, qpbenchmark_options
from .base import Backend, BackendSolution

if TYPE_CHECKING:
    import qpsolvers

#: DAQP exit flag -> (status, DAQP's name).
EXITFLAGS = {
    2: ("optimal", "SOFT_OPTIMAL"),
    1: ("optimal", "OPTIMAL"),
    -1: ("primal_infeasible", "INFEASIBLE"),
    -2: ("max_iter", "CYCLE"),
    -3: ("dual_infeasible", "UNBOUNDED"),
    -4: ("max_iter", "ITERLIMIT"),
    -5: ("error", "NONCONVEX"),
    -6: ("error", "OVERDETERMINED_INITIAL"),
    -7: ("time_limit", "TIMELIMIT"),
}

#: ``sense`` flag of an equality row (active + immutable).
_EQUALITY = 5

_DAQP: list = []


def _daqp():
    if not _DAQP:
        import daqp

        _DAQP.append(daqp)
    return _DAQP[0]


class _Buffers:
    """Stacked ``A``, ``bupper``, ``blower``, ``sense`` of one shape, and views to fill them."""

    __slots__ = (
        "A",
        "bu",
        "bl",
        "sense",
        "A_eq",
        "A_in",
        "bu_box",
        "bu_eq",
        "bu_in",
        "bl_box",
        "bl_eq",
        "n",
        "me",
        "mi",
        "nb",
    )

    def __init__(self, n: int, me: int, mi: int, box: bool):
        nb = n if box else 0
        m = nb + me + mi
        self.n, self.me, self.mi, self.nb = n, me, mi, nb
        self.A = np.zeros((me + mi, n))
        self.bu = np.empty(m)
        self.bl = np.full(m, -np.inf)
        self.sense = np.zeros(m, dtype=np.intc)
        self.sense[nb : nb + me] = _EQUALITY
        self.A_eq = self.A[:me]
        self.A_in = self.A[me:]
        self.bu_box = self.bu[:nb]
        self.bu_eq = self.bu[nb : nb + me]
        self.bu_in = self.bu[nb + me :]
        self.bl_box = self.bl[:nb]
        self.bl_eq = self.bl[nb : nb + me]

    def fill(self, A, b, G, h, lb, ub) -> None:
        """Write a problem's rows and bounds into the stacked arrays (equalities as ``bl = bu``)."""
        if self.me:
            self.A_eq[:] = A
            self.bu_eq[:] = b
            self.bl_eq[:] = b
        if self.mi:
            self.A_in[:] = G
            self.bu_in[:] = h
        if self.nb:
            self.bu_box[:] = _INF if ub is None else ub
            self.bl_box[:] = -_INF if lb is None else lb

    def __deepcopy__(self, memo):
        # A plain deep copy would copy each view on its own: the copy's views
        # would no longer write into the copy's A, bu, bl (the arrays
        # ``daqp.solve`` reads), and it would solve a stale problem.
        new = _Buffers(self.n, self.me, self.mi, self.nb > 0)
        new.A[:] = self.A
        new.bu[:] = self.bu
        new.bl[:] = self.bl
        memo[id(self)] = new
        return new


def _native_names(generic: dict) -> dict:
    """DAQP's settings for the generic ones given (any of ``eps_abs, eps_rel, max_iter, time_limit``)."""
    out: dict = {}
    if "eps_abs" in generic:
        out["primal_tol"] = out["dual_tol"] = float(generic["eps_abs"])
    if "max_iter" in generic:
        out["iter_limit"] = int(min(generic["max_iter"], 2**31 - 1))
    limit = generic.get("time_limit")
    if limit is not None and np.isfinite(limit):
        out["time_limit"] = float(limit)
    return out


@register
class DaqpBackend(Backend):
    """DAQP through ``daqp.solve`` with simple bounds native and equalities by sense flags."""

    name = "daqp-stateless"
    certifies_infeasibility = True
    family = "active set (dual)"
    package = "daqp"
    module = "daqp"

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings and DAQP's own: the keys of the installed package's
        ``daqp.Model().settings`` (the keyword settings ``daqp.solve`` takes)."""
        from ._common import GENERIC_KEYS

        return frozenset(_daqp().Model().settings) | frozenset(GENERIC_KEYS)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._buffers: dict[tuple, _Buffers] = {}
        self._options: dict | None = None
        self.options()  # checks the settings now (ParamError naming an unknown one)

    def options(self) -> dict:
        """Keyword settings passed to ``daqp.solve`` (profile first, then the user's)."""
        if self._options is None:
            generic, native = generic_settings(self)
            allowed = set(_daqp().Model().settings)
            for key in native:
                if key not in allowed:
                    raise ParamError(
                        f"unknown setting '{key}' for backend 'daqp' (DAQP's own: {', '.join(sorted(allowed))}; "
                        "generic: eps_abs, eps_rel, max_iter, time_limit)",
                        key=key,
                    )
            given = qpbenchmark_options(self, "daqp", _native_names)
            if given is not None:  # as the qpsolvers:daqp route under a qpbenchmark profile
                self._options = given
            else:
                self._options = {**_native_names(generic), **native}
        return self._options

    def reset(self) -> None:
        self._buffers.clear()

    def _solve(self, problem, warm_start):
        daqp = _DAQP[0] if _DAQP else _daqp()
        options = self._options if self._options is not None else self.options()
        P, q, A, b = problem.P, problem.q, problem.A, problem.b
        G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
        # Fast path: the dense float64 arrays a controller builds; anything else
        # (sparse, lists, 1-D single rows, other dtypes) is converted first. Inline, not
        # _common.dense_f64_parts: b, h, lb, ub are copied into this backend's float64
        # buffers, so only P, q, A and G are checked, and the tick pays no extra call.
        if not (
            type(P) is _ndarray
            and type(q) is _ndarray
            and P.dtype == _f64
            and q.dtype == _f64
            and (A is None or (type(A) is _ndarray and A.ndim == 2))
            and (G is None or (type(G) is _ndarray and G.ndim == 2))
        ):
            P, q, A, b, G, h, lb, ub = _dense(problem)
        n = q.shape[0]
        me = 0 if A is None else A.shape[0]
        mi = 0 if G is None else G.shape[0]
        box = lb is not None or ub is not None
        key = (n, me, mi, box)
        buf = self._buffers.get(key)
        if buf is None:
            buf = self._buffers[key] = _Buffers(n, me, mi, box)
        try:
            buf.fill(A, b, G, h, lb, ub)
            x, fval, flag, info = daqp.solve(P, q, buf.A, buf.bu, buf.bl, buf.sense, **options)
        except (ValueError, TypeError) as exc:
            return BackendSolution(problem, status="error", error=f"{type(exc).__name__}: {exc}")
        return read_result(problem, x, fval, flag, info, buf.nb, box, me)


def read_result(
    problem: qpsolvers.Problem,
    x: np.ndarray,
    fval: float,
    flag: int,
    info: dict,
    nb: int,
    box: bool,
    me: int,
) -> BackendSolution:
    """A solution from what DAQP returned: status from the exit flag, its own time, and on
    success ``x``, the objective and the duals, split from DAQP's one multiplier vector
    (bounds first, then equalities, then inequalities; DAQP's signs are qpsolvers')."""
    status, raw = EXITFLAGS.get(flag, _UNKNOWN)
    sol = BackendSolution(problem, status=status)
    sol.iterations = info["iterations"]
    sol.solver_time_s = info["setup_time"] + info["solve_time"]
    sol.extras["raw_status"] = raw
    if status == "optimal":
        lam = info["lam"]
        sol.x = x
        sol.obj = fval
        sol.z_box = lam[:nb] if box else _EMPTY
        sol.y = lam[nb : nb + me]
        sol.z = lam[nb + me :]
    elif status == "error":
        sol.error = f"DAQP exit flag {flag} ({raw})"
    return sol


_ndarray = np.ndarray
_f64 = np.dtype(np.float64)
_INF = np.inf
_UNKNOWN = ("error", "unknown exit flag")
_EMPTY = np.zeros(0)
_EMPTY.flags.writeable = False


_dense = dense_parts
