"""Backend ``qpoases``: qpOASES (online active set) with hotstart, through a compiled shim.

``min 1/2 x'Hx + g'x  s.t.  lb <= x <= ub,  lbA <= A x <= ubA`` with ``A = [A_eq; G]``,
``lbA = [b; -inf]``, ``ubA = [b; h]``, written into the buffer the shim
(:mod:`._qpoases_shim`, compiled on first use) reads. The first tick of a shape calls
``init()``, the next ones ``hotstart()``; a status other than optimal makes the next tick call
``init()``. ``warm_start`` is ignored. Settings: ``max_iter`` -> ``nWSR``, ``time_limit`` [s]
-> qpOASES' CPU-time limit, ``preset`` (:data:`PRESETS`) and :data:`OPTION_NAMES`.
``solver_time_s``: the shim's ``CLOCK_MONOTONIC`` time of the call (qpOASES' own in
``extras["qpoases_cputime_s"]``).
"""

from __future__ import annotations

import ctypes

import numpy as np

from ..exceptions import ParamError
from . import _qpoases_shim as shim
from . import register
from ._common import (
    GENERIC_KEYS,
    check_shapes,
    dense_f64_parts,
    dense_parts,
    generic_settings,
    refuse_unknown,
)
from ._qpoases_shim import OPTION_NAMES, PRESETS, Workspace
from .base import Backend, ViewSolution, new_solution

#: Shim status -> our status.
_STATUSES = {
    0: "optimal",
    1: "max_iter",
    2: "time_limit",
    -2: "primal_infeasible",
    -3: "dual_infeasible",
    -1: "error",
}


@register
class QpoasesBackend(Backend):
    """qpOASES ``SQProblem``: ``init()`` on the first tick of a shape, ``hotstart()`` on the next ones."""

    name = "qpoases"
    certifies_infeasibility = True
    family = "active set (online, parametric)"
    package = "cmeel-qpoases"
    module = None

    @classmethod
    def setting_names(cls) -> frozenset[str]:
        """The generic settings, ``preset`` and :data:`OPTION_NAMES`."""
        return frozenset(OPTION_NAMES) | {"preset"} | frozenset(GENERIC_KEYS)

    def __init__(self, profile="default", **settings):
        super().__init__(profile, **settings)
        self._ws: Workspace | None = None
        generic, native = generic_settings(self)
        preset = native.pop("preset", "default")
        if preset not in PRESETS:
            raise ParamError(
                f"unknown preset '{preset}' for backend 'qpoases' (one of: {', '.join(PRESETS)})",
                key="preset",
            )
        self._preset = PRESETS[preset]
        refuse_unknown("qpoases", native, OPTION_NAMES, "preset, or qpOASES options")
        self._native = native
        self._nwsr = int(min(generic["max_iter"], 2**31 - 1))
        limit = generic["time_limit"]
        self._time_limit = float(limit) if limit is not None and np.isfinite(limit) else 0.0
        self._lib = self.prepare()

    @classmethod
    def prepare(cls) -> ctypes.CDLL:
        """Compile the shim if needed and load it (idempotent; call it before timing anything)."""
        return shim.load()

    @classmethod
    def needs_compile(cls) -> bool:
        """Whether :meth:`prepare` would compile the shim (neither loaded nor built yet)."""
        prefix = shim.qpoases_prefix()
        return not shim.LOADED and not (prefix and shim.shim_path(prefix).is_file())

    @classmethod
    def unavailable_reason(cls) -> str | None:
        if shim.qpoases_prefix() is None:
            return "cmeel-qpoases is not installed (pip install cmeel-qpoases)"
        if cls.needs_compile() and shim.compiler() is None:
            return "no C++ compiler ($CXX, g++ or c++) to build the qpOASES shim"
        return None

    def reset(self) -> None:
        self._ws = None

    def _solve(self, problem, warm_start):
        P, q, A, b, G, h, lb, ub = dense_f64_parts(problem) or dense_parts(problem)
        # A copy into a buffer of another size raises: check_shapes then names the array.
        sizes = (
            P.size,
            q.size,
            None if A is None else A.size,
            None if b is None else b.size,
            None if G is None else G.size,
            None if h is None else h.size,
            None if lb is None else lb.size,
            None if ub is None else ub.size,
        )
        ws = self._ws
        if ws is None or sizes != ws.sizes:  # the workspace of this shape (checked here)
            me, mi = check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            key = (q.shape[0], me, mi, lb is not None or ub is not None)
            if ws is None or ws.key != key:
                self._ws = None
                ws = self._ws = Workspace(
                    key, self._lib, self._preset, self._native, self._nwsr, self._time_limit
                )
            ws.sizes = sizes
        n, me, mi, box = ws.key
        try:
            ws.H[:] = P
            ws.g[:] = q
            if me:
                ws.A_eq[:] = A
                ws.lbA_eq[:] = b
                ws.ubA_eq[:] = b
            if mi:
                ws.A_in[:] = G
                ws.ubA_in[:] = h
            if box:
                ws.lb[:] = -_INF if lb is None else lb
                ws.ub[:] = _INF if ub is None else ub
        except ValueError:
            ws.sizes = None
            check_shapes(self.name, q.shape[0], P, A, b, G, h, lb, ub)
            raise
        st = self._lib.qpb_solve(ws.handle)
        obj, _, solve_time, cputime = ws.s.tolist()
        _, _, iterations, raw, _ = ws.iv.tolist()
        extras = {"raw_status": raw, "qpoases_cputime_s": cputime}
        sol = new_solution(problem, _STATUSES[st], extras, ViewSolution)
        sol.iterations = iterations
        sol.solver_time_s = solve_time
        if st == 0:  # x and the multipliers: one copy, x a view of it
            out = sol._out = ws.xy.copy()
            parts = sol._slices = ws.parts
            sol.x = out[parts[0]]
            sol._obj = obj
        elif st == -1:
            message = self._lib.qpb_message(raw)
            text = message.decode(errors="replace") if message else ""
            sol.error = f"qpOASES return value {raw}: {text}"
        return sol


_INF = np.inf
