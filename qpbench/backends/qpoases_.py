"""Backend ``qpoases``: qpOASES (online active set) with hotstart, through a small compiled shim.

Route. qpOASES' C++ library and headers come from the ``cmeel-qpoases`` wheel
(LGPL, a dependency of qpbench). A C shim of about 100 lines
(``extern "C"`` around ``qpOASES::SQProblem``, source in :data:`qpbench.backends._qpoases_shim.SHIM_SOURCE`)
is compiled by the system's C++ compiler (``$CXX``, else ``g++``, else
``c++``) on first use, once per machine and version, into
``qpbench.cache.shim_dir("qpoases")``: written to a temporary file and
renamed, so a second process never loads a half-written library. Call
:meth:`QpoasesBackend.prepare` (constructing the backend does too) before any
timed or time-limited call; ``qpbench backends`` shows the backend as
unavailable, with the reason, when neither the wheel nor (without a compiled
shim) a compiler is there. The other route that installs from PyPI, casadi's
``conic('qpoases')``, is not offered: on the robot's n = 4 ticks its hotstart
costs over ten times a call of this backend, and it prints a banner.

Formulation. ``SQProblem(n, me + mi)`` solves
``min 1/2 x'Hx + g'x  s.t.  lb <= x <= ub,  lbA <= A x <= ubA`` with::

    H = P,  g = q,  A = [A_eq; G],  lbA = [b; -inf],  ubA = [b; h]

(equalities as ``lbA = ubA``; infinite bounds are passed as qpOASES'
``INFTY = 1e20``). qpOASES' multipliers ``y`` (``n`` for the bounds, then one
per row of ``A``) satisfy ``H x + g = y_box + A' y_rows``: positive at an
active *lower* bound. qpsolvers' convention is the opposite sign, so
``z_box = -y[:n]``, ``y = -y[n:n+me]``, ``z = -y[n+me:]`` (negated in the shim).

Per-call cost. The tick's arrays are copied into one buffer the shim reads
(no stacking, no allocation), the shim is one ctypes call with one
argument, the shapes are checked in full only when the sizes differ from the
previous tick's (a copy into a buffer raises on another shape, so equal
sizes are enough per tick), and ``x`` and the multipliers come out of one copy,
``x`` a view of it through a slice object the workspace keeps, ``z_box``, ``y``
and ``z`` views made when first read (:class:`QpoasesSolution`).

Persistence. The first tick of a shape ``(n, me, mi, with box)`` calls
``init()``; the next ones call ``hotstart()`` with the whole new data (H, g,
A, bounds), which starts from the previous tick's working set (qpOASES'
homotopy from the last solution). A status other than optimal leaves qpOASES
mid-homotopy, so the next tick calls ``init()`` again. ``warm_start`` is
ignored (qpOASES' warm start is the working set, which it keeps itself).
:meth:`QpoasesBackend.reset` drops the object. ``get_state``/``set_state``
copy the whole ``SQProblem`` (qpOASES' deep copy: a snapshot of the working
set to solve from again; ``--repeat`` does not need it, see
:mod:`qpbench.harness.timing`).

Settings. ``max_iter`` -> ``nWSR`` (working-set recalculations),
``time_limit`` -> qpOASES' CPU-time limit [s] (measured by qpOASES with
``gettimeofday``, 1 us resolution). ``eps_abs``/``eps_rel`` are not used: an
active-set method ends on the exact solution of its final working set, and
qpOASES' own tolerances (``terminationTolerance`` 1.1e-9 relative, ...)
keep their defaults. Other settings: ``preset`` (``"default"``, ``"mpc"``,
``"reliable"``, ``"fast"``: qpOASES' ``setTo...()`` option sets; default
``"default"``) and qpOASES' options by name (:data:`OPTION_NAMES`, e.g.
``terminationTolerance=1e-12``, ``enableRegularisation=1``); an unknown name
is a :class:`~qpbench.exceptions.ParamError`. Output is off (``PL_NONE``).

Time. ``solver_time_s`` is the time of the ``init()``/``hotstart()`` call
measured in the shim with ``clock_gettime(CLOCK_MONOTONIC)``: qpOASES' own
CPU-time output (in ``extras["qpoases_cputime_s"]``) comes from
``gettimeofday`` and is too coarse for a hotstart of microseconds.

Statuses. ``SUCCESSFUL_RETURN`` -> optimal; ``isInfeasible()`` or
``RET_*_INFEASIBILITY`` -> primal_infeasible; ``isUnbounded()`` or
``RET_*_UNBOUNDEDNESS`` -> dual_infeasible; ``RET_MAX_NWSR_REACHED`` ->
max_iter, or time_limit when fewer than ``nWSR`` recalculations were done
(the CPU-time limit stopped it); any other return value -> error with
qpOASES' message. ``extras["raw_status"]`` holds qpOASES' return value. Only
an optimal solve carries ``x`` and duals (an interrupted homotopy's iterate
is not a solution of the problem asked).
"""

from __future__ import annotations

import ctypes

import numpy as np

from ..exceptions import ParamError
from . import _qpoases_shim as shim
from . import register
from ._common import dense_parts, generic_settings
from ._qpoases_shim import OPTION_NAMES, PRESETS, Workspace
from ._shapes import check_shapes
from .base import Backend, BackendSolution, _perf_ns

__all__ = ["OPTION_NAMES", "PRESETS", "QpoasesBackend"]

#: Shim status -> our status.
_STATUSES = {
    0: "optimal",
    1: "max_iter",
    2: "time_limit",
    -2: "primal_infeasible",
    -3: "dual_infeasible",
    -1: "error",
}


def _multipliers(part: int, name: str, doc: str) -> property:
    """Field ``name`` of :class:`QpoasesSolution`: ``_xy[_parts[part]]`` on first read (None
    without ``_xy``: no solution), kept; an assigned value replaces it."""
    key = "_" + name

    def get(self):
        d = self.__dict__
        value = d.get(key, _UNSET)
        if value is _UNSET:
            xy = d.get("_xy")
            value = d[key] = None if xy is None else xy[d["_parts"][part]]
        return value

    def set_(self, value) -> None:
        self.__dict__[key] = value

    return property(get, set_, doc=doc)


_UNSET = object()


class QpoasesSolution(BackendSolution):
    """A qpOASES tick's :class:`BackendSolution`.

    ``x``, ``z_box``, ``y`` and ``z`` are views of one copy of the shim's output
    (``x``, then the multipliers with qpsolvers' sign): ``x`` is made with the
    solution, the multipliers on first read and then kept (a closed loop reads
    only ``x``, and making the three views is a measurable share of a tick:
    ``python bench/backend_overhead.py``). Assigning a field replaces
    it, as on any :class:`qpsolvers.Solution`. ``z_box`` is empty when the
    problem has no bounds.
    """

    z_box = _multipliers(1, "z_box", "Multipliers of the bounds ``lb <= x <= ub``.")
    y = _multipliers(2, "y", "Multipliers of the equalities ``A x = b``.")
    z = _multipliers(3, "z", "Multipliers of the inequalities ``G x <= h``.")


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
        """The generic settings, ``preset`` and the qpOASES options the shim sets by name
        (:data:`OPTION_NAMES`, the ``Options`` fields its C++ source assigns)."""
        from ._common import GENERIC_KEYS

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
        for key in native:
            if key not in OPTION_NAMES:
                raise ParamError(
                    f"unknown setting '{key}' for backend 'qpoases' (qpOASES options: {', '.join(OPTION_NAMES)}; "
                    "also preset; generic: eps_abs, eps_rel, max_iter, time_limit)",
                    key=key,
                )
        self._native = native
        self._nwsr = int(min(generic["max_iter"], 2**31 - 1))
        limit = generic["time_limit"]
        self._time_limit = float(limit) if limit is not None and np.isfinite(limit) else 0.0
        self._lib = self.prepare()

    # -- the compiled shim ----------------------------------------------------
    @classmethod
    def prepare(cls) -> ctypes.CDLL:
        """Compile the shim if needed and load it (idempotent; call it before timing anything)."""
        return shim.load()

    @classmethod
    def unavailable_reason(cls) -> str | None:
        prefix = shim.qpoases_prefix()
        if prefix is None:
            return "cmeel-qpoases is not installed (pip install cmeel-qpoases)"
        if shim.LOADED or shim.shim_path(prefix).is_file():
            return None
        if shim.compiler() is None:
            return "no C++ compiler ($CXX, g++ or c++) to build the qpOASES shim"
        return None

    # -- state ----------------------------------------------------------------
    def reset(self) -> None:
        self._ws = None

    def get_state(self) -> Workspace | None:
        """A deep copy of the ``SQProblem`` (working set, factorisations), or None before the first tick."""
        ws = self._ws
        if ws is None:
            return None
        return Workspace(
            ws.key, self._lib, self._preset, {}, self._nwsr, self._time_limit, clone_of=ws.handle
        )

    def set_state(self, state: Workspace | None) -> None:
        if state is None:
            self._ws = None
        elif self._ws is not None and self._ws.key == state.key:
            self._lib.qpb_assign(self._ws.handle, state.handle)
        else:
            self._ws = Workspace(
                state.key,
                self._lib,
                self._preset,
                {},
                self._nwsr,
                self._time_limit,
                clone_of=state.handle,
            )

    def __deepcopy__(self, memo):
        other = type(self)(self.profile, **self.settings)
        other.set_state(self.get_state())
        return other

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_ws"] = None  # native object: a pickled backend starts afresh
        state["_lib"] = None
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lib = self.prepare()

    # -- solving --------------------------------------------------------------
    def solve(self, problem, warm_start=None) -> BackendSolution:
        """One tick; see :meth:`Backend.solve` (same fields). Timed here rather than around a
        ``_solve``: one Python call less per tick."""
        start = _perf_ns()
        P, q, A, b = problem.P, problem.q, problem.A, problem.b
        G, h, lb, ub = problem.G, problem.h, problem.lb, problem.ub
        # Inline, not _common.dense_f64_parts: every array is copied into the workspace's
        # float64 buffers, so the types suffice, and the tick pays no extra call.
        if not (
            type(P) is _ndarray
            and type(q) is _ndarray
            and q.ndim == 1
            and (A is None or (type(A) is _ndarray and type(b) is _ndarray))
            and (G is None or (type(G) is _ndarray and type(h) is _ndarray))
            and (lb is None or type(lb) is _ndarray)
            and (ub is None or type(ub) is _ndarray)
        ):
            P, q, A, b, G, h, lb, ub = _dense(problem)
        # The sizes decide: a copy into a buffer of another shape raises, and one of the same size
        # cannot broadcast; check_shapes names the array when the sizes changed or a copy raised.
        # Written out like piqp's shapes: a helper building the key would cost a call per tick.
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
        if ws is None or sizes != ws.sizes:
            ws = self._workspace(P, q, A, b, G, h, lb, ub)
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
        # Without __init__ (BackendSolution's defaults are class attributes): a microsecond less per call.
        sol = _new(QpoasesSolution)
        sol.problem = problem
        sol.status = status = _STATUSES[st]
        sol.extras = {"raw_status": raw, "qpoases_cputime_s": cputime}
        sol.iterations = iterations
        sol.solver_time_s = solve_time
        if st == 0:
            # x, then the multipliers (already with qpsolvers' sign): one copy; x a view of it
            # through the workspace's slice object, the multipliers on first read.
            xy = sol._xy = ws.xy.copy()
            parts = sol._parts = ws.parts
            sol.x = xy[parts[0]]
            sol._obj = obj
        elif st == -1:
            sol.error = self._message(raw)
        sol.found = status == "optimal"
        sol.backend = self.name
        sol.wall_time_s = (_perf_ns() - start) * 1e-9
        return sol

    def _message(self, raw: int) -> str:
        """The error text of qpOASES' return value ``raw``."""
        message = self._lib.qpb_message(raw)
        return f"qpOASES return value {raw}: {message.decode(errors='replace') if message else ''}"

    def _workspace(self, P, q, A, b, G, h, lb, ub) -> Workspace:
        """The workspace of this problem's shape (checked here), the current one when the shape holds."""
        n = q.shape[0]
        me, mi = check_shapes(self.name, n, P, A, b, G, h, lb, ub)
        key = (n, me, mi, lb is not None or ub is not None)
        ws = self._ws
        if ws is None or ws.key != key:
            self._ws = None
            ws = self._ws = Workspace(
                key, self._lib, self._preset, self._native, self._nwsr, self._time_limit
            )
        return ws


_ndarray = np.ndarray
_new = object.__new__
_INF = np.inf


_dense = dense_parts
