"""Backends ``daqp`` (a persistent ``daqp.Model``) and ``daqp-stateless`` (``daqp.solve``):
DAQP, a dual active-set solver.

DAQP solves ``min 1/2 x'Hx + f'x  s.t.  blower <= [x; A x] <= bupper`` with ``A = [A_eq; G]``,
``bupper = [ub; b; h]``, ``blower = [lb; b; -inf]``, sense 5 (an immutable equality) on the
``b`` rows. ``daqp`` sets a model up per shape, then updates it (``H``, ``f`` only when changed)
and solves from the previous working set; a refused set-up or update or a status other than
optimal drops it. ``warm_start`` is ignored.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from . import register
from ._common import (
    GENERIC_KEYS,
    check_shapes,
    dense_f64_parts,
    dense_parts,
    refuse_unknown,
    solver_module,
    solver_options,
)
from .base import BackendSolution, PersistentBackend, new_solution

#: DAQP exit flag -> (status, DAQP's name). CYCLE: no progress.
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
#: The status of an exit flag not in :data:`EXITFLAGS`.
UNKNOWN_EXITFLAG = ("error", "unknown exit flag")


_daqp = partial(solver_module, "daqp")


class _Buffers:
    """Stacked ``A``, ``bupper``, ``blower``, ``sense`` of one shape, and views to fill them."""

    def __init__(self, n: int, me: int, mi: int, box: bool):
        nb = self.nb = n if box else 0
        m = nb + me + mi
        self.me, self.mi = me, mi
        self.A = np.zeros((me + mi, n))
        self.bu = np.empty(m)
        self.bl = np.full(m, -np.inf)
        self.sense = np.zeros(m, dtype=np.intc)
        self.sense[nb : nb + me] = 5  # equality rows
        self.A_eq, self.A_in = self.A[:me], self.A[me:]
        self.bu_box, self.bl_box = self.bu[:nb], self.bl[:nb]
        self.bu_eq, self.bl_eq = self.bu[nb : nb + me], self.bl[nb : nb + me]
        self.bu_in = self.bu[nb + me :]

    def fill(self, A, b, G, h, lb, ub) -> None:
        """Write a problem's rows and bounds (equalities as ``bl = bu``)."""
        if self.me:
            self.A_eq[:] = A
            self.bu_eq[:] = b
            self.bl_eq[:] = b
        if self.mi:
            self.A_in[:] = G
            self.bu_in[:] = h
        if self.nb:
            self.bu_box[:] = np.inf if ub is None else ub
            self.bl_box[:] = -np.inf if lb is None else lb


#: DAQP's settings for the generic ones: name -> (generic key, conversion).
_OWN_NAMES = {
    "primal_tol": ("eps_abs", float),
    "dual_tol": ("eps_abs", float),
    "iter_limit": ("max_iter", lambda k: int(min(k, 2**31 - 1))),
    "time_limit": ("time_limit", lambda t: float(t) if t is not None and np.isfinite(t) else None),
}


def read_result(problem, flag: int, x=None, fval=None, info=None, buf=None) -> BackendSolution:
    """A solution from DAQP's exit ``flag``, with a solve's ``info`` its iterations, time and
    (when optimal) answer; without (a refused ``setup``/``update``) the status alone."""
    status, raw = EXITFLAGS.get(flag, UNKNOWN_EXITFLAG)
    sol = new_solution(problem, status, {"raw_status": raw})
    if info is None:
        if status == "error":
            sol.error = f"DAQP setup/update exit flag {flag} ({raw})"
        return sol
    sol.iterations = info["iterations"]
    sol.solver_time_s = info["setup_time"] + info["solve_time"]
    if status == "optimal":
        lam, nb, me = info["lam"], buf.nb, buf.me
        sol.x, sol.obj = x, fval
        sol.z_box, sol.y, sol.z = lam[:nb], lam[nb : nb + me], lam[nb + me :]
    elif status == "error":
        sol.error = f"DAQP exit flag {flag} ({raw})"
    return sol


@register
class DaqpBackend(PersistentBackend):
    """DAQP through ``daqp.solve`` with simple bounds native and equalities by sense flags."""

    name = "daqp-stateless"
    errors = (ValueError, TypeError)
    family = "active set (dual)"
    package = "daqp"
    module = "daqp"

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings and the keys of ``daqp.Model().settings``."""
        return frozenset(_daqp().Model().settings) | frozenset(GENERIC_KEYS)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._options = self.options()

    def options(self) -> dict:
        """The keyword settings given to DAQP (profile first, then the user's)."""
        options = solver_options(self, "daqp", _OWN_NAMES)
        allowed = sorted(_daqp().Model().settings)
        refuse_unknown("daqp", options, allowed, "DAQP's own")
        return options

    def reset(self) -> None:
        self._buffers: dict[tuple, _Buffers] = {}

    def _stack(self, P, q, A, b, G, h, lb, ub) -> tuple[tuple, _Buffers]:
        """The shape key and the buffers of that shape, filled with this problem."""
        box = lb is not None or ub is not None
        key = (q.shape[0], 0 if A is None else A.shape[0], 0 if G is None else G.shape[0], box)
        buf = self._buffers.get(key)
        if buf is None:
            buf = self._buffers[key] = _Buffers(*key)
        buf.fill(A, b, G, h, lb, ub)
        return key, buf

    def _attempt(self, problem, warm_start):
        P, q, A, b, G, h, lb, ub = dense_f64_parts(problem) or dense_parts(problem)
        _, buf = self._stack(P, q, A, b, G, h, lb, ub)
        x, fval, flag, info = _daqp().solve(P, q, buf.A, buf.bu, buf.bl, buf.sense, **self._options)
        return read_result(problem, flag, x, fval, info, buf)


@register
class DaqpModelBackend(DaqpBackend):
    """DAQP through a persistent ``daqp.Model`` (setup once per shape, update + solve per tick)."""

    name = "daqp"

    def reset(self) -> None:
        super().reset()
        self._model = self._key = None
        self._H = self._f = None  # copies of the H and f the model holds

    def _attempt(self, problem, warm_start):
        P, q, A, b, G, h, lb, ub = dense_f64_parts(problem) or dense_parts(problem)
        check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
        key, buf = self._stack(P, q, A, b, G, h, lb, ub)
        if key != self._key:
            self._model, self._key = None, key
        model = self._model
        if model is None:
            model = _daqp().Model()
            model.settings = dict(model.settings, **self._options)
            flag, _ = model.setup(P, q, buf.A, buf.bu, buf.bl, buf.sense)
            if flag >= 0:
                self._model = model
                self._H, self._f = P.copy(), q.copy()
        else:
            H = f = None
            if P.tobytes() != self._H.tobytes():
                H = self._H = P.copy()
            if q.tobytes() != self._f.tobytes():
                f = self._f = q.copy()
            # only arrays with entries: DAQP's update indexes the first one (IndexError)
            A = buf.A if buf.A.shape[0] else None
            bu, bl = (buf.bu, buf.bl) if buf.bu.shape[0] else (None, None)
            flag = model.update(H, f, A, bu, bl)
        if flag < 0:
            self._model = None
            return read_result(problem, flag)
        x, fval, flag, info = model.solve()
        sol = read_result(problem, flag, x, fval, info, buf)
        if sol.status != "optimal":
            self._model = None  # set up afresh on the next tick
        return sol
